"""Never silently wrong: every solve checks its own energy balance (`SolveStatus.ENERGY_BALANCE`), and a
parameter outside its plausible range (a typo like 1e16 for 1e6) is refused unless the scenario opts in
with `allow_implausible`, under which the solve's own checks still apply.

The broken case throughout: paper-4.2 with rope.stiffness = 1e16 N/m. The default Rosenbrock-W solver
"succeeds" on it over 1 s with a rope tension of 0 N and the load risen, and an energy balance open by
~0.9 of the energy that flowed."""

import contextlib
import dataclasses
import io
import re
from unittest import mock

import equinox as eqx
import numpy as np
import pytest
from conftest import N_SAVE

import jaxhoist as jh
import jaxhoist._numerics.solve as solve_mod
from jaxhoist._apps import cli
from jaxhoist._errors import MAX_MESSAGE_CHARS
from jaxhoist._physics import energy
from jaxhoist._physics.checks import PLAUSIBLE
from jaxhoist._physics.paths import get_leaf

BROKEN = {"rope.stiffness": 1e16}
# N_SAVE saved times with the default options: the compiled core of test_rosenbrock.py's `default_run` (the
# labels and `allow_implausible` are not part of the program)
TIMES = jh.Times(1.0, n=N_SAVE)
# The scan's saved times (its group program is this file's own)
SCAN_TIMES = jh.Times(1.0, n=51)


def _core_must_not_run(*args, **kwargs):
    raise AssertionError("the jitted core was reached with an implausible scenario")


def _named(path: str) -> str:
    return r"(?<![\w.])" + re.escape(path) + r"(?![\w])"


@pytest.fixture(scope="module")
def broken(paper42):
    return paper42.replace(**BROKEN, allow_implausible=True)


@pytest.fixture(scope="module")
def broken_traj(broken):
    return jh.simulate(broken, TIMES, throw=False)


# ------------------------------------------------------------------------ the relative residual


def test_relative_balance_residual_by_hand():
    """Hand-made histories [J]: a closed balance gives 0; a balance open by R relative to the energy that
    flowed gives R / (ΔE + W + D + F) (their largest sum over time), independent of the energy's origin."""
    hoist = np.array([0.0, 100.0, 300.0])
    damping = np.array([0.0, 10.0, 30.0])
    friction = np.array([0.0, 40.0, 70.0])
    mech = 5e4 + hoist - damping - friction  # closed: E(t) - E(0) = W - D - F
    closed = energy.relative_balance_residual(mech, hoist, damping, friction, xp=np)
    assert closed == pytest.approx(0.0, abs=1e-12)
    off = mech + np.array([0.0, 0.0, 40.0])  # 40 J created from nothing at the end
    flow = (200.0 + 40.0) + 300.0 + 30.0 + 70.0  # |ΔE| + W + D + F at the last time
    rel = energy.relative_balance_residual(off, hoist, damping, friction, xp=np)
    assert rel == pytest.approx(40.0 / (flow + energy.BALANCE_FLOOR * (5e4 + 240.0)), rel=1e-12)
    shifted = energy.relative_balance_residual(off + 1e3, hoist, damping, friction, xp=np)
    assert shifted == pytest.approx(rel, rel=1e-6)  # only the floor sees the energy's origin
    # a scenario in which nothing happens: no energy flows, the balance closes at round-off level
    still = energy.relative_balance_residual(np.full(3, 5e4) + [0, 1e-11, 0], *np.zeros((3, 3)), xp=np)
    assert still < 1e-6
    # NaN is never "ok": the solve compares `not rel <= bound`
    assert np.isnan(energy.relative_balance_residual(mech * np.nan, hoist, damping, friction, xp=np))


# ------------------------------------------------------------------------ the solve's status


def test_healthy_solve_passes_the_energy_check_with_margin(paper42):
    """paper-4.2 over 1 s with the default solver: status ok, and the relative residual far below the
    bound (measured 1e-5 to 4e-4 on the presets and random plausible scenarios)."""
    tr = jh.simulate(paper42.replace(allow_implausible=True), TIMES)
    assert int(tr.status) == jh.SolveStatus.OK
    assert float(tr.energy_check()) < energy.BALANCE_BOUND / 20, float(tr.energy_check())


def test_rope_of_1e16_is_marked_energy_balance_never_ok(broken_traj):
    """The default solver reports success on a rope of 1e16 N/m, but its result is wrong: the tension is 0
    at every saved time while the load is hoisted; the energy check marks it."""
    tr = broken_traj
    assert int(tr.status) == jh.SolveStatus.ENERGY_BALANCE
    assert not bool(tr.ok)
    assert float(tr.energy_check()) > 0.5  # measured 0.91
    assert float(np.max(np.abs(np.asarray(tr.rope_tension)))) == 0.0  # the symptom the check catches
    assert jh.SolveStatus.ENERGY_BALANCE.message.startswith("the solver reported success but the energy")


def test_throw_raises_on_an_open_energy_balance(broken):
    """`throw=True` (the default) raises for an open energy balance as for any other failure."""
    with pytest.raises(Exception, match="energy balance does not close"):
        jh.simulate(broken, TIMES)


def test_the_check_only_reads_the_result(paper42, broken_traj):
    """The broken trajectory is what the solver returned (not NaN-ed): the status is the only change."""
    assert np.all(np.isfinite(np.asarray(broken_traj.position)))


# ------------------------------------------------------------------------ scans


def test_scan_marks_exactly_the_broken_member(paper42):
    """A scan with one broken member (rope 1e16 N/m, the default solver): that member, and only it, is
    `ENERGY_BALANCE`, its observables NaN and its reason given; the others are ok and equal, bit for bit,
    to a scan without it (they are never averaged with it)."""
    ks = np.array([1.4e7, 1e16, 2e7, 3e7])
    kw = dict(observables=["final_position"], batch=jh.BatchOptions(lanes=2, sort=False))
    res = jh.scan(paper42.replace(allow_implausible=True), {"rope.stiffness": ks}, SCAN_TIMES, **kw)
    assert list(res.status) == [0, jh.ScanStatus.ENERGY_BALANCE, 0, 0]
    assert [f["index"] for f in res.failures()] == [1]
    assert res.failures()[0]["status"] == "energy_balance"
    assert "energy balance" in res.reason(1)
    assert np.all(np.isnan(res["final_position"][1]))
    assert res.status_counts() == {"ok": 3, "energy_balance": 1}
    ks_clean = ks.copy()
    ks_clean[1] = 1.4e7
    clean = jh.scan(paper42, {"rope.stiffness": ks_clean}, SCAN_TIMES, **kw)
    np.testing.assert_array_equal(res["final_position"][[0, 2, 3]], clean["final_position"][[0, 2, 3]])
    # without the opt-in, the implausible member is refused on the host, not solved
    refused = jh.scan(paper42, {"rope.stiffness": ks}, SCAN_TIMES, **kw)
    assert refused.status[1] == jh.ScanStatus.INVALID_PARAMETER and "plausible range" in refused.reason(1)
    np.testing.assert_array_equal(refused["final_position"][[0, 2, 3]], clean["final_position"][[0, 2, 3]])


# ------------------------------------------------------------------------ plausible ranges


def _ranges(module, prefix=""):
    """(dotted path, PlausibleRange) of every field of `module` that has one."""
    out = []
    for f in dataclasses.fields(module):
        v = getattr(module, f.name, None)
        if isinstance(v, eqx.Module):
            out += _ranges(v, f"{prefix}{f.name}.")
        elif PLAUSIBLE in f.metadata:
            out.append((f"{prefix}{f.name}", f.metadata[PLAUSIBLE]))
    return out


def _all_ranges(paper42):
    bristle = eqx.tree_at(lambda s: s.foundation.friction, paper42, jh.BristleFriction())
    ramped = eqx.tree_at(lambda s: s.hoist, paper42, jh.RampedHoist(0.3, 1.0))
    seen = dict(_ranges(paper42))
    for sc in (bristle, ramped):
        seen.update(dict(_ranges(sc)))
    return seen, paper42, bristle, ramped


def _scenario_with(paper42, path):
    _, *scs = _all_ranges(paper42)
    return next(sc for sc in scs if any(p == path for p, _ in _ranges(sc)))


#: Every float parameter but the box geometry's (mass centre, rope point: bounded by the box) and the
#: bristle's break-away ratio (bounded to [0, 1) by its law).
RANGED = (
    "load.size",
    "load.mass",
    "foundation.stiffness",
    "foundation.damping",
    "foundation.friction_coefficient",
    "foundation.damping_onset",
    "foundation.friction.regularisation_velocity",
    "foundation.friction.deflection",
    "foundation.friction.relaxation_time",
    "rope.stiffness",
    "rope.damping",
    "rope.slack",
    "rope.damping_onset",
    "hoist.speed",
    "hoist.ramp_time",
    "hoist.travel",
    "boom.tip_position",
    "boom.tip_mass",
    "boom.stiffness",
    "boom.damping",
    "gravity",
)


def test_every_parameter_has_a_plausible_range(paper42):
    """Every parameter of `RANGED`, and no other, carries a range with a reason."""
    seen, *_ = _all_ranges(paper42)
    assert set(seen) == set(RANGED)
    for path, rng in seen.items():
        assert rng.low < rng.high and len(rng.why) > 10, path


def _with_value(sc, path, value):
    """`sc` with the leaf at `path` set to `value` everywhere (a box's size moves its mass centre and rope
    point along, so the box geometry stays valid and the range is what is tested)."""
    shape = np.shape(get_leaf(sc, path))
    new = {path: np.full(shape, value)}
    if path == "load.size":
        new.update({"load.mass_centre": np.full(3, 0.4 * value), "rope.attachment": np.zeros(3)})
    return sc.replace(**new)


@pytest.mark.parametrize("path", RANGED)
def test_each_range_refuses_outside_and_admits_its_ends(paper42, path):
    """Ten times beyond either end (an order of magnitude: a typo) is refused with one line naming the
    field, the value, the range and the opt-in, before compiling; the ends themselves pass the range
    check; with `allow_implausible` the value beyond passes too."""
    seen, *_ = _all_ranges(paper42)
    rng = seen[path]
    sc = _scenario_with(paper42, path)
    outside = [rng.high * 10.0 if rng.high > 0 else rng.high - 10.0]
    if rng.low > 0:
        outside.append(rng.low / 10.0)
    elif rng.low < 0:
        outside.append(rng.low * 10.0)
    for value in outside:
        bad = _with_value(sc, path, value)
        with mock.patch.object(solve_mod, "_core", _core_must_not_run):
            with pytest.raises(jh.ScenarioError) as info:
                jh.simulate(bad, 0.1)
        msg = str(info.value)
        assert re.search(_named(path), msg) and "plausible range" in msg, msg
        assert "allow_implausible=True" in msg and "--allow-implausible" in msg, msg
        assert "\n" not in msg and len(msg) <= MAX_MESSAGE_CHARS
        try:
            bad.replace(allow_implausible=True).check()
        except jh.ScenarioError as e:  # only the hard checks may still refuse (e.g. the ground's sinking)
            assert "plausible range" not in str(e), str(e)
    for value in (rng.low, rng.high):
        ok = _with_value(sc, path, value)
        try:
            ok.check()
        except jh.ScenarioError as e:
            assert "plausible range" not in str(e), (path, value, str(e))


def test_the_documented_table_is_the_metadata(paper42):
    """docs/scenario-files.md lists every range as the metadata has it (the docs state what is true)."""
    from pathlib import Path

    text = (Path(__file__).parents[1] / "docs" / "scenario-files.md").read_text()
    seen, *_ = _all_ranges(paper42)
    for path, rng in seen.items():
        m = re.search(r"\| `" + re.escape(path) + r"` \| (\S+) – (\S+)", text)
        assert m, path
        low, high = (float(x.replace("−", "-")) for x in m.groups())
        assert (low, high) == (rng.low, rng.high), (path, low, high, rng)


def test_zero_is_a_switch_where_the_range_says_so(paper42):
    """No damping, no slack, no friction, no hoisting: 0 is admitted where it switches a term off."""
    paper42.replace(
        **{
            "foundation.damping": 0.0,
            "rope.damping": 0.0,
            "boom.damping": 0.0,
            "rope.slack": 0.0,
            "foundation.friction_coefficient": 0.0,
            "hoist.speed": 0.0,
            "rope.damping_onset": 0.0,
            "foundation.damping_onset": 0.0,
        }
    ).check()


@pytest.mark.parametrize(
    "path,value",
    [("rope.stiffness", 1e16), ("boom.tip_mass", 1e-12), ("foundation.friction_coefficient", 1e4)],
)
def test_absurd_values_are_refused_and_solved_with_the_opt_in(paper42, path, value):
    with mock.patch.object(solve_mod, "_core", _core_must_not_run):
        with pytest.raises(jh.ScenarioError, match=_named(path)):
            jh.simulate(paper42.replace(**{path: value}), 0.1)
    opted = paper42.replace(**{path: value}, allow_implausible=True)
    assert opted.allow_implausible and not paper42.allow_implausible
    opted.check()
    # the opt-in survives a later change of a leaf, and a copy with new labels
    assert opted.replace(**{"hoist.speed": 0.2}).allow_implausible
    assert dataclasses.replace(opted, name="renamed").allow_implausible


def test_presets_and_the_random_plausible_scenarios_are_inside_every_range(paper42):
    """The presets, and the corners of the random plausible scenarios of the robustness study (friction
    0.05-0.9, ground 1e6-1e9 N/m, regularisation 1e-4-1e-2 m/s, rope 1e6-1e8 N/m, hoist 0.05-1 m/s), pass."""
    for name in ("paper-2.3", "paper-4.1", "paper-4.2", "paper-4.3"):
        jh.load_scenario(name).check()
    for corner in (0, 1):
        paper42.replace(
            **{
                "foundation.friction_coefficient": (0.05, 0.9)[corner],
                "foundation.stiffness": (1e6, 1e9)[corner],
                "foundation.friction.regularisation_velocity": (1e-4, 1e-2)[corner],
                "rope.stiffness": (1e6, 1e8)[corner],
                "hoist.speed": (0.05, 1.0)[corner],
            }
        ).check()


def _toml(tmp_path, old, new):
    from importlib import resources

    text = resources.files("jaxhoist._io.presets").joinpath("paper-4.2.toml").read_text()
    assert old in text
    path = tmp_path / "typo.toml"
    path.write_text(text.replace(old, new))
    return path


def test_file_with_a_typo_is_refused_and_loads_with_the_opt_in(tmp_path):
    path = _toml(tmp_path, "stiffness = 1.4e7", "stiffness = 1.4e17")
    with pytest.raises(jh.ScenarioError) as info:
        jh.load_scenario(path)
    msg = str(info.value)
    assert re.search(_named("rope.stiffness"), msg) and "1.4e+17" in msg and str(path) in msg, msg
    sc = jh.load_scenario(path, allow_implausible=True)
    assert sc.allow_implausible and float(sc.rope.stiffness) == 1.4e17


def test_implausible_density_in_a_file(tmp_path):
    path = _toml(tmp_path, "density = 850.0", "density = 2e5")
    with pytest.raises(jh.ScenarioError, match=_named("load.density") + ".*plausible range"):
        jh.load_scenario(path)
    assert float(jh.load_scenario(path, allow_implausible=True).load.mass) == pytest.approx(2e5 * 37.5)


# ------------------------------------------------------------------------ the command line


def _cli(argv):
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = cli.main(argv)
    return code, out.getvalue(), err.getvalue()


def test_cli_refuses_the_typo_and_marks_the_opted_in_solve(tmp_path):
    """`simulate --set rope.stiffness=1e16` exits 2 with one line naming the field and the flag; with
    `--allow-implausible` it is solved and exits 1, its summary saying energy_balance."""
    # 11 saved times: the short command of tests/test_cli.py and test_cli_messages.py (one compiled core)
    base = ["simulate", "paper-4.2", "--t1", "1", "--n-save", "11", "--quiet", "--no-plots"]
    code, _, err = _cli([*base, "--out", str(tmp_path / "a"), "--set", "rope.stiffness=1e16"])
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert code == 2 and len(lines) == 1, (code, lines)
    assert "rope.stiffness" in lines[0] and "pass --allow-implausible" in lines[0], lines[0]
    assert "allow_implausible=True" not in lines[0], lines[0]  # the CLI's words, not Python's
    assert not (tmp_path / "a").exists()
    code, out, _ = _cli(
        [*base, "--out", str(tmp_path / "b"), "--set", "rope.stiffness=1e16", "--allow-implausible"]
    )
    assert code == 1
    status_line = next(ln for ln in out.splitlines() if ln.startswith("status"))
    assert "energy_balance" in status_line and "energy balance does not close" in status_line
