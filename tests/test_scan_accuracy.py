"""Scans that report their own accuracy (`AccuracyCheck`): the report agrees with an independent tight solve
of the same members, is on by default only for big scans, flags a deliberately loose scan, and reaches
scan.json and the command line. One small scan of paper-4.2 over 1 s; the default, the loose and the
reference programs are each compiled once and shared."""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest

import jaxhoist as jh
from jaxhoist._apps.cli.app import main
from jaxhoist._apps.scan import accuracy as acc

T1 = 1.0
MU = np.linspace(0.2, 0.6, 8)
CHECK = jh.AccuracyCheck(members=4, seed=0)


@pytest.fixture(scope="module")
def scenario():
    return jh.load_scenario("paper-4.2")


@pytest.fixture(scope="module")
def checked(scenario):
    return jh.scan(scenario, jh.Sweep("foundation.friction_coefficient", MU), T1, accuracy=CHECK)


@pytest.fixture(scope="module")
def references(scenario, checked):
    """An independent tight solve of each re-solved member: `simulate`, not the scan's batch core."""
    opts = acc.reference_options(CHECK, jh.SolverOptions())
    out = {}
    for i in checked.accuracy["indices"]:
        sc = scenario.replace(**{"foundation.friction_coefficient": float(MU[i])})
        tr = jh.simulate(sc, jh.Times(T1, n=201), options=opts)
        out[i] = np.asarray(tr.position)[-1]
    return out


def test_report_matches_an_independent_tight_solve(checked, references):
    rep = checked.accuracy
    assert rep["members"] == 4 and len(set(rep["indices"])) == 4
    assert rep["indices"] == [int(i) for i in acc.choose(checked, CHECK)]  # seeded: the same members
    d = [np.linalg.norm(checked["final_position"][i] - references[i]) for i in rep["indices"]]
    fp = rep["observables"]["final_position"]
    assert fp["kind"] == "length" and fp["target"] == 0.01
    # the reference's own error (rtol 5e-7) is ~1e-3 of the scan's: the maxima agree to a few %
    assert fp["max"] == pytest.approx(max(d), rel=0.05, abs=1e-7)
    assert fp["median"] == pytest.approx(float(np.median(d)), rel=0.05, abs=1e-7)
    assert 0 < fp["max"] < 0.01 and fp["over_target"] == 0 and rep["suggest"] is None
    assert rep["observables"]["max_tilt"]["kind"] == "relative"
    # no lift-off within 1 s: inf in both solves is agreement, not an undefined difference
    assert rep["observables"]["liftoff_time"]["max"] == 0.0
    assert rep["over_target"] == 0 and rep["reference"]["rtol"] == 5e-7
    line = acc.summary(rep)
    assert line.startswith("4 members re-solved at rtol 5e-07: final_position max ") and "0 over 1 cm" in line


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
    res = jh.scan(scenario, jh.Sweep("foundation.friction_coefficient", MU), T1)  # the compiled program
    assert res.accuracy is None and not calls
    monkeypatch.setattr(acc, "AUTO_MIN_MEMBERS", len(MU))  # as if 8 members were a big scan
    res = jh.scan(scenario, jh.Sweep("foundation.friction_coefficient", MU), T1)
    assert calls == [1] and res.accuracy == {}


def test_loose_scan_is_flagged(scenario, references):
    loose = jh.SolverOptions(rtol=3e-2, atol=6e-4)
    check = jh.AccuracyCheck(members=4, seed=0, length_target=1e-3)
    res = jh.scan(
        scenario, jh.Sweep("foundation.friction_coefficient", MU), T1, options=loose, accuracy=check
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
    assert set(acc.choose(failed, jh.AccuracyCheck(members=16))) == {0, 2, 4, 6}
    assert set(acc.choose(failed, jh.AccuracyCheck(members=3))) < {0, 2, 4, 6}
    assert acc.choose(checked, CHECK).tolist() == acc.choose(checked, CHECK).tolist()


def test_cli_prints_the_line_and_scan_json_carries_it(checked, tmp_path, capsys):
    out = tmp_path / "scan"
    argv = ["scan", "paper-4.2", "--param", "foundation.friction_coefficient", "--values", "0.2:0.6:8"]
    rc = main([*argv, "--t1", str(T1), "--accuracy-members", "4", "--out", str(out), "--quiet", "--no-plots"])
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
