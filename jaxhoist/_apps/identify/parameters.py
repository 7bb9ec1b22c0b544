"""Fitted parameters of `identify`: short names, the reparameterisation that keeps positivity and bounds
(log, scaled logit, affine), the flat vector z the optimiser sees, random starts, and the noise levels and
weights that whiten the residuals."""

from __future__ import annotations

import dataclasses
import difflib
from collections.abc import Mapping, Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from ..._errors import ScenarioError
from ..._io.measurement import Measurement, MeasurementError, check_signal_names, signal_groups
from ..._physics.params import Scenario
from ..._physics.paths import get_leaf, parse_path

ALIASES: dict[str, str] = {
    "mu": "foundation.friction_coefficient",
    "k": "foundation.stiffness",
    "h": "foundation.damping",
    "c_l": "rope.stiffness",
    "b_l": "rope.damping",
}
"""Short names accepted for `params` (and by the CLI's `--fit`)."""

SYMBOLS: dict[str, str] = {v: k for k, v in ALIASES.items()}

# Leaves (by last path component) that are positive by nature: fitted as θ = θ_ref exp(z).
_POSITIVE = {
    "stiffness",
    "damping",
    "friction_coefficient",
    "mass",
    "tip_mass",
    "size",
    "speed",
    "gravity",
    "regularisation_velocity",
    "deflection",
    "relaxation_time",
    "ramp_time",
}


# ------------------------------------------------------------------------------------- parameters


@dataclasses.dataclass(frozen=True)
class Param:
    """One fitted leaf (or one element of a vector leaf, `path[i]`)."""

    name: str  # as reported: "foundation.stiffness", "load.mass_centre[1]"
    path: str  # dotted leaf path
    index: int | None  # element of a vector leaf, or None for the whole leaf
    shape: tuple[int, ...]  # shape of the fitted value
    kind: str  # "log" | "logit" | "affine"
    ref: np.ndarray  # θ_ref (log, affine) [unit of the leaf]
    lo: np.ndarray  # lower bound (logit)
    hi: np.ndarray  # upper bound (logit)
    scale: np.ndarray  # affine scale

    @property
    def size(self) -> int:
        return int(np.prod(self.shape, dtype=int))

    def element_names(self) -> list[str]:
        if self.shape == ():
            return [self.name]
        return [f"{self.name}[{i}]" for i in range(self.size)]

    def to_z(self, theta: np.ndarray) -> np.ndarray:
        theta = np.asarray(theta, dtype=np.float64)
        if self.kind == "log":
            return np.asarray(np.log(theta / self.ref))
        if self.kind == "logit":
            u = (theta - self.lo) / (self.hi - self.lo)
            return np.asarray(np.log(u) - np.log1p(-u))
        return np.asarray((theta - self.ref) / self.scale)


def to_theta(kind: str, z, ref, lo, hi, scale):
    if kind == "log":
        return ref * jnp.exp(z)
    if kind == "logit":
        return lo + (hi - lo) * jax.nn.sigmoid(z)
    return ref + scale * z


def _dtheta_dz(kind: str, z, ref, lo, hi, scale):
    if kind == "log":
        return ref * np.exp(z)
    if kind == "logit":
        s = 1.0 / (1.0 + np.exp(-z))
        return (hi - lo) * s * (1 - s)
    return scale * np.ones_like(z)


def resolve_param(name: str) -> tuple[str, int | None]:
    """`"mu"` -> (`"foundation.friction_coefficient"`, None); `"load.mass_centre[1]"` -> (path, 1)."""
    name = name.strip()
    try:
        base, index = parse_path(name)
    except ScenarioError:  # not a path: `_leaf` says so, with the short names
        base, index = name, None
    return ALIASES.get(base, base), index


def _leaf(scenario: Scenario, path: str, given: str) -> np.ndarray:
    if "." not in path and path not in ("gravity",):
        hint = difflib.get_close_matches(path, list(ALIASES), n=1, cutoff=0.5)
        raise ScenarioError(
            f"parameter {given!r} is neither a short name ({', '.join(ALIASES)}) nor a dotted leaf path such "
            f"as 'foundation.stiffness'" + (f" (did you mean {hint[0]!r}?)" if hint else "")
        )
    leaf = get_leaf(scenario, path)
    if not isinstance(leaf, jax.Array | np.ndarray):
        raise ScenarioError(
            f"parameter {given!r}: {path} is not an array leaf of the scenario and cannot be fitted"
        )
    return np.asarray(leaf, dtype=np.float64)


def _default_bounds(scenario: Scenario, path: str) -> tuple[np.ndarray, np.ndarray] | None:
    if path == "load.mass_centre":
        size = np.asarray(scenario.load.size)
        return np.zeros(3), size
    if path == "foundation.friction.breakaway_ratio":
        return np.zeros(()), np.ones(())
    return None


def build_params(
    scenario: Scenario,
    params: Sequence[str],
    start: Mapping[str, Any],
    bounds: Mapping[str, tuple[float, float]],
) -> tuple[list[Param], np.ndarray]:
    """Check the parameter list on the host; return the parameter specs and the flat start θ0."""
    if isinstance(params, str):
        params = [p for p in params.split(",") if p.strip()]
    if not params:
        raise ScenarioError("identify: give at least one parameter to fit (params=[...])")
    resolved = [resolve_param(p) for p in params]
    seen: dict[tuple[str, int | None], str] = {}
    for given, key in zip(params, resolved, strict=True):
        if key in seen or (key[0], None) in seen or (key[1] is None and any(k[0] == key[0] for k in seen)):
            raise ScenarioError(f"parameter {given!r} is listed twice (as {seen.get(key, key[0])!r})")
        seen[key] = given
    start_r = {resolve_param(k): v for k, v in (start or {}).items()}
    for k, given in zip(start_r, (start or {}), strict=True):
        if k not in resolved:
            raise ScenarioError(
                f"start value given for {given!r}, which is not a fitted parameter ({', '.join(params)})"
            )
    bounds_r = {resolve_param(k): v for k, v in (bounds or {}).items()}
    for k, given in zip(bounds_r, (bounds or {}), strict=True):
        if k not in resolved:
            raise ScenarioError(
                f"bounds given for {given!r}, which is not a fitted parameter ({', '.join(params)})"
            )
    out, theta0 = [], []
    for given, (path, index) in zip(params, resolved, strict=True):
        leaf = _leaf(scenario, path, given)
        if index is not None:
            if leaf.ndim != 1 or not 0 <= index < leaf.shape[0]:
                raise ScenarioError(
                    f"parameter {given!r}: {path} has shape {leaf.shape}, index {index} is out of range"
                )
            value = np.asarray(leaf[index])
        else:
            value = leaf
        name = path if index is None else f"{path}[{index}]"
        if (path, index) in start_r:
            try:
                v = np.asarray(start_r[(path, index)], dtype=np.float64)
                value = np.broadcast_to(v, value.shape).copy()
            except (ValueError, TypeError):
                raise ScenarioError(
                    f"start value of {name} must be a number or array of shape {value.shape}, "
                    f"got {start_r[(path, index)]!r}"
                ) from None
        if not np.all(np.isfinite(value)):
            raise ScenarioError(f"start value of {name} must be finite, got {value.tolist()}")
        b = bounds_r.get((path, index))
        if b is None:
            b = _default_bounds(scenario, path)
            if b is not None and index is not None:
                b = (b[0][index], b[1][index])
        if b is not None:
            try:
                lo, hi = (np.broadcast_to(np.asarray(x, dtype=np.float64), value.shape).copy() for x in b)
            except (ValueError, TypeError):
                raise ScenarioError(f"bounds of {name} must be (low, high), got {b!r}") from None
            if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and np.all(lo < hi)):
                raise ScenarioError(f"bounds of {name} must be finite with low < high, got {b!r}")
            if np.any(value <= lo) or np.any(value >= hi):
                raise ScenarioError(
                    f"start value of {name} = {value.tolist()} must lie strictly inside its "
                    f"bounds ({lo.tolist()}, {hi.tolist()})"
                )
            kind, ref, scale = "logit", np.zeros_like(value), np.ones_like(value)
        elif path.rsplit(".", 1)[-1] in _POSITIVE:
            if np.any(value <= 0):
                raise ScenarioError(
                    f"{name} is fitted on a log scale (it is positive by nature) and needs a "
                    f"start value > 0, got {value.tolist()}; give start={{{name!r}: ...}}"
                )
            kind, ref, scale, lo, hi = (
                "log",
                value.copy(),
                np.ones_like(value),
                np.zeros_like(value),
                np.zeros_like(value),
            )
        else:
            scale = np.asarray(np.where(np.abs(value) > 0, np.abs(value), 1.0))
            kind, ref, lo, hi = "affine", value.copy(), np.zeros_like(value), np.zeros_like(value)
        out.append(Param(name, path, index, value.shape, kind, ref, lo, hi, scale))
        theta0.append(value.ravel())
    return out, np.concatenate(theta0)


def unflatten(params: list[Param], flat: np.ndarray) -> dict[str, np.ndarray | float]:
    out, i = {}, 0
    for p in params:
        v = flat[i : i + p.size].reshape(p.shape)
        out[p.name] = float(v) if p.shape == () else v.copy()
        i += p.size
    return out


def flat_z(params: list[Param], theta: np.ndarray) -> np.ndarray:
    out, i = [], 0
    for p in params:
        out.append(p.to_z(theta[i : i + p.size].reshape(p.shape)).ravel())
        i += p.size
    return np.concatenate(out)


def _per_param(params: list[Param], z: np.ndarray, f) -> np.ndarray:
    """`f(kind, z_p, ref, lo, hi, scale)` on each parameter's segment `z_p` of the flat `z`, flattened."""
    out, i = [], 0
    for p in params:
        seg = z[i : i + p.size].reshape(p.shape)
        out.append(np.asarray(f(p.kind, seg, p.ref, p.lo, p.hi, p.scale)).ravel())
        i += p.size
    return np.concatenate(out)


def flat_dtheta_dz(params: list[Param], z: np.ndarray) -> np.ndarray:
    return _per_param(params, z, _dtheta_dz)


def apply_params(scenario: Scenario, values: Mapping[str, Any]) -> Scenario:
    """A copy of `scenario` with fitted values set (names as in `IdentificationResult.estimates`, aliases
    and `path[i]` allowed)."""
    out = scenario
    for name, v in values.items():
        path, index = resolve_param(name)
        if index is None:
            out = out.replace(**{path: v})
        else:
            leaf = jnp.asarray(get_leaf(out, path))
            out = out.replace(**{path: leaf.at[index].set(v)})
    return out


def theta_of(plist: list[Param], z: np.ndarray) -> np.ndarray:
    return _per_param(plist, z, to_theta).astype(np.float64)


def random_starts(
    plist: list[Param], theta0: np.ndarray, n: int, spread: float, seed: int
) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        parts, i = [], 0
        for p in plist:
            v = theta0[i : i + p.size]
            u = rng.uniform(-1.0, 1.0, size=v.shape)
            if p.kind == "log":
                w = v * (1.0 + spread) ** u
            elif p.kind == "logit":
                lo, hi = p.lo.ravel(), p.hi.ravel()
                w = np.clip(v * (1.0 + spread) ** u, lo + 1e-3 * (hi - lo), hi - 1e-3 * (hi - lo))
            else:
                w = v + spread * p.scale.ravel() * u
            parts.append(w)
            i += p.size
        out.append(np.concatenate(parts))
    return out


# ------------------------------------------------------------------------------------- noise/weights


def spec_value(raw, name: str, y: np.ndarray, what: str) -> float:
    if isinstance(raw, str) and raw.strip().endswith("%"):
        try:
            pct = float(raw.strip()[:-1])
        except ValueError:
            raise ScenarioError(f"{what} of {name!r} must be a number or 'x%', got {raw!r}") from None
        rms = float(np.sqrt(np.mean(y**2)))
        value = pct / 100.0 * rms
    else:
        try:
            value = float(raw)
        except (TypeError, ValueError):
            raise ScenarioError(
                f"{what} of {name!r} must be a positive number (or 'x%' for noise), got {raw!r}"
            ) from None
    if not (np.isfinite(value) and value > 0):
        raise ScenarioError(f"{what} of {name!r} must be positive, got {raw!r}")
    return value


def expand(spec: Mapping[str, Any] | None, names: list[str], what: str) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, raw in (spec or {}).items():
        check_signal_names([key], what, groups=True)
        hits = [s for s in signal_groups(key) if s in names]
        if not hits:
            raise MeasurementError(f"{what}: {key!r} names no fitted signal (fitted: {names})")
        for s in hits:
            out[s] = raw
    return out


def sigmas(m: Measurement, noise, weights) -> tuple[dict[str, float], bool, list[str]]:
    names = m.names
    noise_e = expand(noise, names, "noise")
    weight_e = expand(weights, names, "weights")
    both = sorted(set(noise_e) & set(weight_e))
    if both:
        raise ScenarioError(f"give a noise level or a weight for a signal, not both: {both}")
    sig, warn = {}, []
    for s in names:
        y = m.signals[s]
        if s in noise_e:
            sig[s] = spec_value(noise_e[s], s, y, "noise")
        elif s in weight_e:
            sig[s] = 1.0 / spec_value(weight_e[s], s, y, "weight")
        elif s in m.noise:
            sig[s] = m.noise[s]
        else:
            spread = float(np.std(y))
            sig[s] = spread if spread > 0 else (float(np.sqrt(np.mean(y**2))) or 1.0)
    unknown = [s for s in names if s not in noise_e and s not in m.noise]
    if unknown:
        warn.append(
            f"no noise level for {', '.join(unknown)}: "
            + (
                "residuals weighted by the given weights"
                if weight_e
                else "each such signal is scaled by its spread (standard deviation over time)"
            )
            + "; the covariance uses the residual variance estimate RSS/(n - p)"
        )
    return sig, not unknown, warn
