"""JAX transforms through `simulate`: vmap, forward and reverse derivatives against finite differences,
no recompilation when only leaf values change, and failure reporting."""

import dataclasses

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxhoist as jh
import jaxhoist._numerics.solve as solve_mod
from jaxhoist._physics.paths import get_leaf

# Tight solves shared by the vmap, derivative and finite-difference tests (one compile per transform):
# two saved times [0, t1] and rtol 1e-12.
# Tsit5 at a tight tolerance: these tests check the transforms of the explicit diffrax path against
# differences and single solves; the default Rosenbrock-W solver has its own in test_rosenbrock.py.
TIGHT = jh.SolverOptions(diffrax.Tsit5(), rtol=1e-12, atol=1e-14)
TIGHT_FORWARD = jh.SolverOptions(diffrax.Tsit5(), adjoint=diffrax.ForwardMode(), rtol=1e-12, atol=1e-14)
LOOSE = jh.SolverOptions(rtol=1e-4, atol=1e-6)
PATHS = ("foundation.friction_coefficient", "foundation.stiffness", "rope.stiffness")  # μ, k, c_l


def final_x(scenario, x, t1, adjoint="reverse", throw=True):
    """X_C(t1) [m] of paper-4.2 with (μ, k, c_l) = x."""
    sc = scenario.replace(**{p: x[i] for i, p in enumerate(PATHS)})
    ts = jnp.stack([jnp.zeros(()), jnp.asarray(t1)])
    tr = jh.simulate(
        sc, jh.Times(ts=ts), options=TIGHT_FORWARD if adjoint == "forward" else TIGHT, throw=throw
    )
    return tr.position[-1, 0]


def central_differences(scenario, x0, t1, rel=1e-3):
    """Central differences with steps of 1e-3 of each parameter: truncation ~1e-7 relative, round-off
    ~1e-12 / 1e-3 = 1e-9 relative at rtol 1e-12 (checked against steps of 1e-4: same to 1e-6)."""
    out = []
    for i in range(len(PATHS)):
        h = rel * float(x0[i])
        e = jnp.zeros(len(PATHS)).at[i].set(h)
        out.append(float(final_x(scenario, x0 + e, t1) - final_x(scenario, x0 - e, t1)) / (2 * h))
    return np.array(out)


@pytest.fixture(scope="module")
def x0(paper42):
    return jnp.stack([get_leaf(paper42, p) for p in PATHS])


# -------------------------------------------------------------------------------------- vmap


def test_vmap_over_mu_equals_single_solves(paper42):
    """8 values of μ in one vmapped solve against 8 separate solves over 1 s of dragging and tipping.

    The batched vector field differs from the unbatched one by round-off (XLA vectorises the reductions
    differently), which the adaptive controller turns into slightly different step sequences, so the two
    agree to the solver tolerance rather than bitwise: at rtol 1e-12, 1e-12 m measured; we allow 1e-10 m
    (position) and 1e-9 rad-ish units for the quaternion."""
    mus = jnp.linspace(0.1, 0.45, 8)
    ts = jnp.array([0.0, 1.0])

    def one(mu):
        sc = paper42.replace(**{"foundation.friction_coefficient": mu})
        return jh.simulate(sc, jh.Times(ts=ts), throw=False, options=TIGHT)

    batch = jax.vmap(one)(mus)
    assert np.all(np.asarray(batch.status) == jh.SolveStatus.OK)
    x_final = []
    for i, mu in enumerate(mus):
        tr = one(mu)
        assert np.abs(np.asarray(batch.position[i] - tr.position)).max() < 1e-10
        assert np.abs(np.asarray(batch.states.quaternion[i] - tr.states.quaternion)).max() < 1e-9
        x_final.append(float(tr.position[-1, 0]))
    # The members are really different lifts: μ moves the final position by centimetres.
    assert np.ptp(x_final) > 1e-2


# ------------------------------------------------------------------------------- derivatives


def test_jacfwd_and_grad_match_finite_differences(paper42, x0):
    """d X_C(0.5 s) / d(μ, k, c_l) by `jax.jacfwd` (adjoint="forward") and by `jax.grad`
    (adjoint="reverse") against central differences of solves at rtol 1e-12.

    Over 0.5 s the container is dragged and a corner lifts off. At a corner's lift-off the vector field
    has a kink (N_i = max(0, ...)), where the derivative of the discrete solve converges to the true
    sensitivity only like sqrt(rtol): measured relative errors 1e-4 at rtol 1e-8, 1e-5 at 1e-10 and
    <= 1e-5 at 1e-12 (forward and reverse differ from each other by as much). Hence rtol 1e-12 and a
    tolerance of 3e-5 relative."""
    t1 = 0.5
    fd = central_differences(paper42, x0, t1)
    fwd = np.asarray(jax.jacfwd(lambda x: final_x(paper42, x, t1, adjoint="forward"))(x0))
    rev = np.asarray(jax.grad(lambda x: final_x(paper42, x, t1, adjoint="reverse"))(x0))
    assert np.all(np.abs(fd) > 0)
    np.testing.assert_allclose(fwd, fd, rtol=3e-5, atol=0)
    np.testing.assert_allclose(rev, fd, rtol=3e-5, atol=0)


def test_derivative_across_damped_touch_down(paper42, x0):
    """As above over 1 s, across the first touch-down of a lifted corner (between 0.5 s and 0.6 s).
    The damper builds up over `foundation.damping_onset` = 0.1 mm, so the contact force is continuous
    and the sensitivities have no jump the solver could miss. With damping_onset = 0 (the paper's (3.1)
    as written, N jumping to h dp/dt at touch-down) jacfwd gave 0.159 against 0.426 from differences.
    Measured now: relative errors <= 3e-5 (more kinks than over 0.5 s: lift-offs and the onset ramps'
    corners); we allow 1e-4, far below the factor 2.7 of a missed jump."""
    t1 = 1.0
    fd = central_differences(paper42, x0, t1)
    fwd = np.asarray(jax.jacfwd(lambda x: final_x(paper42, x, t1, adjoint="forward"))(x0))
    np.testing.assert_allclose(fwd, fd, rtol=1e-4, atol=0)


# ---------------------------------------------------------------------------- recompilation


# The jitted core of `simulate`, wrapped to raise if traced a second time. Module-level, so that the tests
# below share its one compile (the guard counts traces, and cache hits are not traces).
_GUARDED = eqx.filter_jit(eqx.debug.assert_max_traces(solve_mod.solve, max_traces=1))


@pytest.fixture
def guarded_core(monkeypatch):
    monkeypatch.setattr(solve_mod, "_solve_jit", _GUARDED)


def _mu(s):
    return s.foundation.friction_coefficient


def test_no_recompile_when_leaf_values_change(paper42, guarded_core):
    """One trace serves every call that changes only values: leaves through `Scenario.replace` and
    `eqx.tree_at` (float64 arrays), t1 as a float, numpy or JAX scalar, saved times of the same length,
    and scenarios that differ only in their static labels (another preset, a renamed copy:
    `Scenario.unlabelled`)."""
    kw = dict(options=LOOSE)
    jh.simulate(paper42, jh.Times(0.05, n=3), **kw)
    jh.simulate(
        paper42.replace(
            **{
                "foundation.friction_coefficient": 0.3,
                "rope.stiffness": 1.0e7,
                "load.mass_centre": [1.1, 2.4, 1.0],
            }
        ),
        jh.Times(0.05, n=3),
        **kw,
    )
    jh.simulate(eqx.tree_at(_mu, paper42, jnp.asarray(0.35, dtype=jnp.float64)), jh.Times(0.05, n=3), **kw)
    jh.simulate(eqx.tree_at(_mu, paper42, np.asarray(0.35)), jh.Times(0.05, n=3), **kw)
    jh.simulate(paper42, jh.Times(np.float64(0.04), n=3), **kw)
    jh.simulate(paper42, jh.Times(jnp.asarray(0.06), n=3), **kw)
    jh.simulate(paper42, jh.Times(ts=np.array([0.0, 0.01, 0.03])), options=LOOSE)
    jh.simulate(jh.load_scenario("paper-2.3"), jh.Times(0.05, n=3), **kw)
    renamed = dataclasses.replace(paper42, name="my lift", t1=3.0, description="renamed")
    jh.simulate(renamed, jh.Times(0.05, n=3), **kw)
    # The guard is live: a new shape of the saved times must retrace, and does.
    with pytest.raises(RuntimeError, match="traced"):
        jh.simulate(paper42, jh.Times(0.05, n=4), options=LOOSE)


@pytest.mark.parametrize("value", [0.35, jnp.asarray(0.35)], ids=["python-float", "weak-f64"])
def test_no_recompile_for_float_or_weak_leaf(paper42, guarded_core, value):
    kw = dict(options=LOOSE)
    jh.simulate(paper42, jh.Times(0.05, n=3), **kw)
    jh.simulate(eqx.tree_at(_mu, paper42, value), jh.Times(0.05, n=3), **kw)


# ------------------------------------------------------------------------------------ failures


def test_max_steps_reported_or_raised(paper42):
    """A step budget of 16 cannot reach t1 = 0.5 s (thousands of steps): status MAX_STEPS with throw=False,
    an error naming max_steps with throw=True."""
    kw = dict(options=jh.SolverOptions(max_steps=16))
    tr = jh.simulate(paper42, jh.Times(0.5, n=3), throw=False, **kw)
    assert int(tr.status) == jh.SolveStatus.MAX_STEPS
    assert not bool(tr.ok)
    with pytest.raises(eqx.EquinoxRuntimeError, match="max_steps"):
        jh.simulate(paper42, jh.Times(0.5, n=3), throw=True, **kw)


def test_nan_leaf_rejected_before_compiling(paper42, monkeypatch):
    def boom(*a, **k):
        raise AssertionError("the jitted core must not be reached with an invalid scenario")

    monkeypatch.setattr(solve_mod, "_solve_jit", boom)
    for path in ("foundation.friction_coefficient", "rope.damping", "boom.tip_mass"):
        with pytest.raises(jh.ScenarioError, match=path.replace(".", r"\.")):
            jh.simulate(paper42.replace(**{path: float("nan")}), 0.1)
    with pytest.raises(jh.ScenarioError, match=r"load\.mass_centre"):
        jh.simulate(paper42.replace(**{"load.mass_centre": [1.0, float("nan"), 1.0]}), 0.1)
