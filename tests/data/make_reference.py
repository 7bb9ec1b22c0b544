"""Record the reference results that `tests/test_reference_results.py` compares against.

Moving code between modules must not change any result: this script, run once before such a move, stores
short-horizon results of the three presets with both models and of a 64-member scan with forward-mode
sensitivities in `tests/data/reference_results.npz` (a few hundred kB).
Re-run it only when a result is meant to change, and say why in the commit message.

XLA compiles for the host CPU's vector instructions, so a machine of another kind rounds differently, and
the adaptive solvers turn that rounding into other steps: on an AMD EPYC with AVX2 and no AVX-512, against
the Intel Xeon that recorded `reference_results.npz` (the same code and, as far as the package index
shows, the same versions), the rigid paper-2.3 run took 3 276 accepted steps instead of 1 122, the elastic
positions moved by up to 6e-9 m, and the scan's sensitivities by up to 0.07 m per unit of μ (a member near
a contact switch). Results of one kind of machine therefore go in a file of their own,
`reference_results.<machine>.npz` (`machine()`: architecture, CPU vendor, widest vector extension), which
the test prefers where it exists. For the same reason each file records the XLA compiler options it was
computed with (`STAMP`), and the test compares a file only with results of the same options.

    PYTHONPATH=$PWD python tests/data/make_reference.py                 # reference_results.npz
    PYTHONPATH=$PWD python tests/data/make_reference.py --this-machine  # reference_results.<machine>.npz
"""

from __future__ import annotations

import os
import platform
import sys
from pathlib import Path

import diffrax
import jax
import numpy as np

import jaxhoist as jh
from jaxhoist._numerics import xla_options

PRESETS = ("paper-2.3", "paper-4.1", "paper-4.2")
T1 = 2.0  # [s]: the elastic model's horizon, short so that the comparison stays cheap
# The rigid model's horizon [s] and rope per preset: paper-4.2 with the elastic rope takes 124 000 steps in
# its first 0.1 s, and with either rope it enters a Zeno sequence of impacts at 0.44-0.48 s (more than
# max_phases = 2000 phases), so it runs 0.2 s with the inextensible rope (748 accepted steps).
RIGID = {
    "paper-2.3": (0.45, jh.ElasticRope()),
    "paper-4.1": (0.45, jh.ElasticRope()),
    "paper-4.2": (0.2, jh.InextensibleRope()),
}
N_SAVE = 21
TRAJECTORY_FIELDS = (
    "position",
    "velocity",
    "euler",
    "angular_velocity",
    "normal_forces",
    "rope_tension",
    "hoist_work",
    "friction_work",
    "num_accepted_steps",
)
SCAN_PATH = "foundation.friction_coefficient"
SCAN_VALUES = np.linspace(0.2, 0.4, 64)
SCAN_T1 = 2.0  # [s]
SCAN_OBSERVABLES = ("final_psi", "final_position", "max_tilt")
OUT = Path(__file__).with_name("reference_results.npz")


def machine() -> str:
    """The kind of machine whose XLA code rounds alike: architecture, CPU vendor and widest vector
    extension (x86: avx512 or avx2), e.g. `x86_64-AuthenticAMD-avx2`; the architecture alone where
    /proc/cpuinfo is missing."""
    flags: set[str] = set()
    vendor = ""
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                key, _, value = line.partition(":")
                if key.strip() == "vendor_id" and not vendor:
                    vendor = value.strip()
                elif key.strip() == "flags" and not flags:
                    flags = set(value.split())
    except OSError:
        pass
    isa = "avx512" if "avx512f" in flags else "avx2" if "avx2" in flags else ""
    return "-".join(part for part in (platform.machine(), vendor, isa) if part)


def own_path() -> Path:
    """This kind of machine's own reference file, `reference_results.<machine>.npz`."""
    return OUT.with_name(f"reference_results.{machine()}.npz")


def reference_path() -> Path:
    """This machine's own reference file where one is recorded, else `reference_results.npz`."""
    own = own_path()
    return own if own.exists() else OUT


def _one_label(sc: jh.Scenario, like: jh.Scenario) -> jh.Scenario:
    """`sc` with the static labels (`name`, `t1`, `description`) of `like`, every leaf its own. The labels
    are static fields, so each preset used to compile the elastic solve and the rigid phase kernels again
    (74 s of the test's 88 s); no solve reads them here (the saved times are given), and the arrays are the
    same bit for bit either way (checked against the recorded file when this was introduced)."""
    return jh.Scenario(
        sc.load,
        sc.foundation,
        sc.rope,
        sc.hoist,
        sc.boom,
        sc.gravity,
        name=like.name,
        t1=like.t1,
        description=like.description,
    )


def trajectories() -> dict[str, np.ndarray]:
    """`{preset}/{model}/{field}` -> the field at the N_SAVE saved times of a short simulate per model."""
    out = {}
    like = jh.load_scenario(PRESETS[-1])
    for name in PRESETS:
        sc = _one_label(jh.load_scenario(name), like)
        t1_rigid, rope = RIGID[name]
        runs = {
            "elastic": jh.simulate(sc, jh.Times(T1, n=N_SAVE), model=jh.ElasticFoundation()),
            "rigid": jh.simulate(sc, jh.Times(t1_rigid, n=N_SAVE), model=jh.RigidGround(rope=rope)),
        }
        for model, traj in runs.items():
            for f in TRAJECTORY_FIELDS:
                out[f"{name}/{model}/{f}"] = np.asarray(getattr(traj, f))
    return out


def scan() -> dict[str, np.ndarray]:
    """`scan/{name}` -> every observable, its sensitivity and the status of the 64-member μ scan."""
    res = jh.scan(
        jh.load_scenario("paper-4.2"),
        {SCAN_PATH: SCAN_VALUES},
        jh.Times(SCAN_T1, n=N_SAVE),
        observables=list(SCAN_OBSERVABLES),
        derivatives=True,
        # the solver the reference was recorded with (then the default of scan(derivatives=True))
        options=jh.SolverOptions(diffrax.Tsit5(), adjoint=diffrax.ForwardMode()),
        # one device (valid while the multi-device path changes) and the group width the reference was
        # recorded with (the default for 64 members until the default width followed the device count; a
        # width is a numerical setting: another moves these values by rounding)
        batch=jh.BatchOptions(devices=jax.devices()[:1], lanes=16),
    )
    out = {f"scan/{k}": np.asarray(v) for k, v in res.data.items()}
    out["scan/status"] = np.asarray(res.status)
    out["scan/num_accepted_steps"] = np.asarray(res.num_accepted_steps)
    return out


#: The entry that records the compiler options the arrays were computed with (`xla_options.describe()`):
#: other options round differently, so a file recorded with other ones is not compared (a file without
#: the entry was recorded with XLA's defaults).
STAMP = "meta/compiler_options"


def stamp(arrays: dict[str, np.ndarray]) -> str:
    """The compiler options a recording's arrays were computed with, as `xla_options.describe()` gives
    them."""
    return str(arrays[STAMP]) if STAMP in arrays else xla_options.describe({})


def compute() -> dict[str, np.ndarray]:
    return {**trajectories(), **scan(), STAMP: np.array(xla_options.describe())}


def _setup() -> None:
    """The tests' device set-up (tests/conftest.py): two CPU devices, float64 (before the backend starts;
    under pytest, conftest.py has done it)."""
    try:
        jax.config.update("jax_num_cpu_devices", 2)
    except AttributeError:
        flags = os.environ.get("XLA_FLAGS", "")
        os.environ["XLA_FLAGS"] = (flags + " --xla_force_host_platform_device_count=2").strip()
    jax.config.update("jax_enable_x64", True)


if __name__ == "__main__":
    _setup()
    path = own_path() if "--this-machine" in sys.argv[1:] else OUT
    arrays = compute()
    np.savez_compressed(path, **arrays)
    print(f"{path}: {len(arrays)} arrays, {path.stat().st_size} bytes")
