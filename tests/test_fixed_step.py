"""`jaxhoist._numerics.fixed_step`: the lean fixed-step Runge-Kutta loop used by `scan` with constant steps
(`diffrax.ConstantStepSize()`).

It must take the same steps as diffrax's `ConstantStepSize` with the same tableau and give the same states
to round-off; land on saved times that are not multiples of the step; carry forward-mode sensitivities
that agree with differences of its own solutions; and refuse a request that exceeds `max_steps` before
compiling. Horizons are 0.2 s of paper-4.2 (the rope's corner lifts and the box starts to slide), 200 steps.
"""

import jax

jax.config.update("jax_enable_x64", True)  # tests/conftest.py also does this

import diffrax  # noqa: E402
import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

import jaxhoist as jh  # noqa: E402
from jaxhoist._apps.scan.run import scan  # noqa: E402
from jaxhoist._numerics import fixed_step  # noqa: E402
from jaxhoist._numerics.options import SolverOptions  # noqa: E402
from jaxhoist._numerics.solve import solve  # noqa: E402

MU = "foundation.friction_coefficient"
DT = 1e-3
T1 = 0.2
FIELDS = (
    "position",
    "velocity",
    "euler",
    "angular_velocity",
    "tip_position",
    "hoist_work",
    "damping_loss",
    "friction_work",
)


@pytest.fixture(scope="module")
def sc():
    return jh.load_scenario("paper-4.2").replace(**{"foundation.friction.regularisation_velocity": 1e-2})


@pytest.mark.parametrize("solver", [diffrax.Bosh3(), diffrax.Heun()], ids=["bosh3-fsal", "heun"])
def test_same_steps_and_states_as_diffrax_constant_steps(sc, solver):
    """Saved times on the step grid: every output equals diffrax's fixed-step solve to round-off (Bosh3
    carries its last stage into the next step, Heun evaluates it again: both code paths)."""
    ts = jnp.linspace(0.0, T1, 5)
    opt = SolverOptions(
        solver=solver, stepsize_controller=diffrax.ConstantStepSize(), dt0=DT, max_steps=10_000
    )
    ref = eqx.filter_jit(solve)(sc, ts, opt)
    lean = eqx.filter_jit(fixed_step.solve_fixed)(sc, ts, opt)
    assert int(lean.status) == 0 and int(ref.status) == 0
    assert int(lean.num_accepted_steps) == int(ref.num_accepted_steps) == round(T1 / DT)
    # The load has moved (rope corner lifted, slid): the comparison is not of a state at rest.
    assert float(jnp.max(jnp.abs(ref.position[-1] - ref.position[0]))) > 1e-3
    for f in FIELDS:
        a, b = np.asarray(getattr(ref, f)), np.asarray(getattr(lean, f))
        scale = max(1.0, float(np.max(np.abs(a))))
        # Round-off of ~200 steps of a stiff contact problem (the two sum the stage terms in another order).
        np.testing.assert_allclose(b, a, rtol=0, atol=1e-11 * scale, err_msg=f)


def test_lands_on_saved_times_off_the_step_grid(sc):
    """Saved times that are not multiples of dt: ⌈span/dt⌉ equal steps per interval, no interpolation; the
    final state differs from the on-grid solve only by the truncation error of the shorter steps."""
    ts_on = jnp.linspace(0.0, T1, 5)
    ts_off = jnp.array([0.0, 0.0125, 0.05, 0.1337, T1])
    opt = SolverOptions(
        solver=diffrax.Bosh3(), stepsize_controller=diffrax.ConstantStepSize(), dt0=DT, max_steps=10_000
    )
    run = eqx.filter_jit(fixed_step.solve_fixed)
    on, off = run(sc, ts_on, opt), run(sc, ts_off, opt)
    assert int(off.num_accepted_steps) == fixed_step.steps_needed(ts_off, DT) == 13 + 38 + 84 + 67
    np.testing.assert_array_equal(off.ts, ts_off)
    # The two grids differ in a few steps only; measured 7e-9 m after 7 mm of motion.
    np.testing.assert_allclose(off.position[-1], on.position[-1], rtol=0, atol=1e-7)


def test_scan_sensitivities_match_differences_of_the_same_steps(sc):
    """d(final X)/dμ by forward mode through the lean loop equals the central difference of its own
    solutions at μ ± 1e-5 (the same discrete map; measured agreement 7e-9 relative: the truncation of the
    difference, O(h²), and round-off / (2h) ~ 1e-11 m / 2e-5 over a derivative of 0.016 m)."""
    h = 1e-5
    res = scan(
        sc,
        {MU: [0.3 - h, 0.3, 0.3 + h]},
        jh.Times(T1, n=2),
        observables=["final_x"],
        options=jh.SolverOptions(diffrax.Bosh3(), diffrax.ConstantStepSize(), dt0=DT),
        derivatives=True,
        batch=jh.BatchOptions(lanes=4),
    )
    assert np.all(res.ok) and np.all(res.num_accepted_steps == round(T1 / DT))
    x, dx = res["final_x"], res["d_final_x"][:, 0]
    central = (x[2] - x[0]) / (2 * h)
    assert dx[1] < 0.0  # more friction, less far towards the boom
    assert dx[1] == pytest.approx(central, rel=1e-7)


def test_too_many_steps_refused_before_compiling(sc):
    with pytest.raises(jh.ScenarioError, match="max_steps"):
        scan(
            sc,
            {MU: [0.3]},
            T1,
            options=jh.SolverOptions(diffrax.Bosh3(), diffrax.ConstantStepSize(), dt0=DT, max_steps=100),
        )
