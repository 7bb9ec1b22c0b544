"""Compiled programs stored whole (`stored_programs`, through `compile_cache.program`): a second process with
the same cache folder loads the scan's group program (plain and with forward-mode sensitivities),
`simulate`'s solve core and the derivative's program of a caller's `jax.jvp`, the bifurcation locator's
solves, `identify`'s fit pieces and the rigid model's phase-driver pieces without tracing them, and returns
the same bits; programs whose key has no stable text (a user's lambda observable) are not stored. (A damaged
stored file, compiled again with a warning, is tested once, on a small program, on the route every program
here takes, `stored_programs.load_or_compile`: tests/test_compilation_cache.py.) Short horizons and few
members: the compile is what is tested, not the physics."""

from pathlib import Path

import diffrax
import jax
import numpy as np
from conftest import N_SAVE
from test_compilation_cache import run_script

import jaxhoist as jh
from jaxhoist._numerics import batch
from jaxhoist._numerics import observables as obs_mod
from jaxhoist._numerics import persistent_cache as pc
from jaxhoist._numerics import stored_programs as sp

MU = "foundation.friction_coefficient"


_KEY_SCRIPT = r"""
import json
import jax, jax.numpy as jnp
jax.config.update("jax_enable_x64", True)
import jaxhoist as jh
from jaxhoist._numerics import batch
from jaxhoist._numerics import observables as obs_mod
from jaxhoist._numerics import stored_programs as sp

def key(observables, derivatives=False):
    spec = batch.BatchSpec(paths=("foundation.friction_coefficient",), observables=tuple(observables),
                           histories=("position",), options=jh.SolverOptions(), lanes=2,
                           devices=tuple(jax.devices()), derivatives=derivatives)
    sc = jh.load_scenario("paper-4.2").unlabelled()
    return sp.program_key("scan-group", (sc, jnp.linspace(0.0, 0.5, 6), jnp.full((2, 1), 0.3), spec))

builtin = [
    *obs_mod.resolve(None),  # the default observables
    obs_mod.detachment_time_difference("E", "D"),  # made by a factory: a closure of jaxhoist
    obs_mod.get("contact_margin[E]"),  # one component: a closure over another function
    obs_mod.get("final_angular_velocity"),  # a lambda of jaxhoist
]
def mine(traj):
    return traj.position[-1, 0]

def lock_step_keys(paths, options=jh.SolverOptions()):  # a scan's two stored programs: (group, members)
    spec = batch.BatchSpec(paths=paths, observables=tuple(builtin), histories=("position",),
                           options=options, lanes=2, devices=tuple(jax.devices()))
    sc, ts = jh.load_scenario("paper-4.2").unlabelled(), jnp.linspace(0.0, 0.5, 6)
    values = jnp.full((2, len(paths)), 0.3)
    scenarios = batch.member_scenarios(sc, values, paths)
    group = (scenarios, ts, batch.group_options(spec), batch.group_spec(spec, ts))
    members = sp.program_key("scan-members", (sc, values, paths))
    return [sp.program_key("scan-lock-step-group", group), members]

print(json.dumps({
    "lock_step": [lock_step_keys(p) for p in [("foundation.friction_coefficient",), ("foundation.stiffness",),
                                              ("foundation.friction_coefficient", "hoist.speed")]],
    "tolerances": [lock_step_keys(("foundation.stiffness",), o)[0]
                   for o in [jh.SolverOptions(rtol=1e-6, atol=1e-8), jh.SolverOptions(max_steps=1000)]],
    "builtin": [key(builtin), key(builtin, True)],
    "prefixes": [key(builtin[:k]) for k in range(1, len(builtin) + 1)],
    "closures": [key([obs_mod.detachment_time_difference(c, "D")]) for c in "EF"],
    "user": [key(builtin + list(obs_mod.resolve({"mine": mine}))),
             key(builtin + list(obs_mod.resolve({"mine": lambda t: t.position[-1, 0]})))],
}))
"""


def test_scan_group_programs_have_a_stable_key_unless_an_observable_is_the_users():
    """Without derivatives the group program's key is the same for any swept parameters and any tolerances
    of the step-size controller. In a plain process
    (pytest's jaxtyping hook wraps jaxhoist's closures in checkers the key does not cover, so that there
    they are not stored)."""
    keys = run_script(_KEY_SCRIPT)
    plain, derivatives = keys["builtin"]
    assert plain is not None and derivatives is not None and plain != derivatives
    assert "lambda" in plain and "detachment_time_difference" in plain
    assert None not in keys["prefixes"] and len(set(keys["prefixes"])) == len(keys["prefixes"])
    e, f = keys["closures"]  # two closures of one factory that differ only in what they captured
    assert e is not None and f is not None and e != f
    assert keys["user"] == [None, None]  # a user's code is not covered by the key: nothing is stored
    # without derivatives the group program's key does not depend on the swept paths, only the small
    # members program's does
    groups, members = zip(*keys["lock_step"], strict=True)
    assert None not in groups and len(set(groups)) == 1 and groups[0] != plain
    assert None not in members and len(set(members)) == 3
    # nor on the step-size controller's tolerances (values of the program), but on the step budget
    other_tolerances, fewer_steps = keys["tolerances"]
    assert other_tolerances == groups[0] and fewer_steps is not None and fewer_steps != groups[0]


# ------------------------------------------------------------------------------------ across processes

_SCAN_SCRIPT = r"""
import json, sys, warnings
import diffrax, jax, numpy as np
jax.config.update("jax_enable_x64", True)
jax.config.update("jax_num_cpu_devices", 2)
import jaxhoist as jh
from jaxhoist._numerics import batch
from jaxhoist._numerics import observables as obs_mod

traced = []
_checked_outputs = batch.checked_outputs
def counting_checked_outputs(*args, **kwargs):  # every trace of a group program calls it
    traced.append(1)
    return _checked_outputs(*args, **kwargs)
batch.checked_outputs = counting_checked_outputs

warnings.simplefilter("always")
out, how = {}, {}
with warnings.catch_warnings(record=True) as caught:
    jh.enable_compilation_cache(sys.argv[1])
    sc = jh.load_scenario("paper-4.2")
    observables = ["final_psi", "max_tilt", obs_mod.detachment_time_difference("E", "D")]
    for case in sys.argv[3].split(","):
        sweep = ({"foundation.stiffness": np.linspace(1.0e7, 2.0e7, 4)} if case == "stiffness"
                 else {"foundation.friction_coefficient": np.linspace(0.2, 0.5, 4)})
        res = jh.scan(sc, sweep, jh.Times(0.5, n=6),
                      observables=observables, histories=["position"], derivatives=case == "derivatives",
                      options=jh.SolverOptions(diffrax.Tsit5()))
        how[case] = res.attrs["group_program"]
        for k in [*res.data, *res.histories]:
            out[f"{case}:{k}"] = res[k]
        out[f"{case}:status"], out[f"{case}:steps"] = res.status, res.num_accepted_steps
np.savez(sys.argv[2], **out)
print(json.dumps({"how": how, "traced": len(traced), "warnings": [str(w.message) for w in caught]}))
"""


def _run_scan(cache: Path, out: Path, cases: str) -> dict:
    return run_script(_SCAN_SCRIPT, cache, out, cases, timeout=900)


def _assert_same_bits(a: Path, b: Path) -> None:
    x, y = np.load(a), np.load(b)
    assert x.files and all(k in y.files for k in x.files)
    for k in x.files:
        np.testing.assert_array_equal(x[k], y[k], err_msg=k, strict=True)


def _group_files(cache: Path) -> list[Path]:
    """The stored group programs: the lock-step group (a scan without derivatives) and the vmapped one (with
    derivatives), beside which the small program of the lock-step members' scenarios is stored."""
    folder = cache / sp.SUBFOLDER
    return sorted([*folder.glob("scan-group-*-cache"), *folder.glob("scan-lock-step-group-*-cache")])


def test_a_second_process_loads_the_scan_group_programs_untraced_with_the_same_bits(tmp_path, monkeypatch):
    """With Tsit5, whose group programs (plain and derivatives) compile in 40 % of the CPU time of the default
    solver's (Rosenbrock-W) on the same route; a stored program of the default solver is tested below
    (`simulate`'s solve core)."""
    cache = tmp_path / "cache"
    first = _run_scan(cache, tmp_path / "a.npz", "plain,derivatives")
    assert first["how"] == {"plain": "compiled", "derivatives": "compiled"} and first["traced"] > 0
    stored = _group_files(cache)
    assert len(stored) == 2  # one program each, stored whole
    assert len(list((cache / sp.SUBFOLDER).glob("scan-members-*-cache"))) == 1

    second = _run_scan(cache, tmp_path / "b.npz", "plain,derivatives")
    assert second["how"] == {"plain": "loaded", "derivatives": "loaded"}
    assert second["traced"] == 0, "the group program was traced although it was loaded"
    assert not second["warnings"] and _group_files(cache) == stored
    _assert_same_bits(tmp_path / "a.npz", tmp_path / "b.npz")
    assert np.all(np.isfinite(np.load(tmp_path / "b.npz")["derivatives:d_final_psi"]))

    # another swept parameter in a third process: the group program of the μ scan, loaded untraced; only
    # the small program that sets the stiffness is new
    third = _run_scan(cache, tmp_path / "c.npz", "stiffness")
    assert third["how"] == {"stiffness": "loaded"} and third["traced"] == 0 and not third["warnings"]
    assert _group_files(cache) == stored
    assert len(list((cache / sp.SUBFOLDER).glob("scan-members-*-cache"))) == 2
    assert np.all(np.load(tmp_path / "c.npz")["stiffness:status"] == 0)

    # the stored program gives the bits of the program compiled as for an accelerator (`ChunkProgram`), in
    # this process, without the cache
    monkeypatch.setattr(batch, "stores_whole", lambda spec: False)
    res = jh.scan(
        jh.load_scenario("paper-4.2"),
        {MU: np.linspace(0.2, 0.5, 4)},
        jh.Times(0.5, n=6),
        observables=["final_psi", "max_tilt", obs_mod.detachment_time_difference("E", "D")],
        histories=["position"],
        options=jh.SolverOptions(diffrax.Tsit5()),
    )
    a = np.load(tmp_path / "a.npz")
    for k in [*res.data, *res.histories]:
        np.testing.assert_array_equal(res[k], a[f"plain:{k}"], err_msg=k, strict=True)


_SIMULATE_SCRIPT = r"""
import json, sys, warnings
import equinox as eqx, jax, numpy as np
jax.config.update("jax_enable_x64", True)
jax.config.update("jax_num_cpu_devices", int(sys.argv[4]))
import jaxhoist as jh
from jaxhoist._numerics import compile_cache, solve

traced = []
_plain = solve._solve_plain
def counting(*args, **kwargs):  # every trace of the solve core calls it
    traced.append(1)
    return _plain(*args, **kwargs)
solve._solve_plain = counting

warnings.simplefilter("always")
out = {}
with warnings.catch_warnings(record=True) as caught:
    jh.enable_compilation_cache(sys.argv[1])
    for mu in sys.argv[5:]:
        sc = jh.load_scenario("paper-4.2")
        sc = eqx.tree_at(lambda s: s.foundation.friction_coefficient, sc, float(mu))
        traj = jh.simulate(sc, jh.Times(0.3, n=int(sys.argv[3])))
        for k in ("position", "euler", "rope_tension", "normal_forces"):
            out[f"{k}@{mu}"] = np.asarray(getattr(traj, k))
np.savez(sys.argv[2], **out)
print(json.dumps({"traced": len(traced), "programs": compile_cache.count("simulate"),
                  "warnings": [str(w.message) for w in caught], "devices": len(jax.devices())}))
"""


def _run_simulate(cache: Path, out: Path, devices: int, *mus: str) -> dict:
    return run_script(_SIMULATE_SCRIPT, cache, out, N_SAVE, devices, *mus)


def test_a_second_process_loads_simulates_solve_core_untraced_with_the_same_bits(tmp_path, paper42):
    """With the default solver (Rosenbrock-W) and N_SAVE saved times: the in-process solve below is the
    program of the default solver that tests/test_rosenbrock.py compiles (`default_run`), shared. The
    first process has two host devices (as the command line on two cores), the second one (as a script
    that leaves JAX's default): the stored single-device program is the same for both."""
    cache = tmp_path / "cache"
    first = _run_simulate(cache, tmp_path / "a.npz", 2, "0.25")  # paper-4.2's own μ
    assert first["traced"] > 0 and first["programs"] == 1 and first["devices"] == 2
    [stored] = sorted((cache / sp.SUBFOLDER).glob("solve-*-cache"))
    second = _run_simulate(cache, tmp_path / "b.npz", 1, "0.25", "0.3")  # another value: the same program
    assert second["traced"] == 0 and second["programs"] == 1 and not second["warnings"]
    assert second["devices"] == 1
    a, b = np.load(tmp_path / "a.npz"), np.load(tmp_path / "b.npz")
    for k in a.files:
        np.testing.assert_array_equal(a[k], b[k], err_msg=k, strict=True)
    assert not np.array_equal(b["position@0.25"], b["position@0.3"])
    # the bits of the plain `jax.jit` core in this process (the cache off)
    traj = jh.simulate(paper42, jh.Times(0.3, n=N_SAVE))
    np.testing.assert_array_equal(np.asarray(traj.position), a["position@0.25"], strict=True)
    assert sorted((cache / sp.SUBFOLDER).glob("*-cache")) == [stored]


def test_simulate_under_a_callers_trace_stores_nothing(tmp_path, monkeypatch, paper42):
    """With the cache on, `simulate` under a caller's `jax.jit` (its inputs tracers) traces the plain `jit`
    core into the caller's program: nothing is compiled apart, nothing stored, and the values are those of
    the untraced call."""
    monkeypatch.setattr(pc, "_ENABLED", [tmp_path])
    ts = jh.Times(0.3, n=N_SAVE)  # the test above's saved times: its in-process `simulate` program, shared
    got = jax.jit(lambda mu: jh.simulate(paper42.replace(**{MU: mu}), ts, throw=False).position)(0.25)
    assert not (tmp_path / sp.SUBFOLDER).exists()
    monkeypatch.setattr(pc, "_ENABLED", [None])
    np.testing.assert_allclose(got, jh.simulate(paper42, ts).position, rtol=1e-12)


_LOCATOR_SCRIPT = r"""
import json, sys
import diffrax, jax, jax.numpy as jnp
jax.config.update("jax_enable_x64", True)
import jaxhoist as jh
from jaxhoist._apps.bifurcation import eval as eval_mod
from jaxhoist._numerics import observables as obs_mod

traced = []
_value = eval_mod._value
def counting(*args, **kwargs):  # every trace of the value and slope programs calls it
    traced.append(1)
    return _value(*args, **kwargs)
eval_mod._value = counting

jh.enable_compilation_cache(sys.argv[1])
sc = jh.load_scenario("paper-4.3").unlabelled()
# Tsit5: the route is what is tested, not the solver (the default solver's compiles take longer)
ev = eval_mod.Evaluator(sc, "foundation.friction_coefficient", obs_mod.get("final_theta"),
                        jnp.linspace(0.0, 0.5, 6), jh.SolverOptions(diffrax.Tsit5()))
y = ev.value(0.36)
y2, dy = ev.value_and_slope(0.365)
print(json.dumps({"values": [y, y2, dy], "traced": len(traced)}))
"""


def test_a_second_process_loads_the_locators_solves_untraced_with_the_same_bits(tmp_path):
    runs = [run_script(_LOCATOR_SCRIPT, tmp_path / "cache") for _ in range(2)]
    assert runs[0]["traced"] > 0 and runs[1]["traced"] == 0
    assert runs[0]["values"] == runs[1]["values"]  # bit for bit (JSON keeps every digit of a float)
    names = sorted(p.name.rsplit("-", 2)[0] for p in (tmp_path / "cache" / sp.SUBFOLDER).glob("*-cache"))
    assert names == ["bifurcation-jvp", "bifurcation-value"]


# The first lines of the scripts below: JAX's report of each trace of a program compiled apart, counted in
# `traced` by the program's name.
_TRACE_LOG = r"""
import collections
import jax
traced = collections.Counter()
def listen(event, duration, **kwargs):
    if event == "/jax/core/compile/jaxpr_trace_duration":
        traced[kwargs.get("fun_name", "?")] += 1
jax.monitoring.register_event_duration_secs_listener(listen)
"""

_JVP_SCRIPT = (
    _TRACE_LOG
    + r"""
import json, sys
import diffrax, numpy as np
jax.config.update("jax_enable_x64", True)
import jaxhoist as jh
from jaxhoist._numerics import compile_cache

jh.enable_compilation_cache(sys.argv[1])
forward = jh.SolverOptions(adjoint=diffrax.ForwardMode())
def x_end(mu):  # docs/getting-started.md's derivative, over 0.3 s
    sc = jh.load_scenario("paper-4.2").replace(**{"foundation.friction_coefficient": mu})
    return jh.simulate(sc, jh.Times(0.3, n=2), options=forward).position[-1]
out = [np.asarray(v).tolist() for mu in sys.argv[2:] for v in jax.jvp(x_end, (float(mu),), (1.0,))]
print(json.dumps({"traced": dict(traced), "programs": compile_cache.count("simulate-jvp"), "out": out}))
"""
)


def test_a_second_process_loads_the_derivative_of_a_callers_jvp_untraced_with_the_same_bits(tmp_path):
    """`jax.jvp` of a function that calls `simulate` with forward-mode options (getting-started.md's first
    derivative): the first process compiles and stores the derivative's program, a second one loads it for
    other values without tracing the solve; the values and derivatives are, bit for bit, those of the
    program JAX builds with the cache off (a `jax.custom_jvp` rule that held no leaf as a symbolic zero
    would round differently)."""
    cache = tmp_path / "cache"
    first = run_script(_JVP_SCRIPT, cache, "0.3")
    assert first["traced"].get("solve_jvp", 0) == 1 and first["programs"] == 1
    [stored] = sorted((cache / sp.SUBFOLDER).glob("*-cache"))
    assert stored.name.startswith("solve_jvp-")  # the derivative's program, its primal included
    second = run_script(_JVP_SCRIPT, cache, "0.3", "0.35")
    assert not {"solve_jvp", "solve"} & set(second["traced"]) and second["programs"] == 1
    assert second["out"][:2] == first["out"]
    assert second["out"][1] != second["out"][3]  # another μ, another derivative
    assert sorted((cache / sp.SUBFOLDER).glob("*-cache")) == [stored]

    def x_end(mu):  # the cache off: the program JAX builds from the caller's jax.jvp
        sc = jh.load_scenario("paper-4.2").replace(**{MU: mu})
        opts = jh.SolverOptions(adjoint=diffrax.ForwardMode())
        return jh.simulate(sc, jh.Times(0.3, n=2), options=opts).position[-1]

    x, dx = jax.jvp(x_end, (0.3,), (1.0,))
    assert [np.asarray(x).tolist(), np.asarray(dx).tolist()] == first["out"]


_IDENTIFY_SCRIPT = (
    _TRACE_LOG
    + r"""
import json, sys, warnings
import diffrax, numpy as np
jax.config.update("jax_enable_x64", True)
import jaxhoist as jh

from jaxhoist._apps.identify import core
calls = collections.Counter()  # traces of the model and of the model with its Jacobian, by their solves
def counting(name, f):
    def wrapper(*args, **kwargs):
        calls[name] += 1
        return f(*args, **kwargs)
    return wrapper
core.solve = counting("model", core.solve)
core._sensitivity_solve = counting("jacobian", core._sensitivity_solve)

warnings.simplefilter("always")
with warnings.catch_warnings(record=True) as caught:
    jh.enable_compilation_cache(sys.argv[1])
    sc = jh.load_scenario("paper-4.2")
    m = jh.synthetic_measurement(sc, np.linspace(0.0, 0.4, 21), ["position"])
    # Tsit5, as `fit_solver_options` advises for short records: its programs compile in a fraction of the
    # default solver's time, and the route stored and loaded is the same
    res = jh.identify(sc, m, ["mu"], start={"mu": 0.3}, noise={"position": 0.005},
                      options=jh.SolverOptions(diffrax.Tsit5()))
print(json.dumps({"traced": dict(traced), "calls": dict(calls), "warnings": [str(w.message) for w in caught],
                  "fit": [res.values[0].hex(), res.cost.hex(), res.iterations]}))
"""
)


def test_a_second_process_loads_the_identify_pieces_untraced_with_the_same_bits(tmp_path):
    """`identify`'s Levenberg-Marquardt pieces (its start and one step, `identify.core`), stored whole: a
    second process fits without tracing the model. The tests' one-parameter problem (tests/test_identify.py:
    μ from the mass-centre path, 21 samples)."""
    first, second = (run_script(_IDENTIFY_SCRIPT, tmp_path / "cache", timeout=900) for _ in range(2))
    assert first["traced"].get("lm_init", 0) == 1 and first["traced"].get("lm_step", 0) == 1
    # the pieces trace the residual function and its Jacobian more than once, the model and the model with
    # its Jacobian once each (nested programs: `identify.core.model_nested`); twice each without them
    assert first["calls"] == {"model": 1, "jacobian": 1}
    stored = sorted(p.name.rsplit("-", 2)[0] for p in (tmp_path / "cache" / sp.SUBFOLDER).glob("*-cache"))
    assert stored == ["identify-init", "identify-step", "solve"]  # solve: the synthetic measurement's
    assert not {"lm_init", "lm_step"} & set(second["traced"]), f"traced although stored: {second['traced']}"
    assert second["calls"] == {}
    assert not second["warnings"]
    assert first["fit"][2] > 1 and second["fit"] == first["fit"]  # bit for bit


_RIGID_SCRIPT = (
    _TRACE_LOG
    + r"""
import json, sys, warnings
import numpy as np
jax.config.update("jax_enable_x64", True)
import jaxhoist as jh
from jaxhoist._numerics import compile_cache

warnings.simplefilter("always")
with warnings.catch_warnings(record=True) as caught:
    jh.enable_compilation_cache(sys.argv[1])
    tr = jh.simulate_rigid(jh.load_scenario("paper-4.1"), jh.Times(1.0, n=11))
np.savez(sys.argv[2], position=np.asarray(tr.position), euler=np.asarray(tr.euler),
         normal_forces=np.asarray(tr.normal_forces))
print(json.dumps({"traced": dict(traced), "warnings": [str(w.message) for w in caught],
                  "pieces": sorted(k for k, _ in compile_cache._CACHE if k.startswith("rigid-"))}))
"""
)


def test_a_second_process_loads_the_rigid_models_pieces_untraced_with_the_same_bits(tmp_path):
    """The rigid model's phase driver (`numerics.rigid.compiled`): the phase solve and the guards, contact
    matrices, candidate configurations, forces and outputs it evaluates on the host between phases, each
    stored whole (`compile_cache.stored_jit`). paper-4.1's first second: its start jerk, a few phases."""
    first, second = (run_script(_RIGID_SCRIPT, tmp_path / "cache", tmp_path / f"{x}.npz") for x in "ab")
    pieces = first["pieces"]
    assert "rigid-phase-solve" in pieces and len(pieces) >= 4, pieces
    assert first["traced"].get("_phase_solve", 0) == 1
    stored = sorted(p.name.rsplit("-", 2)[0] for p in (tmp_path / "cache" / sp.SUBFOLDER).glob("*-cache"))
    assert stored == pieces  # one program each, stored whole
    assert second["pieces"] == pieces and not second["warnings"]
    names = {"_phase_solve", "raw_guards", "contact_matrices", "eval_candidates", "forces", "_outputs"}
    assert not names & set(second["traced"]), f"traced although stored: {second['traced']}"
    _assert_same_bits(tmp_path / "a.npz", tmp_path / "b.npz")


def test_stored_jit_keys_programs_as_filter_jit_does(monkeypatch):
    """One program per argument structure, shape, dtype and weak type; a keyword call shares the positional
    call's program; a repeated call finds its executable without going through `program` again; under a
    caller's trace the function is traced inline, compiling nothing of its own."""
    from jaxhoist._numerics import compile_cache

    monkeypatch.setattr(pc, "_ENABLED", [None])  # nothing stored: the key covers jaxhoist's code, not this
    made = []  # the calls that went through `program` (a miss of stored_jit's own lookup)
    program = compile_cache.program

    def counted(kind, *args, **kwargs):
        made.append(kind)
        return program(kind, *args, **kwargs)

    monkeypatch.setattr(compile_cache, "program", counted)

    @compile_cache.stored_jit("test-stored-jit")
    def f(x, scale, offset=1.0):
        return {"y": x * scale + offset}

    def programs():
        assert len(made) == compile_cache.count("test-stored-jit")  # each program made once
        return len(made)

    x = jax.numpy.arange(3.0)
    assert programs() == 0
    np.testing.assert_array_equal(f(x, 2.0)["y"], x * 2.0 + 1.0)  # scale and offset static (Python floats)
    assert programs() == 1
    np.testing.assert_array_equal(f(x, scale=2.0, offset=1.0)["y"], x * 2.0 + 1.0)
    assert programs() == 1  # the keyword call is the same program
    f(x + 1.0, 2.0)
    assert programs() == 1  # other values, the same program
    np.testing.assert_array_equal(f(x, 3.0)["y"], x * 3.0 + 1.0)
    assert programs() == 2  # another static value
    weak = jax.numpy.asarray(2.0)  # a weakly typed float64 scalar: its own program, as under filter_jit
    strong = jax.numpy.asarray(2.0, dtype=jax.numpy.float64)
    assert weak.weak_type and not strong.weak_type
    f(x, weak)
    f(x, strong)
    assert programs() == 4
    assert f(x, weak)["y"].dtype == f(x, strong)["y"].dtype == x.dtype
    np.testing.assert_array_equal(jax.jit(lambda v: f(v, strong)["y"])(x), x * 2.0 + 1.0)
    assert programs() == 4  # traced into the caller's program
    compile_cache.clear("test-stored-jit")
    assert compile_cache.count("test-stored-jit") == 0
