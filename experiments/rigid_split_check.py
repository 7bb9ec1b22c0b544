"""Bit-for-bit check of a refactoring of the rigid model (issue 15, point 4): runs the presets paper-2.3
(20 s) and paper-4.1 (70 s) with the elastic rope, paper-4.1 with the inextensible rope, and paper-2.3 at
μ = 0.28 with the inextensible rope to 12 s (three compliant phases), and writes or compares their
positions, velocities, normal forces, energy residuals and phase logs.

    python experiments/rigid_split_check.py --write out/split_ref.npz    # before the change
    python experiments/rigid_split_check.py --compare out/split_ref.npz  # after it: identical or exit 1
"""

from __future__ import annotations

import argparse
import sys

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import jaxhoist  # noqa: E402
from jaxhoist import simulate_rigid  # noqa: E402

CASES = (
    ("paper-2.3", None, 20.0, "elastic"),
    ("paper-4.1", None, 70.0, "elastic"),
    ("paper-4.1", None, 70.0, "inextensible"),
    ("paper-2.3", 0.28, 12.0, "inextensible"),
)


def _model(rope: str) -> jaxhoist.RigidGround:
    """The rigid model with the rope named "elastic" (2.14) or "inextensible" (2.15)."""
    ropes = {"elastic": jaxhoist.ElasticRope(), "inextensible": jaxhoist.InextensibleRope()}
    return jaxhoist.RigidGround(rope=ropes[rope])


def run() -> dict:
    out = {}
    for preset, mu, t1, rope in CASES:
        sc = jaxhoist.load_scenario(preset)
        if mu is not None:
            sc = sc.replace(**{"foundation.friction_coefficient": mu})
        tr = simulate_rigid(sc, jaxhoist.Times(t1, n=2001), model=_model(rope))
        key = f"{preset}_{mu}_{rope}"
        out[key + "/position"] = np.asarray(tr.position)
        out[key + "/velocity"] = np.asarray(tr.velocity)
        out[key + "/normal"] = np.asarray(tr.normal_forces)
        out[key + "/residual"] = np.asarray(tr.energy_residual())
        out[key + "/log"] = np.array(tr.phase_log())
        print(key, len(tr.phases), "phases", flush=True)
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    g = p.add_mutually_exclusive_group(required=True)
    g.add_argument("--write")
    g.add_argument("--compare")
    args = p.parse_args(argv)
    out = run()
    if args.write:
        np.savez(args.write, **out)
        return 0
    ref = np.load(args.compare)
    bad = [k for k in ref.files if not np.array_equal(ref[k], out[k])]
    for k in ref.files:
        print(f"{k}: {'identical' if k not in bad else 'DIFFERENT'}")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
