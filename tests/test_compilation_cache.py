"""The persistent compilation cache: compiled cores without host callbacks (which JAX refuses to store), a
second process that loads instead of compiling and returns the same bits, a damaged entry recompiled rather
than trusted, `--no-cache`, and the cache folder's location and size bound. Every test uses a folder under
`tmp_path`, never the user's cache."""

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxhoist as jh
from jaxhoist._numerics import batch
from jaxhoist._numerics import persistent_cache as pc
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


# ------------------------------------------------------------------------------------ across processes

_SOLVE_SCRIPT = r"""
import json, logging, sys
import equinox as eqx, jax, numpy as np
jax.config.update("jax_enable_x64", True)
import jaxhoist as jh

seen = {"hits": [], "misses": [], "warnings": []}

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
import warnings
warnings.simplefilter("always")
with warnings.catch_warnings(record=True) as caught:
    folder = jh.enable_compilation_cache(sys.argv[1])
    out = {}
    for mu in sys.argv[3:]:
        sc = jh.load_scenario("paper-4.2")
        sc = eqx.tree_at(lambda s: s.foundation.friction_coefficient, sc, float(mu))
        traj = jh.simulate(sc, jh.Times(0.2, n=5))
        for k in ("position", "euler", "rope_tension", "normal_forces"):
            out[f"{k}@{mu}"] = np.asarray(getattr(traj, k))
seen["warnings"] = [str(w.message) for w in caught]
np.savez(sys.argv[2], **out)
print(json.dumps(seen))
"""


def _cold_env() -> dict[str, str]:
    """This environment without the test session's compilation cache (tests/conftest.py), which JAX would
    use in a subprocess: each test here starts from a folder of its own, as a new user does."""
    return {
        k: v
        for k, v in os.environ.items()
        if not k.startswith("JAX_PERSISTENT_CACHE") and k != "JAX_COMPILATION_CACHE_DIR"
    }


def _run_solve(cache: Path, out: Path, *mus: str) -> dict:
    env = {**_cold_env(), "PYTHONPATH": str(ROOT), "JAX_PLATFORMS": "cpu"}
    env.pop(pc.ENV_VAR, None)
    proc = subprocess.run(
        [sys.executable, "-c", _SOLVE_SCRIPT, str(cache), str(out), *mus],
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def _entries(folder: Path) -> list[Path]:
    return sorted(p for p in folder.iterdir() if p.name.endswith("-cache"))


def test_second_process_loads_the_program_and_returns_the_same_bits(tmp_path):
    cache = tmp_path / "cache"
    first = _run_solve(cache, tmp_path / "a.npz", "0.5")
    assert "jit_solve" in first["misses"] and "jit_solve" not in first["hits"]
    written = _entries(cache)
    assert any(p.name.startswith("jit_solve-") for p in written)

    # a new process, the same value and another one: the solve core is loaded, never compiled
    second = _run_solve(cache, tmp_path / "b.npz", "0.5", "0.3")
    assert "jit_solve" in second["hits"] and "jit_solve" not in second["misses"]
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
    assert "jit_solve" in third["misses"] and "jit_solve" not in third["hits"]
    assert any("persistent compilation cache" in w for w in third["warnings"])
    c = np.load(tmp_path / "c.npz")
    for k in c.files:
        np.testing.assert_array_equal(a[k], c[k], err_msg=k)


def _cli(tmp_path: Path, out: str, *extra: str, cache: str) -> subprocess.CompletedProcess:
    env = {**_cold_env(), "PYTHONPATH": str(ROOT), "JAX_PLATFORMS": "cpu", pc.ENV_VAR: cache}
    args = ["simulate", "paper-4.2", "--out", str(tmp_path / out), "--t1", "0.2", "--n-save", "5"]
    proc = subprocess.run(
        [sys.executable, "-m", "jaxhoist", *args, "--no-plots", "--quiet", *extra],
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
    _cli(tmp_path, "b", cache=str(cache))
    assert any(p.name.startswith("jit_solve-") for p in _entries(cache))


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
