"""Name the changes the bifurcation tools located in paper-4.2 and paper-4.3 (`classify_change`).

- paper-4.2, μ = 0.4546517 (`bifurcation_mu.py`'s level crossing of ψ(t1)): expected a steep ramp;
- paper-4.2, μ = 0.4721707 (the jump of the first all-off time `liftoff_time`): expected an
  event-definition change (the last contact does not move);
- paper-4.3, μ* = 0.3635004 (`bifurcation_calibrate.py`'s crossing of ϑ(t1) = 15°): expected a steep ramp.

Each located value is taken with a bracket of ± 1e-6 around its rounded value (the diagram's brackets were
9.8e-7 wide) and classified from 83 solves over ± 5e-3 (paper-4.2) or 51 over ± 6e-3 (paper-4.3), 25 s,
saves every 10 ms.

    python experiments/figures/bifurcation_classify.py --out out/bif-classify  # ~3-5 min on 2 shared cores
    python experiments/figures/bifurcation_classify.py --out out/bif-classify --quick   # smoke check

Writes `classify.json`; prints one line per change.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jaxhoist as jh  # noqa: E402

MU = "foundation.friction_coefficient"
CASES = [
    ("paper-4.2", 0.4546517, "final_psi", 5e-3, 81),
    ("paper-4.2", 0.4721707, "liftoff_time", 5e-3, 81),
    ("paper-4.3", 0.3635004, "final_theta", 6e-3, 49),
]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", required=True)
    p.add_argument("--quick", action="store_true", help="smoke check: the first case, 9 samples over 2 s")
    args = p.parse_args(argv)
    if args.quick:  # smoke runs share one compilation cache ($JAXHOIST_CACHE_DIR: .ci/experiments sets it)
        jh.enable_compilation_cache()
    cases = CASES[:1] if args.quick else CASES
    times = jh.Times(2.0, n=201) if args.quick else jh.Times(25.0, n=2501)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    for preset, mu, obs, half, n in cases:
        c = jh.classify_change(
            jh.load_scenario(preset),
            param=MU,
            bracket=(mu - 1e-6, mu + 1e-6),
            observable=obs,
            half_window=half,
            n_window=9 if args.quick else n,
            times=times,
        )
        print(f"{preset}: {c.summary()}", flush=True)
        rows.append({"preset": preset, **c.to_dict()})
        (out / "classify.json").write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
