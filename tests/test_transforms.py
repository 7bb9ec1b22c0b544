"""JAX transforms through `simulate`: vmap, forward and reverse derivatives against finite differences,
no recompilation when only leaf values change, and failure reporting."""

import dataclasses
import warnings

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import N_SAVE, TSIT5_CAPPED, stiff_member

import jaxhoist as jh
import jaxhoist._numerics.solve as solve_mod
from jaxhoist._numerics import compile_cache
from jaxhoist._numerics import persistent_cache as pc
from jaxhoist._physics.paths import get_leaf

# Tight solves of the derivative tests (one compile per transform: the forward-mode one also gives the
# central differences' values): two saved times [0, t1] and rtol 1e-12.
# Tsit5 at a tight tolerance: these tests check the transforms of the explicit diffrax path against
# differences and single solves; the default Rosenbrock-W solver has its own in test_rosenbrock.py.
TIGHT = jh.SolverOptions(diffrax.Tsit5(), rtol=1e-12, atol=1e-14)
TIGHT_FORWARD = jh.SolverOptions(diffrax.Tsit5(), adjoint=diffrax.ForwardMode(), rtol=1e-12, atol=1e-14)
PATHS = ("foundation.friction_coefficient", "foundation.stiffness", "rope.stiffness")  # μ, k, c_l


def final_x(scenario, x, t1, adjoint="reverse", throw=True):
    """X_C(t1) [m] of paper-4.2 with (μ, k, c_l) = x."""
    sc = scenario.replace(**{p: x[i] for i, p in enumerate(PATHS)})
    ts = jnp.stack([jnp.zeros(()), jnp.asarray(t1)])
    tr = jh.simulate(
        sc, jh.Times(ts=ts), options=TIGHT_FORWARD if adjoint == "forward" else TIGHT, throw=throw
    )
    return tr.position[-1, 0]


def forward(scenario, x, dx, t1):
    """(X_C(t1) [m], its derivative along `dx`) by `jax.jvp` with adjoint="forward": one compiled program
    for the derivative along each parameter in turn (`jax.jacfwd` compiles a batched one, larger) and,
    from its primal (the plain solve's operations: Tsit5's steps, differentiated alongside), the values of
    the central differences, which then need no program of their own."""
    return jax.jvp(lambda x: final_x(scenario, x, t1, adjoint="forward"), (x,), (dx,))


def jacobian_forward(scenario, x0, t1):
    """d X_C(t1) / d(μ, k, c_l) [m per unit], one forward-mode derivative per parameter."""
    unit = jnp.eye(len(PATHS), dtype=x0.dtype)
    return np.array([float(forward(scenario, x0, unit[i], t1)[1]) for i in range(len(PATHS))])


def central_differences(scenario, x0, t1, rel=1e-3):
    """Central differences with steps of 1e-3 of each parameter: truncation ~1e-7 relative, round-off
    ~1e-12 / 1e-3 = 1e-9 relative at rtol 1e-12 (checked against steps of 1e-4: same to 1e-6)."""
    out = []
    for i in range(len(PATHS)):
        h = rel * float(x0[i])
        e = jnp.zeros(len(PATHS)).at[i].set(h)
        x_plus, x_minus = forward(scenario, x0 + e, e, t1)[0], forward(scenario, x0 - e, e, t1)[0]
        out.append(float(x_plus - x_minus) / (2 * h))
    return np.array(out)


@pytest.fixture(scope="module")
def x0(paper42):
    return jnp.stack([get_leaf(paper42, p) for p in PATHS])


# -------------------------------------------------------------------------------------- vmap


def test_vmap_over_mu_equals_single_solves(paper42):
    """3 values of μ in one vmapped solve against 3 separate solves over 1 s of dragging and tipping, with the
    default options on N_SAVE saved times: the programs of test_rosenbrock.py's
    `test_vmap_equals_single_solves` (the batched one) and `default_run` (the single ones).

    The batched vector field differs from the unbatched one by round-off (XLA vectorises the reductions
    differently), which the adaptive controller turns into slightly different step sequences, so the two
    agree to round-off amplified by the step-size control rather than bitwise: at the default rtol 5e-4 that
    can change a step's acceptance (measured 5e-9 m in the positions, 2e-9 in the quaternion); we allow
    1e-6 m and 1e-6, still far below what the solver's tolerance allows."""
    mus = jnp.array([0.2, 0.3, 0.45])
    ts = jnp.asarray(np.linspace(0.0, 1.0, N_SAVE))

    def one(mu):
        sc = eqx.tree_at(lambda s: s.foundation.friction_coefficient, paper42, mu)
        return jh.simulate(sc, jh.Times(ts=ts), throw=False)

    batch = jax.vmap(one)(mus)
    assert np.all(np.asarray(batch.status) == jh.SolveStatus.OK)
    x_final = []
    for i, mu in enumerate(mus):
        tr = one(mu)
        assert np.abs(np.asarray(batch.position[i] - tr.position)).max() < 1e-6
        assert np.abs(np.asarray(batch.states.quaternion[i] - tr.states.quaternion)).max() < 1e-6
        x_final.append(float(tr.position[-1, 0]))
    # The members are really different lifts: μ moves the final position by centimetres.
    assert np.ptp(x_final) > 1e-2


# ------------------------------------------------------------------------------- derivatives


def test_jvp_and_grad_match_finite_differences(paper42, x0):
    """d X_C(0.5 s) / d(μ, k, c_l) by `jax.jvp` (adjoint="forward") and by `jax.grad`
    (adjoint="reverse") against central differences of solves at rtol 1e-12.

    Over 0.5 s the container is dragged and a corner lifts off. At a corner's lift-off the vector field
    has a kink (N_i = max(0, ...)), where the derivative of the discrete solve converges to the true
    sensitivity only like sqrt(rtol): measured relative errors 1e-4 at rtol 1e-8, 1e-5 at 1e-10 and
    <= 1e-5 at 1e-12 (forward and reverse differ from each other by as much). Hence rtol 1e-12 and a
    tolerance of 3e-5 relative."""
    t1 = 0.5
    fd = central_differences(paper42, x0, t1)
    fwd = jacobian_forward(paper42, x0, t1)
    rev = np.asarray(jax.grad(lambda x: final_x(paper42, x, t1, adjoint="reverse"))(x0))
    assert np.all(np.abs(fd) > 0)
    np.testing.assert_allclose(fwd, fd, rtol=3e-5, atol=0)
    np.testing.assert_allclose(rev, fd, rtol=3e-5, atol=0)


def test_derivative_across_damped_touch_down(paper42, x0):
    """As above over 1 s, across the first touch-down of a lifted corner (between 0.5 s and 0.6 s).
    The damper builds up over `foundation.damping_onset` = 0.1 mm, so the contact force is continuous
    and the sensitivities have no jump the solver could miss. With damping_onset = 0 (the paper's (3.1)
    as written, N jumping to h dp/dt at touch-down) forward mode gave 0.159 against 0.426 from differences.
    Measured now: relative errors <= 3e-5 (more kinks than over 0.5 s: lift-offs and the onset ramps'
    corners); we allow 1e-4, far below the factor 2.7 of a missed jump."""
    t1 = 1.0
    fd = central_differences(paper42, x0, t1)
    fwd = jacobian_forward(paper42, x0, t1)
    np.testing.assert_allclose(fwd, fd, rtol=1e-4, atol=0)


# ---------------------------------------------------------------------------- recompilation


@pytest.fixture
def guarded_core(monkeypatch):
    """`simulate`'s solve core (compiled through `compile_cache.program`) wrapped to raise if traced a second
    time while the test runs: the process's compiled `simulate` programs are set aside, so the test's first
    call traces once (its compile is loaded from JAX's cache where another test compiled it), and put back
    afterwards. Cache hits are not traces. The library's cache is off meanwhile, so that a program stored
    whole by another test is traced here, not loaded."""
    monkeypatch.setattr(pc, "_ENABLED", [None])
    saved = {k: v for k, v in compile_cache._CACHE.items() if k[0] == "simulate"}
    compile_cache.clear("simulate")
    monkeypatch.setattr(solve_mod, "solve", eqx.debug.assert_max_traces(solve_mod.solve, max_traces=1))
    yield
    compile_cache.clear("simulate")
    compile_cache._CACHE.update(saved)


def _mu(s):
    return s.foundation.friction_coefficient


def test_no_recompile_when_leaf_values_change(paper42, guarded_core):
    """One trace serves every call that changes only values: leaves through `Scenario.replace` and
    `eqx.tree_at` (float64 arrays), t1 as a float, numpy or JAX scalar, saved times of the same length,
    and scenarios that differ only in their static labels (another preset, a renamed copy:
    `Scenario.unlabelled`). The default options on N_SAVE saved times: the program of test_rosenbrock.py's
    `default_run`, which the guarded core loads rather than compiles where that ran before."""
    n = N_SAVE
    jh.simulate(paper42, jh.Times(0.05, n=n))
    jh.simulate(
        paper42.replace(
            **{
                "foundation.friction_coefficient": 0.3,
                "rope.stiffness": 1.0e7,
                "load.mass_centre": [1.1, 2.4, 1.0],
            }
        ),
        jh.Times(0.05, n=n),
    )
    jh.simulate(eqx.tree_at(_mu, paper42, jnp.asarray(0.35, dtype=jnp.float64)), jh.Times(0.05, n=n))
    jh.simulate(eqx.tree_at(_mu, paper42, np.asarray(0.35)), jh.Times(0.05, n=n))
    jh.simulate(paper42, jh.Times(np.float64(0.04), n=n))
    jh.simulate(paper42, jh.Times(jnp.asarray(0.06), n=n))
    jh.simulate(paper42, jh.Times(ts=0.03 * np.linspace(0.0, 1.0, n) ** 2))  # unevenly spaced
    jh.simulate(jh.load_scenario("paper-2.3"), jh.Times(0.05, n=n))
    renamed = dataclasses.replace(paper42, name="my lift", t1=3.0, description="renamed")
    jh.simulate(renamed, jh.Times(0.05, n=n))
    # The guard is live: a new shape of the saved times must retrace, and does (before compiling).
    with pytest.raises(RuntimeError, match="traced"):
        jh.simulate(paper42, jh.Times(0.05, n=n + 1))


@pytest.mark.parametrize("value", [0.35, jnp.asarray(0.35)], ids=["python-float", "weak-f64"])
def test_no_recompile_for_float_or_weak_leaf(paper42, guarded_core, value):
    jh.simulate(paper42, jh.Times(0.05, n=N_SAVE))
    jh.simulate(eqx.tree_at(_mu, paper42, value), jh.Times(0.05, n=N_SAVE))


# ------------------------------------------------------------------------------------ failures


def test_max_steps_reported_or_raised(paper42):
    """Tsit5 with a step budget of 10 000 cannot reach t1 = 1 s of `stiff_member` (it needs about 13 000
    steps): status MAX_STEPS with throw=False, an error naming max_steps with throw=True. The program of
    test_rosenbrock.py's `test_stiff_member_solves` (the same options, structure and number of saved
    times)."""
    stiff = stiff_member(paper42)
    times = jh.Times(ts=np.linspace(0.0, 1.0, N_SAVE))
    tr = jh.simulate(stiff, times, throw=False, options=TSIT5_CAPPED)
    assert int(tr.status) == jh.SolveStatus.MAX_STEPS
    assert not bool(tr.ok)
    assert int(tr.num_accepted_steps + tr.num_rejected_steps) == TSIT5_CAPPED.max_steps
    # the saved times it did not reach hold inf: their arrays for the files (the command line's) have a NaN
    # energy residual there, without numpy's "invalid value" warning
    from jaxhoist._io.results import trajectory_arrays

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        arrays = trajectory_arrays(tr)
    assert np.isinf(arrays["position"][-1]).all() and np.isnan(arrays["energy_residual"][-1])
    with pytest.raises(eqx.EquinoxRuntimeError, match="max_steps"):
        jh.simulate(stiff, times, throw=True, options=TSIT5_CAPPED)


def test_nan_leaf_rejected_before_compiling(paper42, monkeypatch):
    def boom(*a, **k):
        raise AssertionError("the compiled core must not be reached with an invalid scenario")

    monkeypatch.setattr(solve_mod, "_core", boom)
    for path in ("foundation.friction_coefficient", "rope.damping", "boom.tip_mass"):
        with pytest.raises(jh.ScenarioError, match=path.replace(".", r"\.")):
            jh.simulate(paper42.replace(**{path: float("nan")}), 0.1)
    with pytest.raises(jh.ScenarioError, match=r"load\.mass_centre"):
        jh.simulate(paper42.replace(**{"load.mass_centre": [1.0, float("nan"), 1.0]}), 0.1)
