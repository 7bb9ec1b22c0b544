"""The persistent compilation cache: compiled cores without host callbacks (which JAX refuses to store), a
second process that loads instead of compiling and returns the same bits (JAX's cache, for a user's own
`jax.jit` around `simulate`; jaxhoist's own programs stored whole: also tests/test_stored_programs.py), a
damaged entry recompiled rather than trusted, `--no-cache`, the cache folder's location and size bound,
and the compiler options of jaxhoist's own programs.
Every test uses a folder under `tmp_path`, never the user's cache."""

import hashlib
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import N_SAVE, SOLVE_OPTIONS

import jaxhoist as jh
from jaxhoist._apps.identify import core as identify_core
from jaxhoist._apps.identify import fit as identify_fit
from jaxhoist._apps.identify.options import fit_solver_options
from jaxhoist._io.measurement import Measurement
from jaxhoist._numerics import batch, compile_cache, xla_options
from jaxhoist._numerics import persistent_cache as pc
from jaxhoist._numerics import solve as solve_mod
from jaxhoist._numerics import stored_programs as sp
from jaxhoist._numerics.observables import get as get_observable
from jaxhoist._numerics.solve import _solve_jit, as_float64_leaves

ROOT = Path(__file__).resolve().parents[1]


def _custom_call_targets(lowered) -> list[str]:
    text = lowered.as_text()
    return re.findall(r"custom_call @(\w+)", text) + re.findall(r'call_target_name = "(\w+)"', text)


def _assert_no_host_callback(lowered):
    targets = _custom_call_targets(lowered)
    assert targets, "no custom_call at all: the pattern no longer matches the lowered text"
    callbacks = sorted({t for t in targets if "callback" in t})
    assert not callbacks, f"host callbacks in the compiled program: {callbacks}"


@pytest.fixture(scope="module")
def tiny():
    sc = as_float64_leaves(jh.load_scenario("paper-4.2")).unlabelled()
    return sc, jnp.linspace(0.0, 0.2, 5)


def test_default_simulate_core_has_no_host_callback(tiny):
    sc, ts = tiny
    _assert_no_host_callback(_solve_jit.lower(sc, ts, jh.SolverOptions()))


def test_jaxhoists_programs_compile_with_its_compiler_options(monkeypatch, tiny, tmp_path):
    """On CPU this jaxlib takes jaxhoist's compiler options (`xla_options`), no other backend gets them, and
    the programs jaxhoist compiles itself (`compile_cache.program`: `simulate`'s core with concrete inputs,
    the cache off and on) are compiled with them."""
    assert xla_options.compiler_options("cpu") == xla_options.CPU_OPTIONS
    assert xla_options.compiler_options("gpu") == {}
    seen = []
    compile_lowered = jax.stages.Lowered.compile

    def spy(self, compiler_options=None, **kwargs):
        seen.append(compiler_options)
        return compile_lowered(self, compiler_options, **kwargs)

    monkeypatch.setattr(jax.stages.Lowered, "compile", spy)
    x = jnp.arange(3.0)
    for folder in (None, tmp_path):
        monkeypatch.setattr(pc, "_ENABLED", [folder])
        compile_cache.clear("test-options")
        exe = compile_cache.program("test-options", "x", jnp.cumsum, (x,))[0]
        np.testing.assert_array_equal(exe(x), [0.0, 1.0, 3.0])
    assert seen == [xla_options.CPU_OPTIONS] * 2
    sc, ts = tiny
    monkeypatch.setattr(
        compile_cache, "program", lambda kind, *args, **kwargs: (seen.append(kind), (None,))[1]
    )
    assert solve_mod._core(sc, ts, jh.SolverOptions()) is None and seen[-1] == "simulate"


def test_simulate_compiles_one_program_for_any_tolerances(paper42, monkeypatch):
    """`simulate` passes rtol and atol to its compiled core as values (`SolverOptions.traced_tolerances`): a
    solve at other tolerances compiles nothing, and uses the tolerances it is given (it takes other steps).
    That the values are bit for bit those of a program with the tolerances compiled in is
    tests/test_reference_results.py's (its references were computed so). The library's cache is off
    meanwhile: a program of its own for the other tolerances would be compiled here, not loaded."""
    monkeypatch.setattr(pc, "_ENABLED", [None])
    ts = jh.Times(ts=jnp.linspace(0.0, 0.5, N_SAVE))
    compiled = []

    def listener(event, duration, **kw):
        if event == "/jax/core/compile/backend_compile_duration":
            compiled.append(kw.get("fun_name"))

    shared = jh.simulate(paper42, ts, options=SOLVE_OPTIONS)  # the shared program of the physics tests
    jax.monitoring.register_event_duration_secs_listener(listener)
    try:
        loose = jh.simulate(paper42, ts, options=jh.SolverOptions(diffrax.Tsit5(), rtol=1e-4, atol=1e-6))
    finally:
        jax.monitoring.unregister_event_duration_listener(listener)
    assert not [name for name in compiled if "solve" in str(name)], compiled
    assert int(loose.num_accepted_steps) < int(shared.num_accepted_steps)
    assert not np.array_equal(np.asarray(loose.position), np.asarray(shared.position))


def test_forward_mode_derivative_of_the_core_has_no_host_callback(tiny):
    # `jax.jvp` of the compiled core differentiates its traced program after the core's own trace has ended:
    # the custom JVP rule (the augmented solve) must trace diffrax's checks without callbacks too
    sc, ts = tiny
    forward = jh.SolverOptions(adjoint=diffrax.ForwardMode())

    def x_end(mu):
        return _solve_jit(sc.replace(**{"foundation.friction_coefficient": mu}), ts, forward).position[-1, 0]

    _assert_no_host_callback(jax.jit(lambda mu: jax.jvp(x_end, (mu,), (1.0,))).lower(0.3))


def test_a_progress_meter_is_a_host_callback(tiny):
    # the check above can fail: the in-loop meter, asked for, is a callback
    sc, ts = tiny
    targets = _custom_call_targets(
        _solve_jit.lower(sc, ts, jh.SolverOptions(progress_meter=diffrax.TextProgressMeter()))
    )
    assert any("callback" in t for t in targets)


def test_default_scan_group_program_has_no_host_callback(tiny):
    sc, ts = tiny
    spec = batch.BatchSpec(
        paths=("foundation.friction_coefficient",),
        observables=(get_observable("final_psi"), get_observable("liftoff_time")),
        histories=("position",),
        options=jh.SolverOptions(),
        lanes=2,
        devices=(jax.devices()[0],),
    )
    lowered = batch.chunk_fn(spec).lower(sc, ts, jnp.full((1, 2, 1), 0.5), jnp.ones((1,), bool))
    for program in lowered.lowered.values():
        _assert_no_host_callback(program)


def test_identify_pieces_have_no_host_callback(tiny):
    # the tests' one-parameter problem (tests/test_identify.py); the data values do not enter the programs
    sc, _ = tiny
    t = np.linspace(0.0, 0.4, 21)
    names = ("position_x", "position_y", "position_z")
    m = Measurement(t, {n: np.ones_like(t) for n in names}, {n: 0.005 for n in names})
    prob = identify_fit._setup(sc, m, ["mu"], options=fit_solver_options(None))
    z0 = jnp.asarray(identify_fit.flat_z(prob.params, prob.theta0))
    lm_tol, scale = jnp.asarray([1e-4, 1e-6]), jnp.asarray(1.0)
    fn = identify_core.Residuals(prob.cfg)
    init = eqx.filter_jit(identify_core.lm_init).lower(fn, z0, prob.args, lm_tol, scale)
    assert "callback" not in init.as_text()  # the first state: no solve, no custom_call at all
    carry, _ = init.compile()(fn, z0, prob.args, lm_tol, scale)
    _assert_no_host_callback(eqx.filter_jit(identify_core.lm_step).lower(fn, carry, prob.args, lm_tol, scale))


# ------------------------------------------------------------------------------------ across processes

# The scripts' first lines: JAX's log of persistent-cache hits and misses collected in `seen` by program name.
_CACHE_LOG = r"""
import logging
seen = {"hits": [], "misses": []}

class Record(logging.Handler):
    def emit(self, record):
        m = record.getMessage()
        if m.startswith("Persistent compilation cache hit for"):
            seen["hits"].append(m.split("'")[1])
        elif m.startswith("PERSISTENT COMPILATION CACHE MISS for"):
            seen["misses"].append(m.split("'")[1])

log = logging.getLogger("jax._src.compiler")
log.addHandler(Record())
log.setLevel(logging.DEBUG)
log.propagate = False
"""

_SOLVE_SCRIPT = (
    _CACHE_LOG
    + r"""
import json, sys
import diffrax, equinox as eqx, jax, numpy as np
jax.config.update("jax_enable_x64", True)
import jaxhoist as jh

seen["warnings"] = []
import warnings
warnings.simplefilter("always")
with warnings.catch_warnings(record=True) as caught:
    folder = jh.enable_compilation_cache(sys.argv[1])
    base = jh.load_scenario("paper-4.2")

    # Tsit5: what is tested is the cache, not the solver (Tsit5's program compiles in a fraction of the time
    # of the default Rosenbrock-W's; a stored program of the default solver: tests/test_stored_programs.py)
    options = jh.SolverOptions(diffrax.Tsit5())

    @jax.jit
    def lift(mu):  # a user's own program around simulate: JAX's cache stores it (no stored program)
        sc = eqx.tree_at(lambda s: s.foundation.friction_coefficient, base, mu)
        traj = jh.simulate(sc, jh.Times(0.2, n=5), options=options, throw=False)
        return {k: getattr(traj, k) for k in ("position", "euler", "rope_tension", "normal_forces")}

    out = {}
    for mu in sys.argv[3:]:
        for k, v in lift(float(mu)).items():
            out[f"{k}@{mu}"] = np.asarray(v)
seen["warnings"] = [str(w.message) for w in caught]
np.savez(sys.argv[2], **out)
print(json.dumps(seen))
"""
)


def _cold_env() -> dict[str, str]:
    """This environment without the test session's compilation cache (tests/conftest.py), which JAX would
    use in a subprocess: each test here starts from a folder of its own, as a new user does."""
    return {
        k: v
        for k, v in os.environ.items()
        if not k.startswith("JAX_PERSISTENT_CACHE") and k != "JAX_COMPILATION_CACHE_DIR"
    }


def run_script(script: str, *args: object, timeout: float = 600) -> dict:
    """Run `script` (Python source) in a fresh process with a cold environment (`_cold_env`, no
    `JAXHOIST_CACHE_DIR`: the script names its cache folder) and `args` as its arguments; **returns** the JSON
    object its last line of output prints."""
    env = {**_cold_env(), "PYTHONPATH": str(ROOT), "JAX_PLATFORMS": "cpu"}
    env.pop(pc.ENV_VAR, None)
    proc = subprocess.run(
        [sys.executable, "-c", script, *map(str, args)],
        env=env,
        capture_output=True,
        text=True,
        timeout=timeout,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def _run_solve(cache: Path, out: Path, *mus: str) -> dict:
    return run_script(_SOLVE_SCRIPT, cache, out, *mus)


def _entries(folder: Path) -> list[Path]:
    return sorted(p for p in folder.iterdir() if p.name.endswith("-cache"))


def test_second_process_loads_the_program_and_returns_the_same_bits(tmp_path):
    cache = tmp_path / "cache"
    first = _run_solve(cache, tmp_path / "a.npz", "0.5")
    assert "jit_lift" in first["misses"] and "jit_lift" not in first["hits"]
    written = _entries(cache)
    assert any(p.name.startswith("jit_lift-") for p in written)

    # a new process, the same value and another one: the program is loaded from JAX's cache, not compiled
    second = _run_solve(cache, tmp_path / "b.npz", "0.5", "0.3")
    assert "jit_lift" in second["hits"] and "jit_lift" not in second["misses"]
    assert _entries(cache) == written  # nothing new was compiled and stored
    a, b = np.load(tmp_path / "a.npz"), np.load(tmp_path / "b.npz")
    for k in a.files:
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)  # bit for bit
    assert not np.array_equal(b["position@0.5"], b["position@0.3"])  # the new value was solved

    # a damaged entry (here: every entry, bytes flipped in the middle) is not trusted: it is recompiled
    for p in written:
        data = bytearray(p.read_bytes())
        mid = len(data) // 2
        data[mid : mid + 16] = bytes(x ^ 0xFF for x in data[mid : mid + 16])
        p.write_bytes(bytes(data))
    third = _run_solve(cache, tmp_path / "c.npz", "0.5")
    assert "jit_lift" in third["misses"] and "jit_lift" not in third["hits"]
    assert any("persistent compilation cache" in w for w in third["warnings"])
    c = np.load(tmp_path / "c.npz")
    for k in c.files:
        np.testing.assert_array_equal(a[k], c[k], err_msg=k)


def _cli(
    tmp_path: Path, out: str, *extra: str, cache: str, quiet: bool = True
) -> subprocess.CompletedProcess:
    env = {**_cold_env(), "PYTHONPATH": str(ROOT), "JAX_PLATFORMS": "cpu", pc.ENV_VAR: cache}
    env.pop("PYTHONUNBUFFERED", None)  # stdout block-buffered into the pipe, as a user's `cmd > file` gets it
    args = ["simulate", "paper-4.2", "--out", str(tmp_path / out), "--t1", "0.2", "--n-save", "5"]
    proc = subprocess.run(
        [sys.executable, "-m", "jaxhoist", *args, "--no-plots", *(["--quiet"] if quiet else []), *extra],
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    return proc


def test_cli_no_cache_writes_nothing_and_the_default_writes_the_cache(tmp_path):
    # (JAXHOIST_CACHE_DIR="" is checked in-process: test_empty_cache_dir_switches_the_cache_off)
    cache = tmp_path / "cache"
    _cli(tmp_path, "a", "--no-cache", cache=str(cache))
    assert not cache.exists()
    first = _cli(tmp_path, "b", cache=str(cache), quiet=False)
    assert "compiling" in first.stderr and "loading the compiled program" not in first.stderr
    # the command ends with `os._exit` (`cli.entry_point`): its summary on the piped stdout is whole
    assert first.stdout.splitlines()[-1].startswith("wrote "), first.stdout[-3000:]
    stored = _entries(cache / sp.SUBFOLDER)
    assert [p.name.split("-")[0] for p in stored] == ["solve"]

    # the same command again loads the stored program (no tracing, no compiling) and writes the same bits
    second = _cli(tmp_path, "c", cache=str(cache), quiet=False)
    assert "loading the compiled program" in second.stderr and "compiling" not in second.stderr
    a, b = np.load(tmp_path / "b" / "trajectory.npz"), np.load(tmp_path / "c" / "trajectory.npz")
    for k in a.files:
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)


# ------------------------------------------------------------------------------------ stored programs

_STORED_SCRIPT = r"""
import sys
from pathlib import Path
import jax, jax.numpy as jnp, numpy as np
jax.config.update("jax_enable_x64", True)
from jaxhoist._numerics import stored_programs as sp

def f(d, k):  # a linear solve: its LAPACK kernel must work in a process that lowered nothing
    return {"x": jnp.linalg.solve(d["m"], d["v"]) * k, "c": jnp.cumsum(jnp.sin(d["v"]))}

scale = float(sys.argv[3])
args = ({"m": jnp.eye(3) * 2.0 + 0.1 * scale, "v": jnp.arange(3.0) + scale}, 3.0)
program, loaded = sp.load_or_compile(Path(sys.argv[1]), "test-f", f, args)
np.savez(sys.argv[2], **{k: np.asarray(v) for k, v in program(*args).items()})
print("loaded" if loaded else "compiled")
"""


def _run_stored(folder: Path, out: Path, scale: str = "1.0") -> tuple[str, str]:
    env = {**_cold_env(), "PYTHONPATH": str(ROOT), "JAX_PLATFORMS": "cpu"}
    proc = subprocess.run(
        [sys.executable, "-c", _STORED_SCRIPT, str(folder), str(out), scale],
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    return proc.stdout.strip().splitlines()[-1], proc.stderr


def test_a_stored_program_is_loaded_by_another_process_with_the_same_bits(tmp_path):
    folder = tmp_path / "cache"
    assert _run_stored(folder, tmp_path / "a.npz")[0] == "compiled"
    [path] = _entries(folder / sp.SUBFOLDER)
    assert _run_stored(folder, tmp_path / "b.npz")[0] == "loaded"
    assert _run_stored(folder, tmp_path / "c.npz", "2.0")[0] == "loaded"  # other values: the same program
    a, b, c = (np.load(tmp_path / f"{x}.npz") for x in "abc")
    for k in a.files:
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)  # bit for bit
        assert not np.array_equal(a[k], c[k])

    # a damaged file is detected (its digest), not run: compiled again, and the file is replaced
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0xFF
    path.write_bytes(bytes(data))
    how, err = _run_stored(folder, tmp_path / "d.npz")
    assert how == "compiled" and "not used" in err
    d = np.load(tmp_path / "d.npz")
    for k in a.files:
        np.testing.assert_array_equal(a[k], d[k], err_msg=k)
    raw, head = path.read_bytes(), len(sp._MAGIC)
    assert hashlib.sha256(raw[head + 32 :]).digest() == raw[head : head + 32]  # rewritten whole


def _stored_args(scale: float = 1.0):
    return ({"m": jnp.eye(3) * 2.0 + 0.1 * scale, "v": jnp.arange(3.0) + scale}, 3.0)


def _f(d, k):
    return {"x": d["m"] @ d["v"] * k}


def test_a_stale_or_foreign_stored_program_is_compiled_again(tmp_path, monkeypatch):
    args = _stored_args()
    program, loaded = sp.load_or_compile(tmp_path, "test-g", _f, args)
    assert not loaded
    key = sp.program_key("test-g", args)
    assert key is not None
    path = sp.program_path(tmp_path, "test-g", key)
    assert path.is_file() and sp.load(tmp_path, "test-g", args) is not None

    # a file at the right place that was written for another key (intact digest): refused
    other = sp.program_path(tmp_path, "test-g", key.replace("program test-g", "program test-h"))
    sp._store(other, key.replace("program test-g", "program test-h"), program.executable, program.out_def)
    os.replace(other, path)
    with pytest.warns(UserWarning, match="another key"):
        assert sp.load(tmp_path, "test-g", args) is None

    # another jaxhoist source (or JAX version, static value, shape): another key, so nothing stored applies
    monkeypatch.setattr(sp, "_SOURCE_DIGEST", ["0" * 64])
    assert sp.program_key("test-g", args) != key
    assert sp.program_key("test-g", (args[0], 4.0)) != sp.program_key("test-g", args)
    assert sp.program_key("test-g", ({"m": jnp.eye(4), "v": jnp.ones(4)}, 3.0)) != sp.program_key(
        "test-g", args
    )


class _Elsewhere:  # a class from outside the packages the key covers (its code may change unseen)
    def __repr__(self):
        return "Elsewhere()"


def test_programs_with_uncovered_static_parts_are_not_stored(tmp_path):
    x = {"v": jnp.ones(3)}
    assert sp.program_key("p", (x, lambda v: v)) is None  # no stable name
    assert sp.program_key("p", (x, _Elsewhere())) is None  # code the key does not cover
    assert sp.program_key("p", (x, np.sin, "a", 1.5, (2, None))) is not None
    program, loaded = sp.load_or_compile(tmp_path, "p", lambda d, s: d["v"] * 2.0, (x, _Elsewhere()))
    assert not loaded and not (tmp_path / sp.SUBFOLDER).exists()
    np.testing.assert_array_equal(program(x, _Elsewhere()), 2.0 * np.ones(3))


# ------------------------------------------------------------------------------------ folder and bound


def test_empty_cache_dir_switches_the_cache_off(monkeypatch):
    before = jax.config.jax_compilation_cache_dir
    monkeypatch.setenv(pc.ENV_VAR, "")
    assert pc.enable_compilation_cache() is None
    assert jax.config.jax_compilation_cache_dir == before


def test_cache_folder_location(monkeypatch, tmp_path):
    monkeypatch.setenv(pc.ENV_VAR, str(tmp_path / "here"))
    assert pc.default_cache_dir() == tmp_path / "here"
    monkeypatch.setenv(pc.ENV_VAR, "")
    assert pc.default_cache_dir() is None
    monkeypatch.delenv(pc.ENV_VAR)
    monkeypatch.setattr(sys, "platform", "linux")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert pc.default_cache_dir() == tmp_path / "xdg" / "jaxhoist"
    monkeypatch.delenv("XDG_CACHE_HOME")
    assert pc.default_cache_dir() == Path.home() / ".cache" / "jaxhoist"
    monkeypatch.setattr(sys, "platform", "darwin")
    assert pc.default_cache_dir() == Path.home() / "Library" / "Caches" / "jaxhoist"
    monkeypatch.setattr(sys, "platform", "win32")
    monkeypatch.setenv("LOCALAPPDATA", str(tmp_path / "local"))
    assert pc.default_cache_dir() == tmp_path / "local" / "jaxhoist" / "Cache"


def test_prune_deletes_the_least_recently_used_entries_down_to_the_bound(tmp_path):
    for i in range(10):
        p = tmp_path / f"jit_f{i}-key{i}-cache"
        p.write_bytes(b"x" * 1000)
        os.utime(p, (1000.0 + i, 1000.0 + i))  # entry 0 the oldest
    (tmp_path / "other.txt").write_bytes(b"y" * 5000)  # not an entry: never deleted, not counted
    assert pc.prune(tmp_path, 20_000) == 0
    assert pc.prune(tmp_path, 5000) == 6  # 10 kB -> at most 80 % of 5 kB
    left = sorted(p.name for p in _entries(tmp_path))
    assert left == [f"jit_f{i}-key{i}-cache" for i in range(6, 10)]
    assert (tmp_path / "other.txt").exists()
