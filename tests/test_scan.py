"""`jaxhoist.scan` (with `_io/scan_store.py`, `_apps/scan/result.py`): chunked, vmapped, sharded scans.

The scans here share one compiled core (same scenario structure, observables, options, saved times and
chunk shape) wherever a test does not need another shape. The box is a 1 m cube of 1000 kg pulled
obliquely at 0.3 m/s by a stiff rope: within 0.3 s corners D and H leave the ground first, then E and F.
"""

import jax

jax.config.update("jax_enable_x64", True)  # tests/conftest.py also does this, and sets up two CPU devices

import dataclasses  # noqa: E402
import json  # noqa: E402
import re  # noqa: E402

import diffrax  # noqa: E402
import equinox as eqx  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

import jaxhoist as jh  # noqa: E402
from jaxhoist._apps.scan.run import ScanResult, ScanStatus, scan  # noqa: E402
from jaxhoist._apps.scan.sweep import members as _members  # noqa: E402
from jaxhoist._apps.scan.sweep import parse_values  # noqa: E402
from jaxhoist._numerics import observables as O  # noqa: E402
from jaxhoist._physics.paths import get_param, parse_path, set_param  # noqa: E402

MU = "foundation.friction_coefficient"
MUS = np.array([0.1, 0.2, 0.3, 0.4, 0.5, 0.6])
T1 = 0.3
TIMES = jh.Times(T1, n=31)
KW = dict(
    observables=[
        "final_position",
        "liftoff_time",
        "detachment_times",
        "contact_margin",
        "impact_times",
        "contact_time",
        "configuration_time",
        "max_tilt",
    ],
    batch=jh.BatchOptions(lanes=2),
    # Tsit5: these tests are about the scan machinery (layout, failures, store, sensitivities), and its poison
    # member below (μ = 1e4) must exhaust its steps (the default Rosenbrock-W solver, whose friction is
    # implicit, solves it). The default solver's layout independence is tested on its own below.
    options=jh.SolverOptions(diffrax.Tsit5(), max_steps=3000),
)


def kw(**batch) -> dict:
    """`KW` with more `BatchOptions` (chunk size, devices, ...) besides its 2 lanes."""
    return {**KW, "batch": jh.BatchOptions(lanes=2, **batch)}


def oblique_box() -> jh.Scenario:
    return jh.Scenario(
        load=jh.Load([1.0, 1.0, 1.0], 1000.0),
        foundation=jh.Foundation(1.5e7, 2.0e5, 0.3, jh.RegularisedCoulomb(1e-3)),
        rope=jh.Rope(1.5e7, 1.3e4, [0.5, 0.5, 1.0]),
        hoist=jh.ConstantSpeedHoist(0.3),
        boom=jh.Boom([3.0, 0.5, 11.0], 500.0, 5.0e6, 5.0e3),
        name="oblique-box",
        t1=T1,
    )


@pytest.fixture(scope="module")
def box():
    return oblique_box()


@pytest.fixture(scope="module")
def clean(box):
    """The reference scan: 6 μ, groups of 2 lanes, one group per device per chunk (2 chunks)."""
    return scan(box, {MU: MUS}, TIMES, **kw(chunk_size=4))


def test_scan_physics(clean):
    """Every member solved; the observables say what the oblique pull does to the box."""
    assert clean.shape == (6,) and np.all(clean.ok)
    x = clean["final_position"][:, 0]
    # More friction holds the box back: the mass centre ends less far towards the boom (at X = 3 m).
    assert np.all(np.diff(x) < 0)
    assert np.all(x > 0.5)  # it started above X = 0.5 m
    t = clean["detachment_times"]
    # The corners at X = 0 (D, H) are on the far side from the boom and lift first; the mirror symmetry
    # about Y = 0.5 m makes D and H (and E and F) leave at the same time.
    np.testing.assert_allclose(t[:, 0], t[:, 3], rtol=1e-9)
    np.testing.assert_allclose(t[:, 1], t[:, 2], rtol=1e-9)
    assert np.all(t[:, 0] < t[:, 1])
    # contact_margin (min of f_i / k over the saved times) is <= 0 exactly for the corners that left the
    # ground, mirror-symmetric like the detachment times, and no larger than the static compression at
    # t = 0 (rope just taut: m g / (4 k) per corner) [m].
    g_min = clean["contact_margin"]
    np.testing.assert_array_equal(g_min <= 0.0, np.isfinite(t))
    np.testing.assert_allclose(g_min[:, 0], g_min[:, 3], rtol=1e-9)
    np.testing.assert_allclose(g_min[:, 1], g_min[:, 2], rtol=1e-9)
    assert np.all(g_min <= 1000.0 * 9.81 / (4 * 1.5e7) * (1 + 1e-6))
    # A corner's first impact comes after its first detachment (inf where it never left), mirror-symmetric.
    t_imp = clean["impact_times"]
    assert np.isfinite(t_imp).any()  # some corners do land again within 0.3 s
    assert np.all(np.isinf(t_imp[np.isinf(t)])) and np.all(t_imp[np.isfinite(t)] > t[np.isfinite(t)])
    np.testing.assert_allclose(t_imp[:, 0], t_imp[:, 3], rtol=1e-9)
    # Time per contact configuration (16 subsets of D, E, F, H): the mirror keeps D with H and E with F, so
    # only "none", "DH", "EF" and "DEFH" occur, and grouped by the number of corners down it is contact_time.
    conf = clean["configuration_time"]
    labels = clean.components["configuration_time"]
    occurring = {labels[m] for m in range(16) if np.any(conf[:, m] > 0)}
    assert occurring <= {"none", "DH", "EF", "DEFH"} and "DEFH" in occurring
    n_down = np.array([bin(m).count("1") for m in range(16)])
    by_count = np.stack([conf[:, n_down == c].sum(axis=1) for c in range(5)], axis=1)
    np.testing.assert_allclose(by_count, clean["contact_time"], rtol=0, atol=1e-15)
    # Lift-off (all four N_i = 0) cannot come before the last corner's first detachment.
    assert np.all(clean["liftoff_time"] >= t.max(axis=1) - 1e-12)
    # Time spent in the five contact configurations adds up to the horizon.
    np.testing.assert_allclose(clean["contact_time"].sum(axis=1), T1, rtol=1e-12)
    assert (
        clean.units[MU] == "-" and clean.units["final_position"] == "m" and clean.units["liftoff_time"] == "s"
    )


def test_identical_for_any_chunk_size_and_device_count(box, clean):
    assert len(jax.devices()) >= 2, "tests/conftest.py should provide two CPU devices"
    one_chunk = scan(box, {MU: MUS}, TIMES, **kw(chunk_size=8))
    one_device = scan(box, {MU: MUS}, TIMES, **kw(chunk_size=2, devices=jax.devices()[:1]))
    assert clean.attrs["chunk_size"] == 4 and one_chunk.attrs["chunk_size"] == 8
    for other in (one_chunk, one_device):
        for k in clean.data:
            np.testing.assert_array_equal(other[k], clean[k], err_msg=k)
        np.testing.assert_array_equal(other.num_accepted_steps, clean.num_accepted_steps)


def test_a_renamed_scenario_reuses_the_compiled_chunk(box, clean):
    """The compiled chunk does not depend on the scenario's static labels (`Scenario.unlabelled`) nor on
    how a leaf was set (`as_float64_leaves`): the same scan of a renamed copy, one of its leaves set to a
    Python float with `eqx.tree_at`, compiles nothing, gives the same results bit for bit, and is named for
    the copy."""
    renamed = dataclasses.replace(box, name="renamed box", t1=2 * T1, description="a copy")
    renamed = eqx.tree_at(lambda s: s.foundation.stiffness, renamed, float(box.foundation.stiffness))
    again = scan(renamed, {MU: MUS}, TIMES, **kw(chunk_size=4))
    assert again.attrs["timings_s"]["compile"] == 0.0 and clean.attrs["timings_s"]["compile"] > 0.0
    assert again.attrs["scenario"] == "renamed box"
    for k in clean.data:
        np.testing.assert_array_equal(again[k], clean[k], err_msg=k)


def test_another_swept_parameter_reuses_the_compiled_group(box, clean):
    """The lock-step group program takes the members' scenarios, not their values (`batch.group_spec`): a
    scan of the foundation's stiffness instead of μ, and a scan of μ on a stiffer box, run the group program
    of `clean` without compiling it again, and a member that two of them share is bit for bit the same,
    whichever parameter was swept (the box's own μ = 0.3 at k = 2e7 N/m, and the box itself). `clean` made
    its group program: compiled, or loaded where the session's cache folder holds it from an earlier run
    (JAXHOIST_TEST_CACHE_DIR kept between sessions)."""
    assert clean.attrs["group_program"] in ("compiled", "loaded")
    stiffnesses = np.array([1.0e7, 1.5e7, 2.0e7, 2.5e7])
    by_k = scan(box, {"foundation.stiffness": stiffnesses}, TIMES, **kw(chunk_size=4))
    stiffer = box.replace(**{"foundation.stiffness": 2.0e7})
    by_mu = scan(stiffer, {MU: MUS}, TIMES, **kw(chunk_size=4))
    assert by_k.attrs["group_program"] == by_mu.attrs["group_program"] == "reused"
    assert np.all(by_k.ok) and np.all(by_mu.ok)
    assert float(get_param(box, MU)) == MUS[2]
    assert float(get_param(box, "foundation.stiffness")) == stiffnesses[1]
    for k in clean.data:
        np.testing.assert_array_equal(by_k[k][2], by_mu[k][2], err_msg=k)
        np.testing.assert_array_equal(by_k[k][1], clean[k][2], err_msg=k)  # the box itself
    assert by_k.num_accepted_steps[2] == by_mu.num_accepted_steps[2]
    # the stiffness matters: the stiffer foundation gives other results than the box's 1.5e7 N/m
    assert not np.array_equal(by_k["final_position"][2], by_k["final_position"][1])


def test_another_swept_parameter_reuses_the_group_compiled_as_for_an_accelerator(box, clean, monkeypatch):
    """The same on the route of accelerators (and of host devices other than the default one), where each
    device gets its own copy of the group program (`batch.ChunkProgram`): the stiffness scan reuses the μ
    scan's copy, and both give `clean`'s bits, which come from the stored route."""
    from jaxhoist._numerics import batch

    monkeypatch.setattr(batch, "stores_whole", lambda spec: False)
    by_mu = scan(box, {MU: MUS}, TIMES, **kw(chunk_size=4))
    by_k = scan(box, {"foundation.stiffness": [1.0e7, 1.5e7]}, TIMES, **kw(chunk_size=4))
    assert by_mu.attrs["group_program"] == "compiled" and by_k.attrs["group_program"] == "reused"
    for k in clean.data:
        np.testing.assert_array_equal(by_mu[k], clean[k], err_msg=k)
        np.testing.assert_array_equal(by_k[k][1], clean[k][2], err_msg=k)  # the box itself
    # other tolerances: the same copy, run under them (the next test does this on the stored route)
    loose = scan(box, {MU: MUS}, TIMES, **{**kw(chunk_size=4), "options": LOOSE})
    assert loose.attrs["group_program"] == "reused"
    assert loose.num_accepted_steps.sum() < 0.6 * clean.num_accepted_steps.sum()


#: `KW`'s options (Tsit5 at its default rtol 1e-6, atol 1e-8) at 100x looser tolerances.
LOOSE = jh.SolverOptions(diffrax.Tsit5(), rtol=1e-4, atol=1e-6, max_steps=3000)


def test_other_tolerances_reuse_the_compiled_group(box, clean):
    """The lock-step group program takes the step-size controller's tolerances as values
    (`batch.group_options`): the scan of `clean` at 100x looser tolerances runs `clean`'s group program
    without compiling, under those tolerances (under 0.6 of the steps in all, every final position within
    1 mm of `clean`'s and not equal to it), and `clean`'s tolerances again give `clean` bit for bit. `clean`
    compiled its group program, or loaded it from a kept cache folder (the test above)."""
    assert clean.attrs["group_program"] in ("compiled", "loaded")
    loose = scan(box, {MU: MUS}, TIMES, **{**KW, "options": LOOSE, "batch": jh.BatchOptions(lanes=2)})
    assert loose.attrs["group_program"] == "reused" and np.all(loose.ok)
    assert loose.attrs["solver"]["rtol"] == 1e-4 and loose.attrs["solver"]["atol"] == 1e-6
    assert loose.num_accepted_steps.sum() < 0.6 * clean.num_accepted_steps.sum()
    np.testing.assert_allclose(loose["final_position"], clean["final_position"], rtol=0, atol=1e-3)
    assert not np.array_equal(loose["final_position"], clean["final_position"])
    again = scan(box, {MU: MUS}, TIMES, **kw(chunk_size=4))
    assert again.attrs["group_program"] == "reused"
    for k in clean.data:
        np.testing.assert_array_equal(again[k], clean[k], err_msg=k)


@pytest.mark.parametrize("solver", [None, diffrax.Tsit5()], ids=["default", "tsit5"])
def test_layout_independent_and_failing_group_mate_isolated(paper42, solver):
    """On paper-4.2 over 0.5 s in groups of 4, with the default solver (Rosenbrock-W) and Tsit5:
    a scan on two devices in chunks of 8 equals, bit for bit, one on one device in chunks of 4 (the
    partitioned program used before differed by 4.7e-6 m with Rosenbrock-W); and a member whose rope of
    1e16 N/m on a tip of 1e-12 kg exhausts its steps (marked `max_steps`) leaves its three group mates
    bit-for-bit what they are beside a healthy member (its group is solved again without it,
    `numerics.batch.CompiledChunk`; without that, a Tsit5 group mate moved by 3e-11 m). With the default
    solver the scans are those of the next test (`paper42_members`: the same paths, observables, saved
    times and groups), so the two tests share one compiled group."""
    base = paper42_members(paper42)
    bad = {k: v.copy() for k, v in base.items()}
    bad["rope.stiffness"][1], bad["boom.tip_mass"][1] = 1e16, 1e-12
    kw = dict(observables=["final_position", "final_euler"], options=jh.SolverOptions(solver, max_steps=2000))

    def batch(**b):
        return jh.BatchOptions(lanes=4, sort=False, **b)

    opted = paper42.replace(
        allow_implausible=True
    )  # the bad member's values are outside their plausible ranges
    two = scan(opted, jh.Points(bad), jh.Times(0.5, n=11), batch=batch(chunk_size=8), **kw)
    one = scan(
        opted,
        jh.Points(bad),
        jh.Times(0.5, n=11),
        batch=batch(chunk_size=4, devices=jax.devices()[:1]),
        **kw,
    )
    clean = scan(paper42, jh.Points(base), jh.Times(0.5, n=11), batch=batch(chunk_size=8), **kw)
    assert two.status[1] == ScanStatus.MAX_STEPS and np.all(np.delete(two.status, 1) == ScanStatus.OK)
    np.testing.assert_array_equal(two.num_accepted_steps, one.num_accepted_steps)
    keep = [0, 2, 3, 4, 5, 6, 7]
    for k in two.data:
        np.testing.assert_array_equal(two[k], one[k], err_msg=k)
        np.testing.assert_array_equal(two[k][keep], clean[k][keep], err_msg=k)
    np.testing.assert_array_equal(two.num_accepted_steps[keep], clean.num_accepted_steps[keep])


def paper42_members(paper42, n: int = 8) -> dict[str, np.ndarray]:
    """`n` members of paper-4.2 over μ in [0.1, 0.6], with its rope stiffness and tip mass as paths too (at
    the preset's values) so that a member can be broken by either."""
    rope_k, tip_m = float(paper42.rope.stiffness), float(paper42.boom.tip_mass)
    return {
        MU: np.linspace(0.1, 0.6, n),
        "rope.stiffness": np.full(n, rope_k),
        "boom.tip_mass": np.full(n, tip_m),
    }


def test_a_member_is_the_same_whatever_the_member_count_and_the_group_width(paper42):
    """The default group width follows the member count and the devices (`adaptive_lanes`), so a member
    must not depend on them beyond rounding: on paper-4.2 over 0.5 s with the default solver, four members
    solved among eight in groups of 4 are bit for bit what they are solved alone in a group of 4 (the same
    program, other group mates, another member count), and within 1e-9 relative, in the same steps, of
    the eight in one group of 8 (another width: XLA may round differently in a wider vmap)."""
    mus = paper42_members(paper42)
    kw = dict(observables=["final_position", "final_euler"], options=jh.SolverOptions(max_steps=2000))
    times = jh.Times(0.5, n=11)
    four = scan(paper42, jh.Points(mus), times, batch=jh.BatchOptions(lanes=4, sort=False), **kw)
    sub = {k: v[::2] for k, v in mus.items()}
    alone = scan(paper42, jh.Points(sub), times, batch=jh.BatchOptions(lanes=4, sort=False), **kw)
    wide = scan(paper42, jh.Points(mus), times, batch=jh.BatchOptions(lanes=8, sort=False), **kw)
    assert np.all(four.ok) and np.all(alone.ok) and np.all(wide.ok)
    assert (four.attrs["lanes"], alone.attrs["lanes"], wide.attrs["lanes"]) == (4, 4, 8)
    for k in four.data:
        np.testing.assert_array_equal(alone[k], four[k][::2], err_msg=k)
        np.testing.assert_allclose(wide[k], four[k], rtol=1e-9, atol=1e-12, err_msg=k)
    np.testing.assert_array_equal(alone.num_accepted_steps, four.num_accepted_steps[::2])
    np.testing.assert_array_equal(wide.num_accepted_steps, four.num_accepted_steps)


def test_a_lock_step_group_takes_the_steps_of_a_solve_alone(paper42):
    """A scan group without derivatives is one while loop over its lanes running diffrax's step, step-size
    control and dense output (`numerics.lockstep`), not a `jax.vmap` of `diffeqsolve`: on paper-4.2 over
    0.5 s with the default solver, each of four members takes the accepted and rejected steps that
    `jh.simulate` takes for it, and ends within 1e-9 relative of it (the two programs are compiled apart
    and may round differently). The scan is the `alone` scan of the test above (one compiled group)."""
    mus = {k: v[::2] for k, v in paper42_members(paper42).items()}
    options = jh.SolverOptions(max_steps=2000)
    times = jh.Times(0.5, n=11)
    kw = dict(observables=["final_position", "final_euler"], options=options)
    group = scan(paper42, jh.Points(mus), times, batch=jh.BatchOptions(lanes=4, sort=False), **kw)
    assert np.all(group.ok)
    for i, mu in enumerate(mus[MU]):
        alone = jh.simulate(set_param(paper42, MU, mu), times, options=options)
        assert group.num_accepted_steps[i] == int(alone.num_accepted_steps), i
        assert group.num_rejected_steps[i] == int(alone.num_rejected_steps), i
        np.testing.assert_allclose(group["final_position"][i], alone.position[-1], rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(group["final_euler"][i], alone.euler[-1], rtol=1e-9, atol=1e-12)


def test_poisoned_members_are_marked_and_the_rest_unchanged(box, clean):
    """μ = NaN is refused on the host (not solved); μ = 1e4 makes the regularised friction so stiff that
    the solve runs out of steps. Both are marked with their reason; every other member is bit-for-bit the
    clean scan's, and no observable of a failed member is silently a number. Unsorted, each failing member
    shares its vmapped lock-step group with a healthy one (μ = 0.4 and 0.6), which must not notice."""
    mus = MUS.copy()
    mus[2], mus[4] = np.nan, 1e4
    opted = box.replace(allow_implausible=True)  # μ = 1e4 is outside its plausible range
    res = scan(opted, {MU: mus}, TIMES, **kw(chunk_size=4, sort=False))
    assert res.status[2] == ScanStatus.INVALID_PARAMETER and res.status[4] == ScanStatus.MAX_STEPS
    assert "friction_coefficient" in res.reason(2) and "must be finite" in res.reason(2)
    assert "max_steps" in res.reason(4)
    assert [f["index"] for f in res.failures()] == [2, 4]
    assert np.all(np.isnan(res["final_position"][[2, 4]]))
    keep = [0, 1, 3, 5]
    for k in clean.data:
        np.testing.assert_array_equal(res[k][keep], clean[k][keep], err_msg=k)


def test_a_blown_up_member_is_marked_nonfinite_and_its_group_mate_kept(box):
    """Fixed explicit steps of 0.2 ms: a boom tip of 500 kg on a vertical spring of 1e14 N/m
    (ω = 4.5e5 rad/s, far beyond the step's stability limit ~1.2e4 rad/s) blows up to a non-finite state;
    it is marked NONFINITE with its reason and NaN observables, and the member solved in the same vmapped
    group, like every other one, is bit-for-bit what it is when that group holds a healthy member
    instead."""
    k = "boom.stiffness[2]"
    fixed = jh.SolverOptions(diffrax.Bosh3(), diffrax.ConstantStepSize(), dt0=2e-4, max_steps=3000)
    kw = dict(KW, options=fixed, batch=jh.BatchOptions(lanes=2, sort=False))
    opted = box.replace(allow_implausible=True)  # 1e14 N/m is outside the boom's plausible range
    bad = scan(opted, jh.Sweep(k, [5e6, 1e14, 6e6, 7e6]), TIMES, **kw)
    ref = scan(box, jh.Sweep(k, [5e6, 5.5e6, 6e6, 7e6]), TIMES, **kw)
    assert list(bad.status) == [ScanStatus.OK, ScanStatus.NONFINITE, ScanStatus.OK, ScanStatus.OK]
    assert "non-finite" in bad.reason(1) and np.all(np.isnan(bad["final_position"][1]))
    assert np.all(ref.ok)
    for name in bad.data:
        np.testing.assert_array_equal(bad[name][[0, 2, 3]], ref[name][[0, 2, 3]], err_msg=name)


def test_resume_after_interruption(box, clean, tmp_path):
    """Interrupt after the first chunk (a progress callback raises), resume from the files, and end with
    exactly the uninterrupted result; the saved result is self-describing and loads back."""
    reports = []

    def stop_after_first(p):
        reports.append(p)
        if p.chunk == 0:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        scan(box, {MU: MUS}, TIMES, out_dir=tmp_path, progress=stop_after_first, **kw(chunk_size=4))
    manifest = json.loads((tmp_path / "manifest.json").read_text())
    assert list(manifest["chunks"]) == ["0"] and (tmp_path / "chunk_00000.npz").exists()
    assert not (tmp_path / "scan.npz").exists()

    reports.clear()
    res = scan(box, {MU: MUS}, TIMES, out_dir=tmp_path, progress=reports.append, **kw(chunk_size=4))
    assert [p.loaded for p in reports] == [True, False]
    assert reports[-1].done == reports[-1].total == 6 and reports[-1].eta == 0.0
    for k in clean.data:
        np.testing.assert_array_equal(res[k], clean[k], err_msg=k)

    back = ScanResult.load(tmp_path / "scan.npz")
    for k in clean.data:
        np.testing.assert_array_equal(back[k], clean[k], err_msg=k)
    side = json.loads((tmp_path / "scan.json").read_text())
    assert side["arrays"]["obs:liftoff_time"]["unit"] == "s"
    assert side["arrays"][f"coord:{MU}"]["unit"] == "-"
    assert side["scan"]["components"]["detachment_times"] == ["D", "E", "F", "H"]

    with pytest.raises(jh.ScenarioError, match="different scan"):
        scan(box, {MU: MUS[:3]}, TIMES, out_dir=tmp_path, **kw(chunk_size=4))


def test_netcdf_file_reads_back_with_an_independent_reader(clean, tmp_path):
    """`to_netcdf` writes a classic netCDF file that scipy's reader (not ours) parses: dimensions, values
    (inf kept), units, component labels and the global metadata."""
    import scipy.io

    path = clean.to_netcdf(tmp_path / "scan.nc")
    f = scipy.io.netcdf_file(str(path), "r", mmap=False)
    try:
        assert f.dimensions["member"] == 6 and f.dimensions["detachment_times_component"] == 4
        v = f.variables
        np.testing.assert_array_equal(v[MU].data, MUS)
        assert v[MU].units == b"-" and v["liftoff_time"].units == b"s"
        assert v["detachment_times"].dimensions == ("member", "detachment_times_component")
        np.testing.assert_array_equal(v["detachment_times"].data, clean["detachment_times"])
        labels = [b"".join(row).decode() for row in v["detachment_times_component"].data]
        assert labels == ["D", "E", "F", "H"]
        np.testing.assert_array_equal(v["status"].data, clean.status)
        assert f.scan_mode == b"sweep" and json.loads(f.attrs_json)["t1"] == T1
    finally:
        f.close()


def test_grid_mode_with_time_histories(box, tmp_path):
    """A 2 x 2 grid over μ and the hoist speed, keeping the mass-centre history."""
    res = scan(
        box,
        jh.Grid({MU: [0.2, 0.5], "hoist.speed": [0.2, 0.3]}),
        TIMES,
        histories=("position",),
        **{**KW, "observables": ["final_position"]},
    )
    assert res.shape == (2, 2) and res["position"].shape == (2, 2, 31, 3)
    assert res.units["hoist.speed"] == "m/s" and res.units["position"] == "m"
    np.testing.assert_array_equal(res["position"][:, :, -1], res["final_position"])
    np.testing.assert_array_equal(res.values("hoist.speed"), [[0.2, 0.3], [0.2, 0.3]])
    x = res["final_position"][..., 0]
    assert x[0, 1] > x[0, 0] and x[1, 1] > x[1, 0]  # a faster hoist drags the box further in 0.3 s
    assert x[0, 0] > x[1, 0] and x[0, 1] > x[1, 1]  # more friction, less far

    import scipy.io  # the netCDF file: one dimension per grid parameter, the history over t

    path = res.to_netcdf(tmp_path / "grid.nc")
    f = scipy.io.netcdf_file(str(path), "r", mmap=False)
    try:
        assert f.variables["history_position"].dimensions == (MU, "hoist.speed", "t", "position_dim0")
        np.testing.assert_array_equal(f.variables["history_position"].data, res["position"])
        np.testing.assert_array_equal(f.variables["hoist.speed"].data, [0.2, 0.3])
    finally:
        f.close()


def test_forward_sensitivities_match_differences(box, tmp_path):
    """d(final X)/dμ by forward mode, integrated over [0.29, 0.31] by Simpson's rule, equals the change of
    the scan's own final X, across corners leaving and striking the ground again (the contact and rope
    dampers build up over `damping_onset`, so the forces stay continuous at touch-down and the derivative
    of the solution has no jump that differentiating through the solver steps would miss). The same scan at
    looser tolerances runs the same compiled group program."""

    def derivative_scan(rtol, atol):
        options = jh.SolverOptions(diffrax.Tsit5(), rtol=rtol, atol=atol, max_steps=3000)
        observables = ["final_x", "impacts", "final_position"]
        return scan(
            box,
            {MU: [0.29, 0.3, 0.31]},
            TIMES,
            derivatives=True,
            **{**KW, "observables": observables, "options": options},
        )

    res = derivative_scan(1e-9, 1e-11)
    x, dx = res["final_x"], res["d_final_x"][:, 0]
    assert res["d_final_x"].shape == (3, 1) and res.units["d_final_x"] == "m per -"
    assert np.all(res["impacts"] >= 4)
    assert np.all(dx < 0.0)  # more friction, less far
    simpson = 0.01 / 3 * (dx[0] + 4 * dx[1] + dx[2])
    # Simpson's error ~ h^5 x^(5) and the solver noise (~1e-9 x 0.6 m over a change of 1.6 mm, 4e-7) are
    # small; measured agreement 5e-6.
    assert simpson == pytest.approx(x[2] - x[0], rel=2e-5)
    np.testing.assert_array_equal(res["d_final_position"][:, 0, 0], dx)
    # the group program takes the tolerances as values (`batch.group_options`): at 100x looser ones the
    # same program runs (fewer steps; the sensitivities within 1e-3 relative: measured 1.9e-4)
    loose = derivative_scan(1e-7, 1e-9)
    assert res.attrs["group_program"] in ("compiled", "loaded")  # loaded: from a kept cache folder
    assert loose.attrs["group_program"] == "reused"
    assert np.all(loose.num_accepted_steps < res.num_accepted_steps)
    np.testing.assert_allclose(loose["d_final_x"][:, 0], dx, rtol=1e-3)

    # The sensitivities of a vector observable keep both axes, labelled, in the netCDF file and the plots.
    import scipy.io

    from jaxhoist._apps.plots.scan import _components

    assert res.axes("d_final_position") == [
        ("final_position_component", 3, ("x", "y", "z")),
        ("parameter", 1, (MU,)),
    ]
    assert _components(res, "d_final_position")[0][2] == f"d_final_position[z, {MU}]"
    f = scipy.io.netcdf_file(str(res.to_netcdf(tmp_path / "d.nc")), "r", mmap=False)
    try:
        d = f.variables["d_final_position"]
        assert d.dimensions == ("member", "final_position_component", "parameter")
        np.testing.assert_array_equal(d.data, res["d_final_position"])
    finally:
        f.close()


def test_member_layout_and_value_specs():
    mode, coords, shape, m = _members({"a": [1.0, 2.0], "b": [10.0, 20.0, 30.0]}, "grid")
    assert shape == (2, 3) and m.shape == (6, 2)
    np.testing.assert_array_equal(m[4], [2.0, 20.0])  # row-major: index (1, 1)
    mode, coords, shape, m = _members({"a": [1.0, 2.0], "b": [10.0, 20.0]}, "points")
    np.testing.assert_array_equal(m, [[1.0, 10.0], [2.0, 20.0]])
    with pytest.raises(jh.ScenarioError, match="mode='grid'"):
        _members({"a": [1.0], "b": [2.0]}, "sweep")
    with pytest.raises(jh.ScenarioError, match="equally long"):
        _members({"a": [1.0, 2.0], "b": [2.0]}, "points")
    np.testing.assert_allclose(parse_values("0.1:0.6:6"), MUS)
    np.testing.assert_array_equal(parse_values("1,2.5"), [1.0, 2.5])
    assert parse_path("load.mass_centre[2]") == ("load.mass_centre", 2)


def test_get_param_reads_what_set_param_wrote(box):
    moved = set_param(box, "load.mass_centre[0]", 0.42)
    assert float(get_param(moved, "load.mass_centre[0]")) == 0.42
    assert float(get_param(moved, "load.mass_centre[1]")) == 0.5  # the other components are kept
    assert float(get_param(box, "hoist.speed")) == 0.3
    with pytest.raises(jh.ScenarioError, match="index 3 out of range"):
        get_param(box, "load.mass_centre[3]")


def test_invalid_requests_fail_before_compiling(box):
    with pytest.raises(jh.ScenarioError, match="has no field 'frction_coefficient'"):
        scan(box, {"foundation.frction_coefficient": [0.1]}, T1)
    with pytest.raises(jh.ScenarioError, match=r"load.mass_centre\[0\]"):
        scan(box, {"load.mass_centre": [0.4]}, T1)
    with pytest.raises(jh.ScenarioError, match="every member"):
        scan(box, {MU: [-1.0, np.nan]}, T1)
    with pytest.raises(jh.ScenarioError, match="unknown observable"):
        scan(box, {MU: [0.2]}, TIMES, observables=["final_yaw"])
    # one history name as a string is that name, not its letters ("history 'p' is not ...")
    with pytest.raises(jh.ScenarioError, match="history 'positon' is not a Trajectory output"):
        scan(box, {MU: [0.2]}, TIMES, histories="positon")


def test_first_down_crossing_is_interpolated():
    import jax.numpy as jnp

    ts = jnp.linspace(0.0, 1.0, 11)
    # f = 0.537 - t crosses zero at t = 0.537 exactly; linear interpolation is exact for a linear signal.
    assert float(O.first_down_crossing(ts, 0.537 - ts)) == pytest.approx(0.537, abs=1e-14)
    assert float(O.first_down_crossing(ts, 1.0 + ts)) == np.inf
    assert float(O.first_down_crossing(ts, ts - 0.5)) == 0.0  # not in contact at t = 0
    # A corner leaving at t = 0.25 and landing again at t = 0.75 (f = |t - 0.5| - 0.25, piecewise linear
    # with its kink on a saved time): both crossings are exact.
    f = jnp.abs(ts - 0.5) - 0.25
    assert float(O.first_down_crossing(ts, f)) == pytest.approx(0.25, abs=1e-14)
    assert float(O.first_return(ts, f)) == pytest.approx(0.75, abs=1e-14)
    assert float(O.first_return(ts, 0.537 - ts)) == np.inf  # leaves and never returns
    assert float(O.first_return(ts, 1.0 + ts)) == np.inf  # never leaves
    assert float(O.first_return(ts, ts - 0.55)) == pytest.approx(0.55, abs=1e-14)  # off at t = 0, lands


_WORKER = """
import sys
import jax
jax.config.update("jax_num_cpu_devices", 1)
jax.config.update("jax_enable_x64", True)
port, pid, out = sys.argv[1], int(sys.argv[2]), sys.argv[3]
jax.distributed.initialize(coordinator_address=f"127.0.0.1:{port}", num_processes=2, process_id=pid,
                           initialization_timeout=120)
import numpy as np
sys.path.insert(0, sys.argv[4])
from test_scan import KW, MU, MUS, TIMES, kw, oblique_box
from jaxhoist._apps.scan import scan
assert jax.process_count() == 2 and len(jax.local_devices()) == 1
res = scan(oblique_box(), {MU: MUS}, TIMES, out_dir=out, **kw(chunk_size=4, wait_timeout=300))
np.savez(f"{out}/process{pid}.npz", **{k: res[k] for k in res.data}, status=res.status)
"""


def test_several_processes_share_the_chunks(clean, tmp_path):
    """Two processes under `jax.distributed` (one CPU device each) split the scan's two chunks between
    them through a shared folder; each returns the whole result, bit-for-bit the single-process one
    (the same groups of 2 lanes are solved by the same compiled computation)."""
    import os
    import socket
    import subprocess
    import sys
    from pathlib import Path

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
    here = str(Path(__file__).parent)
    procs = [
        subprocess.Popen(
            [sys.executable, "-c", _WORKER, str(port), str(pid), str(tmp_path), here],
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        for pid in (0, 1)
    ]
    logs = [p.communicate(timeout=600)[0] for p in procs]
    for p, log in zip(procs, logs, strict=True):
        assert p.returncode == 0, log[-3000:]
    manifest = json.loads((tmp_path / "manifest.json").read_text())
    assert sorted(manifest["chunks"]) == ["0", "1"]
    for pid in (0, 1):
        with np.load(tmp_path / f"process{pid}.npz") as got:
            np.testing.assert_array_equal(got["status"], clean.status)
            for k in clean.data:
                np.testing.assert_array_equal(got[k], clean[k], err_msg=f"process {pid}: {k}")
    back = ScanResult.load(tmp_path / "scan.npz")  # written by process 0
    np.testing.assert_array_equal(back["final_position"], clean["final_position"])


_FOUR_DEVICES = """
import os, signal, sys
import jax
jax.config.update("jax_num_cpu_devices", 4)
jax.config.update("jax_enable_x64", True)
import numpy as np
tmp, here = sys.argv[1:3]
sys.path.insert(0, here)
# the same run-time type checking as under pytest (pyproject's --jaxtyping-packages): it rewrites the
# library's bytecode, which the scan's fingerprint hashes for its observables
from jaxtyping import install_import_hook
install_import_hook("jaxhoist", "beartype.beartype")
from test_scan import KW, MU, MUS, TIMES, kw, oblique_box
from jaxhoist._apps.scan import scan
assert len(jax.devices()) == 4
save = lambda name, r: np.savez(f"{tmp}/{name}.npz", **{k: r[k] for k in r.data}, status=r.status)
res = scan(oblique_box(), {MU: MUS}, TIMES, **kw(chunk_size=4))
assert len(res.attrs["devices"]) == 4, res.attrs["devices"]
save("four", res)
# resume on four devices what two devices began (chunks of 4 members: 2 groups for 4 devices)
save("resumed_on_four", scan(oblique_box(), {MU: MUS}, TIMES, out_dir=f"{tmp}/begun", **kw(chunk_size=4)))
mus12 = np.linspace(0.1, 0.6, 12)
save("twelve", scan(oblique_box(), {MU: mus12}, TIMES, **kw(chunk_size=8)))  # the compiled call of the next

def kill_after_first_chunk(p):
    if p.chunk == 0:
        os.kill(os.getpid(), signal.SIGKILL)  # no clean-up, no flush: as if the machine went away

scan(oblique_box(), {MU: mus12}, TIMES, out_dir=f"{tmp}/killed", progress=kill_after_first_chunk,
     **kw(chunk_size=8))
"""


def test_four_devices_and_resumes_across_device_counts(clean, tmp_path):
    """A fresh process with four CPU devices (the device count is fixed when JAX starts; this one has two):
    - the reference scan gives, bit for bit, the same numbers (its one-device twin is checked in
      `test_identical_for_any_chunk_size_and_device_count`);
    - it resumes a scan begun here on two devices (stopped after its first chunk) to the reference result;
    - a scan of 12 members (chunks of 8 = 4 devices x 2 lanes) is killed with SIGKILL once its first chunk
      is written; resumed here, on two devices, it loads that chunk, solves the other and ends with
      the result of the same scan run without interruption."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    def stop(p):
        if p.chunk == 0:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        scan(oblique_box(), {MU: MUS}, TIMES, out_dir=tmp_path / "begun", progress=stop, **kw(chunk_size=4))
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
    run = subprocess.run(
        [sys.executable, "-c", _FOUR_DEVICES, str(tmp_path), str(Path(__file__).parent)],
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert run.returncode == -9, (run.stdout + run.stderr)[-3000:]  # killed, as planned
    for name in ("four", "resumed_on_four"):
        with np.load(tmp_path / f"{name}.npz") as got:
            np.testing.assert_array_equal(got["status"], clean.status)
            for k in clean.data:
                np.testing.assert_array_equal(got[k], clean[k], err_msg=f"{name}: {k}")

    killed = tmp_path / "killed"
    manifest = json.loads((killed / "manifest.json").read_text())
    assert list(manifest["chunks"]) == ["0"] and manifest["chunk_size"] == 8
    reports = []
    res = scan(
        oblique_box(), {MU: np.linspace(0.1, 0.6, 12)}, TIMES, out_dir=killed, progress=reports.append, **KW
    )
    assert [p.loaded for p in reports] == [True, False]
    with np.load(tmp_path / "twelve.npz") as want:
        for k in res.data:
            np.testing.assert_array_equal(res[k], want[k], err_msg=k)


def test_fingerprint_sees_constants_and_closures_of_custom_observables():
    """A custom observable whose constant or closed-over value changed must not reuse the chunks
    of the old one (the fingerprint hashed only the bytecode)."""
    from jaxhoist._apps.scan.run import _fingerprint
    from jaxhoist._numerics.batch import BatchSpec as _Spec
    from jaxhoist._numerics.observables import resolve

    sc = oblique_box()
    ts = np.linspace(0.0, T1, 3)
    members = MUS[:, None]

    def fp(fn):
        spec = _Spec(
            paths=(MU,),
            observables=tuple(resolve({"x": fn})),
            histories=(),
            options=jh.SolverOptions(),
            lanes=2,
            devices=(),
            derivatives=False,
        )
        return _fingerprint(sc, spec, members, ts, True)

    def closure(scale):
        return lambda traj: traj.position[-1, 0] * scale

    assert fp(lambda traj: traj.position[-1, 0] + 1.0) != fp(lambda traj: traj.position[-1, 0] + 2.0)
    assert fp(closure(1.0)) != fp(closure(2.0))
    assert fp(closure(np.array([1.0]))) != fp(closure(np.array([2.0])))
    assert fp(closure(1.0)) == fp(closure(1.0))


def test_fingerprint_sees_solver_settings_beyond_the_tolerances():
    """Chunks of a scan solved with other solver settings at the same tolerances (the ∂f/∂t term off, other
    PI coefficients) are not reused: the fingerprint has the solver's and the controller's fields."""
    import diffrax

    from jaxhoist._apps.scan.run import _fingerprint
    from jaxhoist._numerics.batch import BatchSpec as _Spec
    from jaxhoist._numerics.observables import resolve

    def fp(options):
        spec = _Spec(
            paths=(MU,),
            observables=tuple(resolve(KW["observables"])),
            histories=(),
            options=options,
            lanes=2,
            devices=(),
            derivatives=False,
        )
        return _fingerprint(oblique_box(), spec, MUS[:, None], np.linspace(0.0, T1, 3), True)

    default = jh.SolverOptions()
    ctrl = default.stepsize_controller
    assert fp(default) == fp(jh.SolverOptions())
    assert fp(default) != fp(jh.SolverOptions(jh.RosenbrockW(time_derivative=False), ctrl))
    integral = diffrax.PIDController(rtol=5e-4, atol=1e-5)
    assert fp(default) != fp(jh.SolverOptions(stepsize_controller=integral))


def test_a_damaged_or_foreign_store_is_recomputed_with_a_warning(box, clean, tmp_path):
    """Chunk files are verified on resume (content checksum from the manifest, the scan's
    fingerprint and the member indices inside the file); a truncated or emptied chunk, a chunk copied over
    another, a chunk whose values were changed (NaNs marked ok) and a truncated manifest are each recomputed
    with a `ScanStoreWarning` naming the file, and the result equals the clean scan."""
    from jaxhoist._io.scan_store import ScanStoreWarning

    out = tmp_path / "store"
    first = scan(box, {MU: MUS}, TIMES, out_dir=out, **kw(chunk_size=4))  # 2 chunks (4 and 2 members)
    for k in clean.data:
        np.testing.assert_array_equal(first[k], clean[k], err_msg=k)
    c0, c1 = (out / f"chunk_{i:05d}.npz" for i in range(2))

    def resume_expecting(match):
        with pytest.warns(ScanStoreWarning, match=match):
            again = scan(box, {MU: MUS}, TIMES, out_dir=out, **kw(chunk_size=4))
        for k in clean.data:
            np.testing.assert_array_equal(again[k], clean[k], err_msg=k)

    c0.write_bytes(c0.read_bytes()[:100])  # truncated
    resume_expecting(r"chunk_00000\.npz: its content changed")
    c1.write_bytes(b"")  # emptied
    resume_expecting(r"chunk_00001\.npz: its content changed")
    # a chunk copied over another, with the manifest's checksum updated to match: the member indices and
    # the fingerprint inside the file give it away
    c1.write_bytes(c0.read_bytes())
    man = json.loads((out / "manifest.json").read_text())
    man["chunks"]["1"]["sha256"] = man["chunks"]["0"]["sha256"]
    (out / "manifest.json").write_text(json.dumps(man))
    resume_expecting(r"chunk_00001\.npz: holds other members")
    # values changed behind the manifest's back (a chunk of NaNs still marked ok)
    with np.load(c1) as z:
        arrays = {k: z[k] for k in z.files}
    np.savez(c1, **{k: (np.full_like(v, np.nan) if k.startswith("obs:") else v) for k, v in arrays.items()})
    resume_expecting(r"chunk_00001\.npz: its content changed")
    (out / "manifest.json").write_text((out / "manifest.json").read_text()[:40])  # truncated manifest
    resume_expecting(r"manifest\.json is unreadable")


_FP_WORKER = """
import sys
import jax
jax.config.update("jax_enable_x64", True)
import numpy as np
sys.path.insert(0, sys.argv[1])
# the same run-time type checking as under pytest: it rewrites the library's bytecode, which is hashed
from jaxtyping import install_import_hook
install_import_hook("jaxhoist", "beartype.beartype")
from test_scan import KW, MU, MUS, T1, oblique_box
from jaxhoist._numerics.observables import resolve
from jaxhoist._apps.scan.run import _fingerprint
from jaxhoist._numerics.batch import BatchSpec as _Spec
import jaxhoist as jh
spec = _Spec(paths=(MU,), observables=tuple(resolve(KW["observables"])), histories=(),
             options=jh.SolverOptions(), lanes=2, devices=(), derivatives=False)
print(_fingerprint(oblique_box(), spec, MUS[:, None], np.linspace(0.0, T1, 3), True))
"""


def test_fingerprint_is_the_same_in_every_process():
    """The fingerprint is what processes of one scan (and a resumed run) compare: it must not depend on
    memory addresses (the repr of a code object or function has one)."""
    import subprocess
    import sys
    from pathlib import Path

    from jaxhoist._apps.scan.run import _fingerprint
    from jaxhoist._numerics.batch import BatchSpec as _Spec
    from jaxhoist._numerics.observables import resolve

    spec = _Spec(
        paths=(MU,),
        observables=tuple(resolve(KW["observables"])),
        histories=(),
        options=jh.SolverOptions(),
        lanes=2,
        devices=(),
        derivatives=False,
    )
    here = _fingerprint(oblique_box(), spec, MUS[:, None], np.linspace(0.0, T1, 3), True)
    out = subprocess.run(
        [sys.executable, "-c", _FP_WORKER, str(Path(__file__).parent)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip().splitlines()[-1] == here


def test_every_chunk_records_the_devices_it_ran_on(box, tmp_path):
    """scan.json (attrs) and the manifest say which devices computed each chunk, also for chunks
    read back from an earlier run on other devices."""
    out = tmp_path / "devs"
    one = jax.devices()[:1]
    first = scan(box, {MU: MUS}, TIMES, out_dir=out, **kw(chunk_size=4, devices=one))
    assert first.attrs["chunk_devices"] == {"0": [str(one[0])], "1": [str(one[0])]}
    (out / "chunk_00001.npz").unlink()  # resumed on two devices: chunk 1 is computed again there
    again = scan(box, {MU: MUS}, TIMES, out_dir=out, **kw(chunk_size=4))
    # two host CPU devices: their shares ran in two threads on the first (numerics.batch.execution_targets)
    both = [f"{jax.devices()[0]} (2 threads)"]
    assert again.attrs["chunk_devices"] == {"0": [str(one[0])], "1": both}
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["chunks"]["0"]["devices"] == [str(one[0])] and manifest["chunks"]["1"]["devices"] == both
    recorded = json.loads((out / "scan.json").read_text())["attrs"]["chunk_devices"]
    assert recorded == {"0": [str(one[0])], "1": both}


def test_sweep_objects_count_members_and_refuse_bad_input(box):
    """`Sweep`, `Grid` (outer product) and `Points` (zipped): member counts and layout; a plain mapping is a
    `Sweep` for one parameter and a `Grid` for several; bad input gives a one-line `ScenarioError` naming
    the path, before anything is compiled."""
    from jaxhoist._apps.scan.sweep import as_sweep

    g = jh.Grid({MU: "0.1:0.6:6", "hoist.speed": [0.2, 0.3]})
    assert g.size == len(g) == 12 and g.shape == (6, 2) and g.params == (MU, "hoist.speed")
    np.testing.assert_array_equal(g.members()[7], [0.4, 0.3])
    p = jh.Points({MU: [0.1, 0.2, 0.3], "hoist.speed": [0.2, 0.3, 0.4]})
    assert p.size == 3 and p.shape == (3,)
    assert jh.Sweep(MU, "0.1,0.2").size == 2
    assert isinstance(as_sweep({MU: [0.1]}), jh.Sweep) and isinstance(
        as_sweep({MU: [0.1], "x": [1]}), jh.Grid
    )
    bad = [
        (lambda: jh.Points({MU: [0.1, 0.2], "hoist.speed": [0.2]}), "Points: 'hoist.speed' has 1 values"),
        (lambda: jh.Grid({MU: []}), f"Grid: '{MU}' has no values"),
        (lambda: jh.Grid({MU: "0.1:0.6"}), f"Grid: '{MU}': parameter values '0.1:0.6'"),
        (lambda: jh.Sweep(MU, [[0.1, 0.2]]), f"Sweep: '{MU}': parameter values must be 1-D"),
        (lambda: jh.Grid({}), "Grid needs at least one parameter"),
        (lambda: jh.Grid({3: [0.1]}), "Grid: a parameter path must be a dotted name"),
        (lambda: jh.Points([0.1, 0.2]), "Points takes a mapping"),
        (lambda: as_sweep([0.1, 0.2]), "sweep must be Sweep"),
        (lambda: scan(box, jh.Sweep("foundation.frction_coefficient", [0.1]), T1), "frction_coefficient"),
        # one parameter under two spellings would sweep one of them only, labelled as both
        (lambda: jh.Grid({MU: [0.1, 0.6], MU + " ": [0.3]}), f"Grid: '{MU}' and '{MU} ' name the same"),
        (lambda: jh.Points({"load.mass_centre[0]": [1], "load.mass_centre[00]": [1]}), "name the same"),
    ]
    for make, match in bad:
        with pytest.raises(jh.ScenarioError, match=re.escape(match)) as err:
            make()
        assert "\n" not in str(err.value)


def test_default_lanes_follow_the_member_count_and_the_devices():
    """The default group width of an adaptive scan on CPUs is the power of two in 16-256 whose groups,
    shared out over the devices, cost least (a lock-step iteration costing `STEP_OVERHEAD` + the width):
    the widest groups that still keep every device busy, so that a small scan costs about what a large one
    does per trajectory. On accelerators each device gets one group of up to 65 536; constant steps keep
    256; `lanes` given wins, capped at the member count's next power of two."""
    from types import SimpleNamespace

    from jaxhoist._apps.scan.layout import adaptive_lanes

    widths = {d: {n: adaptive_lanes(n, d) for n in (1, 64, 256, 512, 1024, 4096, 65536)} for d in (1, 2, 16)}
    assert widths[1] == {1: 16, 64: 64, 256: 256, 512: 256, 1024: 256, 4096: 256, 65536: 256}
    assert widths[2] == {1: 16, 64: 32, 256: 128, 512: 256, 1024: 256, 4096: 256, 65536: 256}
    assert widths[16] == {1: 16, 64: 16, 256: 16, 512: 32, 1024: 64, 4096: 256, 65536: 256}
    for d, ws in widths.items():  # every device gets a group where the scan has enough members
        for n, w in ws.items():
            assert w == 16 or -(-n // w) >= d
    adaptive, fixed = (
        jh.SolverOptions(),
        jh.SolverOptions(diffrax.Bosh3(), diffrax.ConstantStepSize(), dt0=1e-3),
    )
    two = tuple(jax.devices()[:2])
    assert jh.BatchOptions().lanes_for(adaptive, 4096, two) == 256
    assert jh.BatchOptions().lanes_for(adaptive, 256, two) == 128
    assert jh.BatchOptions().lanes_for(adaptive, 256, two[:1]) == 256
    assert jh.BatchOptions().lanes_for(fixed, 100) == 128  # 256, capped at the next power of two
    assert jh.BatchOptions(lanes=8).lanes_for(adaptive, 4096) == 8
    gpus = tuple(SimpleNamespace(platform="gpu") for _ in range(2))
    assert [adaptive_lanes(n, accelerator=True) for n in (1, 4096, 10**6)] == [65536] * 3
    assert jh.BatchOptions().lanes_for(adaptive, 4096, gpus[:1]) == 4096  # capped at the next power of two
    assert jh.BatchOptions().lanes_for(adaptive, 4096, gpus) == 2048  # a group per GPU
    for devices in (gpus[:1], gpus):
        assert jh.BatchOptions().lanes_for(adaptive, 200_000, devices) == 65536
        assert jh.BatchOptions().lanes_for(fixed, 4096, devices) == 256
        assert jh.BatchOptions(lanes=8).lanes_for(adaptive, 4096, devices) == 8
    cpu_and_gpu = (jax.devices()[0], gpus[0])  # not all accelerators: the CPU rule
    assert jh.BatchOptions().lanes_for(adaptive, 4096, cpu_and_gpu) == 256
