"""The default scan of the code as checked out against the same scan of an earlier git revision, alternating,
on this machine: the comparison behind a claim that a change made the default call faster when the machine
itself is not the one of the recorded figures.

    python experiments/scan_ab.py --rev be34f90                  # 4096 μ, 25 s, 2 rounds
    python experiments/scan_ab.py --rev HEAD~1 --n 1024 --rounds 3

Each round runs the earlier revision (a temporary `git worktree`) and then the current code, each in a fresh
process with `PYTHONPATH` pointing at its tree: the default call `jaxhoist.scan(paper-4.2, μ evenly in
[0.1, 0.6], Times(t1, n=2), observables=[final_position, final_euler])` on `--devices` host devices.
Separate processes, not one (two versions of the package cannot be imported together), so the rounds
alternate and the load average is printed with each run.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

ONE_RUN = """
import os, sys
import jax
jax.config.update("jax_num_cpu_devices", {devices})
jax.config.update("jax_enable_x64", True)
import numpy as np
import jaxhoist as jh
assert jh.__file__.startswith({tree!r}), jh.__file__
sc = jh.load_scenario("paper-4.2")
mus = np.linspace(0.1, 0.6, {n})
r = jh.scan(sc, {{"foundation.friction_coefficient": mus}}, jh.Times({t1}, n=2),
            observables=["final_position", "final_euler"])
t = r.attrs["timings_s"]
print(f"compile {{t['compile']:.1f}} s, {{1e3 * t['compute'] / {n}:.2f}} ms per trajectory, steps median "
      f"{{int(np.median(r.num_accepted_steps))}} max {{int(r.num_accepted_steps.max())}}, failed "
      f"{{int((~r.ok).sum())}}, load {{os.getloadavg()[0]:.2f}}")
"""


def run(tree: Path, args) -> str:
    code = ONE_RUN.format(devices=args.devices, tree=str(tree), n=args.n, t1=args.t1)
    env = {**os.environ, "PYTHONPATH": str(tree)}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, cwd=tree)
    if out.returncode:
        raise SystemExit(f"run in {tree} failed:\n{out.stderr[-3000:]}")
    return out.stdout.strip().splitlines()[-1]


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--rev", required=True, help="the earlier git revision")
    p.add_argument("--n", type=int, default=4096, help="members (default 4096)")
    p.add_argument("--t1", type=float, default=25.0, help="horizon [s] (default 25)")
    p.add_argument("--devices", type=int, default=os.cpu_count() or 1, help="host devices (default: cores)")
    p.add_argument("--rounds", type=int, default=2)
    args = p.parse_args(argv)
    head = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True, check=True
    ).stdout.strip()
    with tempfile.TemporaryDirectory() as tmp:
        old = Path(tmp) / "old"
        subprocess.run(["git", "worktree", "add", "-q", "--detach", str(old), args.rev], cwd=ROOT, check=True)
        try:
            for k in range(args.rounds):
                print(f"round {k + 1}: {args.rev}: {run(old, args)}", flush=True)
                print(f"round {k + 1}: checked out ({head}, with any changes): {run(ROOT, args)}", flush=True)
        finally:
            subprocess.run(["git", "worktree", "remove", "--force", str(old)], cwd=ROOT, check=True)


if __name__ == "__main__":
    main()
