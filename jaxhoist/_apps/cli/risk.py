"""`jaxhoist risk`: the command line of `lift_risk` (argument parsing, the table it prints, the files and
maps it writes).

    jaxhoist risk my-lift.toml --uncertain "foundation.friction_coefficient=uniform(0.2,0.4)" \\
        --uncertain "load.mass_centre[0]=normal(1.0,0.05)" --design "boom.tip_position[0]=1:2:3" \\
        --hazard slide=0.25 --hazard tilt=3deg --hazard strike --samples 128 --t1 3 --out out/risk
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np

from ..._errors import ScenarioError
from ..._io.validate import parse_values
from ..planning import (
    Fixed,
    Hazard,
    LiftRisk,
    LogNormal,
    Normal,
    TruncatedNormal,
    Uniform,
    lift_risk,
    no_liftoff,
    overload,
    slide,
    strike,
    swing,
    tilt,
    tip,
)
from ..scan import Grid, Sweep
from .common import (
    add_out_options,
    add_sampled_scan_command,
    add_sampled_scan_options,
    claim_out_dir,
    sampled_scan_inputs,
)

_DISTRIBUTIONS = {
    "uniform": (Uniform, "uniform(low,high)"),
    "normal": (Normal, "normal(mean,std)"),
    "truncnormal": (TruncatedNormal, "truncnormal(mean,std,low,high)"),
    "lognormal": (LogNormal, "lognormal(median,sigma)"),
    "fixed": (Fixed, "fixed(value)"),
}
_CALL = re.compile(r"^\s*([A-Za-z_]+)\s*\(([^()]*)\)\s*$")


def split_item(item: str, flag: str) -> tuple[str, str]:
    path, eq, rest = item.partition("=")
    if not eq or not path.strip() or not rest.strip():
        raise ScenarioError(f"{flag} {item!r}: expected PATH=SPEC")
    return path.strip(), rest.strip()


def parse_distribution(text: str, flag: str = "--uncertain"):
    """`uniform(0.2,0.4)`, `normal(1,0.05)`, `truncnormal(1,0.05,0.8,1.2)`, `lognormal(2,0.1)`, `fixed(3)`
    or a plain number -> the distribution object, or a `ScenarioError` naming the flag."""
    try:
        return Fixed(float(text))
    except (ValueError, TypeError):
        pass
    m = _CALL.match(text)
    kinds = ", ".join(form for _, form in _DISTRIBUTIONS.values())
    if not m or m.group(1).lower() not in _DISTRIBUTIONS:
        raise ScenarioError(f"{flag}: {text!r} is no distribution; use one of {kinds} or a number")
    cls, form = _DISTRIBUTIONS[m.group(1).lower()]
    try:
        args = [float(a) for a in m.group(2).split(",")]
    except ValueError:
        raise ScenarioError(f"{flag}: {text!r}: the arguments must be numbers, as in {form}") from None
    try:
        return cls(*args)
    except TypeError:
        raise ScenarioError(f"{flag}: {text!r}: wrong number of arguments, expected {form}") from None
    except ScenarioError as e:
        raise ScenarioError(f"{flag}: {text!r}: {e}") from None


def parse_hazard(text: str, flag: str = "--hazard") -> Hazard:
    """`slide=0.5`, `tilt=10deg` (or radians: `tilt=0.17`), `tip=30deg` (or radians), `strike`,
    `overload=12000`, `swing=0.3`, `no-liftoff=2.5`, or `NAME:OBSERVABLE>THRESHOLD` /
    `NAME:OBSERVABLE<THRESHOLD` -> a `Hazard`."""
    text = text.strip()
    m = re.match(r"^([\w-]+):([\w\[\]]+)\s*([<>])\s*(\S+)$", text)
    if m:
        name, obs, op, thr = m.groups()
        try:
            value = float(thr)
        except ValueError:
            raise ScenarioError(f"{flag} {text!r}: the threshold {thr!r} is not a number") from None
        return Hazard(name, obs, value, above=op == ">")
    kind, eq, arg = text.partition("=")
    kind = kind.strip().lower().replace("-", "_")
    if kind == "strike" and not eq:
        return strike()
    makers = {"slide": slide, "overload": overload, "swing": swing, "no_liftoff": no_liftoff}
    angles = {"tilt": tilt, "tip": tip}
    if kind not in (*makers, *angles) or not arg.strip():
        raise ScenarioError(
            f"{flag} {text!r}: expected slide=M, tilt=RAD or tilt=DEGdeg, tip=RAD or tip=DEGdeg, strike, "
            f"overload=N, swing=M, no-liftoff=S or NAME:OBSERVABLE>THRESHOLD"
        )
    arg = arg.strip()
    if kind in angles and arg.lower().endswith("deg"):
        number, unit = arg[:-3], "degrees"
    else:
        number, unit = arg, None
    try:
        value = float(number)
    except ValueError:
        raise ScenarioError(f"{flag} {text!r}: {number!r} is not a number") from None
    if kind in angles:
        return angles[kind](degrees=value) if unit else angles[kind](value)
    return makers[kind](value)


def configure_parser(subparsers) -> None:
    """Add `jaxhoist risk SCENARIO --uncertain PATH=DIST ... --hazard SPEC ... [--design PATH=VALUES ...]`."""
    p = add_sampled_scan_command(
        subparsers,
        "risk",
        "hazard probabilities of a lift with uncertain inputs, over a grid of designs",
        "Sample the uncertain inputs (randomised quasi-Monte Carlo), solve every design point with every "
        "sample as one scan, and print and save the probability of each hazard with its confidence "
        "interval (docs/lift-planning.md).",
    )
    p.add_argument(
        "--hazard",
        action="append",
        required=True,
        metavar="SPEC",
        help="a hazard (repeatable): slide=M, tilt=RAD or tilt=DEGdeg, tip=RAD or tip=DEGdeg, strike, "
        "overload=N, swing=M, no-liftoff=S, or NAME:OBSERVABLE>THRESHOLD (or <)",
    )
    p.add_argument(
        "--design",
        action="append",
        default=[],
        metavar="PATH=VALUES",
        help="a design axis (repeatable; several make a grid): start:stop:num or v1,v2,..., e.g. "
        "boom.tip_position[0]=1:2:3",
    )
    p.add_argument("--samples", type=int, default=512, help="samples per design point")
    p.add_argument("--replicates", type=int, default=8, help="independent scrambles of the Sobol points")
    p.add_argument("--seed", type=int, default=0, help="seed of the scrambles")
    p.add_argument("--confidence", type=float, default=0.95, help="confidence level of the intervals")
    p.add_argument(
        "--max-failed",
        type=float,
        default=0.05,
        help="largest share of failed members of a design point that still gives numbers",
    )
    add_sampled_scan_options(p)
    add_out_options(
        p,
        "risk",
        "risk.nc, risk.json and risk_*.png are replaced",
        writes="risk.nc, risk.json and the maps",
        prefix="risk-",
    )
    p.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    p.add_argument("--no-plots", action="store_true", help="do not write risk_<hazard>.png")
    p.set_defaults(func=run_cli)


def _design(items: list[str]):
    if not items:
        return None
    axes = {}
    for item in items:
        path, spec = split_item(item, "--design")
        axes[path] = parse_values(spec, "--design")
    return Sweep(*next(iter(axes.items()))) if len(axes) == 1 else Grid(axes)


#: The options of `jaxhoist risk` that are keywords of the same name of `lift_risk`.
_PASSED = ("samples", "replicates", "seed", "confidence", "max_failed")

#: What `jaxhoist risk` writes into its folder (replaced when it runs there again).
_RISK_OUTPUTS = ("risk.nc", "risk.json", "risk_*.png")


def parse_uncertain(items: list[str]) -> dict:
    """The `--uncertain PATH=DIST` items -> {path: distribution}, or a `ScenarioError` naming the flag."""
    return {path: parse_distribution(spec) for path, spec in (split_item(i, "--uncertain") for i in items)}


def run_cli(args) -> int:
    scenario, out, keywords = sampled_scan_inputs(args, "risk", "risk-", _PASSED)
    uncertain = parse_uncertain(args.uncertain)
    hazards = [parse_hazard(h) for h in args.hazard]
    design = _design(args.design)
    risk = lift_risk(scenario, uncertain, hazards, design, **keywords)
    claim_out_dir(out, "risk", _RISK_OUTPUTS)
    print(f"risk          {scenario.name}: {risk.samples} samples x {int(np.prod(risk.shape))} design points")
    for p, d in risk.uncertain.items():
        print(f"uncertain     {p} ~ {d}")
    for h in risk.hazards:
        print(f"hazard        {h.name}: {h.describe()}")
    print(risk.summary())
    nc = risk.to_netcdf(out / "risk.nc")
    (out / "risk.json").write_text(json.dumps(_summary_json(risk), indent=1))
    pngs = [] if args.no_plots else save_risk_plots(risk, out)
    print(
        f"wrote         {nc}, {out / 'risk.json'}"
        + (f", {len(pngs)} PNGs (risk_<hazard>.png)" if pngs else "")
    )
    return 0 if int(np.sum(risk.n_failed)) == 0 else 1


def _summary_json(risk: LiftRisk) -> dict:
    def num(a):
        return [None if not math.isfinite(x) else x for x in np.asarray(a, dtype=float).ravel().tolist()]

    return {
        "design": {p: np.asarray(v).tolist() for p, v in risk.design_coords.items()},
        "design_mode": risk.design_mode,
        "shape": list(risk.shape),
        "uncertain": risk.uncertain,
        "samples": risk.samples,
        "replicates": risk.replicates,
        "seed": risk.seed,
        "confidence": risk.confidence,
        "n_failed": np.asarray(risk.n_failed).ravel().tolist(),
        # why members failed: every status by name, and the first failed member (values, status, reason)
        "status_counts": risk.scan.status_counts() if risk.scan is not None else None,
        "first_failure": (risk.scan.failures() or [None])[0] if risk.scan is not None else None,
        "hazards": {
            h.name: {
                "hazard": h.describe(),
                "probability": num(risk.probability(h)),
                "lower": num(risk.interval(h)[0]),
                "upper": num(risk.interval(h)[1]),
            }
            for h in risk.hazards
        },
    }


def save_risk_plots(risk: LiftRisk, out_dir: Path, dpi: int = 110) -> list[Path]:
    """`risk_<hazard>.png` per hazard: P against the design value with its interval (one design axis), or a
    colour map of P over a grid of two; nothing for other designs. Returns the paths."""
    from ..plots.trajectory import new_figure, save_figure

    if not (len(risk.design_params) == 1 or (risk.design_mode == "grid" and len(risk.design_params) == 2)):
        return []
    paths = []
    for h in risk.hazards:
        fig, axes = new_figure(figsize=(6.0, 4.2))
        ax = axes[0, 0]
        p = risk.probability(h)
        if len(risk.design_params) == 1:
            (path,) = risk.design_params
            x = risk.design_coords[path]
            lo, hi = risk.interval(h)
            order = np.argsort(x)
            ax.fill_between(
                x[order], lo[order], hi[order], alpha=0.3, label=f"{100 * risk.confidence:g} % interval"
            )
            ax.plot(x[order], p[order], "o-", label="P")
            ax.set_xlabel(f"{path} [{risk.units.get(path, '?')}]")
            ax.set_ylabel(f"P({h.describe()})")
            ax.set_ylim(-0.02, 1.02)
            ax.legend()
        else:
            px, py = risk.design_params
            mesh = ax.pcolormesh(
                risk.design_coords[py], risk.design_coords[px], p, vmin=0.0, vmax=1.0, shading="nearest"
            )
            fig.colorbar(mesh, ax=ax, label=f"P({h.describe()})")
            ax.set_xlabel(f"{py} [{risk.units.get(py, '?')}]")
            ax.set_ylabel(f"{px} [{risk.units.get(px, '?')}]")
        ax.set_title(f"{h.name}: {risk.samples} samples per point")
        safe = "".join(c if c.isalnum() or c in "-_" else "_" for c in h.name)
        paths.append(save_figure(fig, Path(out_dir) / f"risk_{safe}.png", dpi=dpi))
    return paths
