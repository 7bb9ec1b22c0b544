"""`jaxhoist.Times`: the saved times of every entry point: resolution, defaults, checks before
anything is compiled, `as_times`, and a traced t1 under `jax.jit`."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import N_SAVE, SOLVE_OPTIONS

import jaxhoist as jh
from jaxhoist._numerics.times import as_times


@pytest.fixture(scope="module")
def sc():
    return jh.load_scenario("paper-4.2")  # t1 = 25 s


def test_resolution_and_defaults(sc):
    t1, ts = jh.Times(2.0).resolve(sc, 5)
    assert t1 == 2.0
    np.testing.assert_array_equal(ts, np.linspace(0.0, 1.0, 5) * 2.0)
    t1, ts = jh.Times(2.0, n=3).resolve(sc, 5)
    np.testing.assert_array_equal(ts, [0.0, 1.0, 2.0])
    t1, ts = jh.Times().resolve(sc, 3)  # the scenario's t1, the entry point's default n
    assert t1 == sc.t1 == 25.0
    np.testing.assert_array_equal(ts, [0.0, 12.5, 25.0])
    given = np.array([0.0, 0.5, 2.0])
    t1, ts = jh.Times(ts=given).resolve(sc, 5)  # t1 from ts; the given array as it is
    assert t1 == 2.0 and ts is given
    t1, ts = jh.Times(ts=[0, 1, 3]).resolve(sc, 5)  # a sequence becomes a float64 array
    assert t1 == 3.0 and ts.dtype == np.float64
    t1, ts = jh.Times(2.0).resolve(sc, 5, jnp)  # jax.numpy: the grid simulate has always built
    assert isinstance(ts, jax.Array)
    np.testing.assert_array_equal(ts, jnp.linspace(0.0, 1.0, 5) * jnp.asarray(2.0, dtype=jnp.float64))
    assert jh.Times(2.0).count(7) == 7 and jh.Times(2.0, n=4).count(7) == 4
    assert jh.Times(ts=given).count(7) == 3
    assert jh.Times(n=np.int64(4)).n == 4 and isinstance(jh.Times(n=np.int64(4)).n, int)


@pytest.mark.parametrize(
    "kw, match",
    [
        (dict(t1=-1.0), r"^t1 must be a positive finite time \[s\], got -1.0$"),
        (dict(t1=float("inf")), r"^t1 must be a positive finite time"),
        (dict(t1="25"), r"^t1 must be an end time \[s\]"),
        (dict(t1=True), r"^t1 must be an end time \[s\]"),
        (dict(t1=np.array([1.0, 2.0])), r"^t1 must be an end time \[s\] \(one real number\)"),
        (dict(n=1), r"^n \(the number of saved times\) must be >= 2, got 1$"),
        (dict(n=2.0), r"^n \(the number of saved times\) must be an integer >= 2"),
        (dict(n=True), r"^n \(the number of saved times\) must be an integer"),
        (dict(ts=[0.0]), r"^ts must be a 1-D array of at least 2 times"),
        (dict(ts=np.zeros((2, 2))), r"^ts must be a 1-D array"),
        (dict(ts=[0.1, 0.2]), r"^ts must start at 0 s"),
        (dict(ts=[0.0, 0.2, 0.2]), r"^ts must start at 0 s and be finite and strictly increasing$"),
        (dict(ts=[0.0, np.nan]), r"^ts must start at 0 s"),
        (dict(ts=["0", "1"]), r"^ts must be an array of saved times \[s\]"),
        (dict(t1=1.0, ts=[0.0, 0.5]), r"^t1 = 1 s contradicts ts, which ends at 0.5 s"),
        (dict(n=3, ts=[0.0, 0.5]), r"^n = 3 contradicts ts, which holds 2 times"),
    ],
)
def test_bad_times_refused_in_one_line(kw, match):
    with pytest.raises(jh.ScenarioError, match=match) as e:
        jh.Times(**kw)
    assert "\n" not in str(e.value)


def test_a_bad_scenario_t1_or_default_n(sc):
    with pytest.raises(jh.ScenarioError, match=r"^n \(the number of saved times\) must be >= 2, got 1"):
        jh.Times(1.0).resolve(sc, 1)
    jh.Times(ts=[0.0, 1.0]).resolve(sc, 1)  # n is not used with ts


def test_as_times():
    t = jh.Times(1.0, n=3)
    assert as_times(t) is t
    assert as_times(None) == jh.Times()
    assert as_times(2.0) == jh.Times(2.0) and as_times(2) == jh.Times(2)
    assert as_times(np.float64(2.0)).t1 == 2.0
    assert as_times(jnp.asarray(2.0)).t1 == 2.0
    np.testing.assert_array_equal(as_times([0.0, 1.0]).ts, [0.0, 1.0])
    np.testing.assert_array_equal(as_times(np.array([0.0, 1.0])).ts, [0.0, 1.0])
    for bad in ("25 s", True, object()):
        with pytest.raises(jh.ScenarioError, match=r"^times must be a jaxhoist\.Times, an end time t1"):
            as_times(bad)
    with pytest.raises(jh.ScenarioError, match=r"^times as an array must be 1-D"):
        as_times(np.zeros((2, 2)))
    with pytest.raises(jh.ScenarioError, match=r"^t1 must be a positive finite time"):
        as_times(-1.0)


def test_traced_t1_stays_traced_under_jit(sc):
    """Under `jax.jit` a traced t1 skips the host checks and builds a traced grid (`xp=jax.numpy`); the
    same numbers as a concrete t1."""

    @jax.jit
    def grid(t1):
        t1_out, ts = jh.Times(t1, n=4).resolve(sc, 501, jnp)
        assert isinstance(ts, jax.core.Tracer) and t1_out is t1
        return ts

    np.testing.assert_array_equal(grid(3.0), jh.Times(3.0, n=4).resolve(sc, 501, jnp)[1])
    # and through simulate: one solve to a traced end time (XLA fuses the outer jit differently: equal to
    # round-off, not bit for bit). The shared solver settings and number of saved times of tests/conftest.py:
    # the concrete solve is the session's shared compiled core, and Tsit5 compiles faster than the default
    # Rosenbrock-W solver inside the outer jit.

    @jax.jit
    def final_x(t1):
        return jh.simulate(sc, jh.Times(t1, n=N_SAVE), options=SOLVE_OPTIONS).position[-1, 0]

    tr = jh.simulate(sc, jh.Times(0.05, n=N_SAVE), options=SOLVE_OPTIONS)
    assert float(final_x(0.05)) == pytest.approx(float(tr.position[-1, 0]), rel=1e-14)
