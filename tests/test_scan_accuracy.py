"""Scans that report their own accuracy (`AccuracyCheck`): the report agrees with an independent tight solve
of the same members, is on by default only for big scans, flags a deliberately loose scan, and reaches
scan.json and the command line. One small scan of paper-4.2 over 1 s, on 21 saved times with the position
history kept (the member made inaccurate on purpose shows only in its history); the default, the loose and
the reference programs are each compiled once and shared by every test."""

from __future__ import annotations

import copy
import json
import re
import types

import numpy as np
import pytest
from conftest import N_SAVE, run

import jaxhoist as jh
from jaxhoist._apps.cli.app import main
from jaxhoist._apps.scan import accuracy as acc

T1 = 1.0
MU = np.linspace(0.2, 0.6, 8)
CHECK = jh.AccuracyCheck(members=4, seed=0)
# every scan here: one program for the default and the loose options (the tolerances are values of the
# program), one for the reference (its step budget)
TIMES = jh.Times(T1, n=21)
HISTORIES = ("position",)


@pytest.fixture(scope="module")
def scenario():
    return jh.load_scenario("paper-4.2")


@pytest.fixture(scope="module")
def checked(scenario):
    return jh.scan(
        scenario, jh.Sweep("foundation.friction_coefficient", MU), TIMES, histories=HISTORIES, accuracy=CHECK
    )


class References(dict):
    """An independent tight solve of a member, on demand: `simulate`, not the scan's batch core, with another
    solver than the report's reference (Tsit5 at rtol 1e-8, tests/conftest.py's `run`: the physics tests'
    compiled solve of paper-4.2 on `N_SAVE` saved times, loaded rather than compiled in the suite)."""

    def __init__(self, scenario):
        super().__init__()
        self.scenario = scenario

    def __missing__(self, i):
        sc = self.scenario.replace(**{"foundation.friction_coefficient": float(MU[i])})
        tr = run(sc, np.linspace(0.0, T1, N_SAVE))
        self[i] = np.asarray(tr.position)[-1]
        return self[i]


@pytest.fixture(scope="module")
def references(scenario):
    return References(scenario)


def test_report_matches_an_independent_tight_solve(checked, references):
    rep = checked.accuracy
    assert rep["members"] == 4 and len(set(rep["indices"])) == 4
    most, drawn = acc.choose(checked, CHECK)  # seeded: the same members
    assert rep["indices"] == sorted([*most.tolist(), *drawn.tolist()])
    assert rep["chosen"] == {"most_steps": most.tolist(), "random": drawn.tolist(), "more": []}
    steps = checked.num_accepted_steps + checked.num_rejected_steps
    assert len(most) == 2 and min(steps[most]) >= max(np.delete(steps, most))  # the two with the most steps
    d = [np.linalg.norm(checked["final_position"][i] - references[i]) for i in rep["indices"]]
    fp = rep["observables"]["final_position"]
    assert fp["kind"] == "length" and fp["target"] == 0.01
    # the report's reference (rtol 5e-7) and the independent solve (rtol 1e-8) err by ~1e-3 of the scan's
    # error or less: the maxima agree to a few %
    assert fp["max"] == pytest.approx(max(d), rel=0.05, abs=1e-7)
    d_drawn = [np.linalg.norm(checked["final_position"][i] - references[i]) for i in drawn]
    assert fp["median"] == pytest.approx(float(np.median(d_drawn)), rel=0.05, abs=1e-7)  # the random half
    assert 0 < fp["max"] < 0.01 and fp["over_target"] == 0 and rep["suggest"] is None
    assert rep["observables"]["max_tilt"]["kind"] == "relative"
    # no lift-off within 1 s: inf in both solves is agreement, not an undefined difference
    assert rep["observables"]["liftoff_time"]["max"] == 0.0
    assert rep["over_target"] == 0 and rep["reference"]["rtol"] == 5e-7
    line = acc.summary(rep)
    assert line.startswith("4 members re-solved (2 with the most steps) at rtol 5e-07: final_position max ")
    assert "0 over 1 cm" in line and rep["rounds"] == 1 and rep["chosen"]["more"] == []


def test_on_by_default_only_for_big_scans():
    assert acc.resolve(None, acc.AUTO_MIN_MEMBERS - 1) is None
    assert acc.resolve(None, acc.AUTO_MIN_MEMBERS) == jh.AccuracyCheck()
    assert acc.resolve(False, 10**6) is None
    assert acc.resolve(True, 3) == jh.AccuracyCheck()
    assert acc.resolve(CHECK, 3) is CHECK
    with pytest.raises(jh.ScenarioError, match="accuracy must be"):
        acc.resolve("yes", 3)
    with pytest.raises(jh.ScenarioError, match="members"):
        jh.AccuracyCheck(members=0)
    with pytest.raises(jh.ScenarioError, match="length_target"):
        jh.AccuracyCheck(length_target=-1.0)


def test_small_scan_is_not_checked_by_default(scenario, checked, monkeypatch):
    calls = []
    monkeypatch.setattr(acc, "check_accuracy", lambda *a, **k: calls.append(1) or {})
    sweep = jh.Sweep("foundation.friction_coefficient", MU)
    res = jh.scan(scenario, sweep, TIMES, histories=HISTORIES)  # the compiled program
    assert res.accuracy is None and not calls
    monkeypatch.setattr(acc, "AUTO_MIN_MEMBERS", len(MU))  # as if 8 members were a big scan
    res = jh.scan(scenario, sweep, TIMES, histories=HISTORIES)
    assert calls == [1] and res.accuracy == {}
    # the check only reads the result: the members' values are those of the checked scan, bit for bit
    for name, v in checked.data.items():
        np.testing.assert_array_equal(res.data[name], v, err_msg=name)
    np.testing.assert_array_equal(res.num_accepted_steps, checked.num_accepted_steps)


def test_loose_scan_is_flagged(scenario, references):
    loose = jh.SolverOptions(rtol=3e-2, atol=6e-4)
    check = jh.AccuracyCheck(members=4, seed=0, length_target=1e-3)
    res = jh.scan(
        scenario,
        jh.Sweep("foundation.friction_coefficient", MU),
        TIMES,
        histories=HISTORIES,
        options=loose,
        accuracy=check,
    )
    assert res.ok.all()  # the status does not see it: only the accuracy report does
    rep = res.accuracy
    assert rep["reference"]["rtol"] == 5e-7  # 1000x tighter, capped: the same reference program
    d = np.array([np.linalg.norm(res["final_position"][i] - references[i]) for i in rep["indices"]])
    assert (d > 1e-3).sum() >= 1
    assert rep["observables"]["final_position"]["over_target"] == (d > 1e-3).sum()
    assert rep["over_target"] >= (d > 1e-3).sum()
    assert rep["suggest"] == pytest.approx({"rtol": 3e-3, "atol": 6e-5})
    line = acc.summary(rep, lambda k, x: f"--{k} {x:.0e}")
    assert "over 1 mm" in line and "for more accuracy: --rtol 3e-03 --atol 6e-05" in line


def test_failed_members_are_not_chosen(checked):
    failed = copy.copy(checked)
    failed.status = np.where(np.arange(len(MU)) % 2 == 0, 0, int(jh.SolveStatus.MAX_STEPS))
    both = lambda check: set(np.concatenate(acc.choose(failed, check)).tolist())  # noqa: E731
    assert both(jh.AccuracyCheck(members=16)) == {0, 2, 4, 6}
    assert both(jh.AccuracyCheck(members=3)) < {0, 2, 4, 6}
    assert [x.tolist() for x in acc.choose(checked, CHECK)] == [
        x.tolist() for x in acc.choose(checked, CHECK)
    ]
    with pytest.raises(jh.ScenarioError, match="most_steps"):
        jh.AccuracyCheck(most_steps=1.5)


def test_the_member_with_the_most_steps_is_chosen_and_reported(scenario):
    """One member made inaccurate on purpose: its path is moved 2 cm in the middle of the lift (its end
    unchanged) and it is given the most solver steps. A check of 4 of 8 members, half of them for their steps,
    re-solves it whatever the seed and reports exactly that member over 1 cm, through the kept history
    (the final position alone would not show it); a random check of 1 member (`most_steps=0`) misses it
    for some seed."""
    sweep = jh.Sweep("foundation.friction_coefficient", MU)
    res = jh.scan(scenario, sweep, TIMES, histories=HISTORIES, accuracy=False)  # the checked scan's program
    bad = 5
    res.histories["position"] = res.histories["position"].copy()
    res.histories["position"][bad, 10, 0] += 0.02
    res.num_accepted_steps = res.num_accepted_steps.copy()
    res.num_accepted_steps[bad] = res.num_accepted_steps.max() + 1

    def run_scan(sc, sw, t, *, observables, options, histories):
        return jh.scan(
            sc, sw, t, observables=observables, options=options, histories=histories, accuracy=False
        )

    def report(check):
        return acc.check_accuracy(
            res,
            check,
            scenario=scenario,
            ts=res.ts,
            observables=list(res.data),  # the default observables, by name
            options=jh.SolverOptions(),
            run_scan=run_scan,
        )

    for seed in (0, 1, 2):
        rep = report(jh.AccuracyCheck(members=4, seed=seed))
        assert bad in rep["chosen"]["most_steps"] and len(rep["chosen"]["random"]) == 2
        assert rep["over_target"] == 1 and rep["suggest"] is not None
        pos = rep["histories"]["position"]
        assert pos["kind"] == "length" and pos["over_target"] == 1
        assert pos["max"] == pytest.approx(0.02, abs=1e-3)  # the 2 cm put in, over the scan's own error
        assert rep["observables"]["final_position"]["over_target"] == 0
        assert re.search(r"position \(history\) max 2(\.\d)? cm, .*; 1 over 1 cm", acc.summary(rep))
    random_only = [
        bad in acc.choose(res, jh.AccuracyCheck(members=1, most_steps=0.0, seed=s))[1] for s in range(8)
    ]
    assert not all(random_only)


def test_differences_near_the_target_re_solve_more_by_steps(checked):
    """The escalation, with the scan's own values as the reference (no solve): member 0 has the most steps
    and is 4 mm off (within 4x of 1 cm), member 3, fourth by steps, is 2 cm off. A check of 2 members
    re-solves 2 more at a time, by steps, until it meets member 3, reports it alone over 1 cm and stops
    there; with `margin=1` it stops after the first round; a scan with no difference needs one round."""
    clean = copy.copy(checked)
    clean.num_accepted_steps = np.arange(len(MU))[::-1] * 10 + 100  # member 0 the most steps, then 1, 2, ...
    clean.num_rejected_steps = np.zeros(len(MU), dtype=int)
    off = copy.copy(clean)
    off.data = dict(clean.data, final_position=clean.data["final_position"].copy())
    off.data["final_position"][0, 0] += 0.004
    off.data["final_position"][3, 1] += 0.02

    def run_scan(sc, sw, t, *, observables, options, histories):
        rows = [int(np.flatnonzero(MU == m)[0]) for m in sw.values["foundation.friction_coefficient"]]
        data = {k: v[rows] for k, v in clean.data.items()}
        histories = {k: v[rows] for k, v in clean.histories.items()}  # the result's own: no difference
        return types.SimpleNamespace(ok=np.ones(len(rows), dtype=bool), data=data, histories=histories)

    def report(result, **kw):
        check = jh.AccuracyCheck(members=2, seed=0, **kw)
        args = dict(
            scenario=None, ts=clean.ts, observables=None, options=jh.SolverOptions(), run_scan=run_scan
        )
        return acc.check_accuracy(result, check, **args)

    rep = report(off)
    first = rep["chosen"]["most_steps"] + rep["chosen"]["random"]
    assert rep["chosen"]["most_steps"] == [0] and 3 not in first
    later = [i for i in range(len(MU)) if i not in first][:4]  # by steps: the next ones, two at a time
    assert rep["chosen"]["more"] == later[: 2 * ((later.index(3) + 2) // 2)]  # whole rounds, to member 3
    assert rep["over_target"] == 1 and rep["observables"]["final_position"]["over_target"] == 1
    assert rep["observables"]["final_position"]["max"] == pytest.approx(0.02)
    assert rep["rounds"] == 1 + len(rep["chosen"]["more"]) // 2 and rep["members"] == len(rep["indices"])
    once = report(off, margin=1.0)
    assert once["rounds"] == 1 and once["over_target"] == 0 and once["chosen"]["more"] == []
    capped = report(off, max_members=3)
    assert capped["members"] == 3 and capped["rounds"] == 2 and len(capped["chosen"]["more"]) == 1
    healthy = report(clean)
    assert healthy["rounds"] == 1 and healthy["members"] == 2 and healthy["over_target"] == 0


def test_cli_prints_the_line_and_scan_json_carries_it(checked, tmp_path, capsys):
    out = tmp_path / "scan"
    argv = ["scan", "paper-4.2", "--param", "foundation.friction_coefficient", "--values", "0.2:0.6:8"]
    argv += ["--t1", str(T1), "--n-save", "21", "--history", "position", "--accuracy-members", "4"]
    rc = main([*argv, "--out", str(out), "--quiet", "--no-plots"])
    assert rc == 0
    lines = [s for s in capsys.readouterr().out.splitlines() if s.startswith("accuracy")]
    assert len(lines) == 1
    assert lines[0] == "accuracy      " + acc.summary(checked.accuracy)
    meta = json.loads((out / "scan.json").read_text())
    assert meta["attrs"]["accuracy"]["indices"] == checked.accuracy["indices"]
    assert meta["attrs"]["accuracy"]["observables"]["final_position"]["max"] == pytest.approx(
        checked.accuracy["observables"]["final_position"]["max"]
    )
    assert jh.ScanResult.load(out / "scan").accuracy == meta["attrs"]["accuracy"]
