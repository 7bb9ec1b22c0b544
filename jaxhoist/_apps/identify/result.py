"""What `identify` returns: `IdentificationResult` (estimates, standard errors, correlations, the fit),
`covariance_report` (the Gauss-Newton covariance and identifiability) and `plot_fit`."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from ..._errors import SolveStatus
from ..._io.measurement import (
    SIGNALS,
)
from ..._physics.params import Scenario
from .parameters import SYMBOLS

# ------------------------------------------------------------------------------------- results


@dataclasses.dataclass(frozen=True)
class StartResult:
    """One Levenberg-Marquardt run: its start, end, cost 0.5 Σ r², iterations and outcome."""

    start: dict[str, Any]
    estimate: dict[str, Any]
    cost: float
    iterations: int
    accepted_steps: int
    converged: bool
    message: str
    wall_time: float


@dataclasses.dataclass(frozen=True)
class IdentificationResult:
    """The outcome of `identify`.

    - `names`: fitted scalar names (vector leaves expand to `path[i]`); `values`, `std_errors`: θ̂ and its
      standard errors, flat, in the leaves' SI units; `estimates`/`standard_errors`: the same by parameter.
    - `covariance`, `correlation`: Gauss-Newton covariance σ²(JᵀJ)⁻¹ at θ̂ (delta method from the fit
      variables z) and the correlation matrix, (p, p).
    - `sigma2`: the variance factor used (1 with known noise, else RSS/(n - p)); `noise_known`.
    - `chi2_reduced`: RSS/(n - p) of the whitened residuals (≈ 1 if the noise levels and the model are right).
    - `t`, `measured`, `fitted`, `residuals` (fitted - measured), `sigma`: per signal, SI units.
    - `cost`: 0.5 Σ r² of the whitened residuals; `n_residuals`.
    - `iterations`, `accepted_steps`: LM steps of the best start; `converged`, `message`.
    - `solve_status`: `SolveStatus` of the simulation at θ̂; `solver_steps`: its accepted steps.
    - `condition_number`: of the information matrix JᵀJ in relative units (Δθ/θ); `weak_direction`: the
      unit vector in relative units along which the fit changes least; `identifiable`: False if the matrix is
      near-singular or a parameter's relative standard error exceeds the limit; `warnings`: plain sentences.
    - `starts`: every LM run (several starts); `scenario`: the scenario with θ̂ set.
    - `wall_time`: the whole call [s]; `compile_time`: compiling the fit's programs, or loading them from
      the compilation cache folder (≈ 0 when compiled earlier in the process) [s]; `fit_time`: the LM
      runs [s].
    - `jacobian`: d(whitened residual)/dθ at θ̂ from the forward sensitivities, (n_residuals, p).
    """

    names: list[str]
    params: list[str]
    values: np.ndarray
    std_errors: np.ndarray
    start_values: np.ndarray
    covariance: np.ndarray
    correlation: np.ndarray
    sigma2: float
    noise_known: bool
    chi2_reduced: float
    t: np.ndarray
    measured: dict[str, np.ndarray]
    fitted: dict[str, np.ndarray]
    residuals: dict[str, np.ndarray]
    sigma: dict[str, float]
    cost: float
    n_residuals: int
    iterations: int
    accepted_steps: int
    converged: bool
    message: str
    solve_status: SolveStatus
    solver_steps: int
    condition_number: float
    weak_direction: dict[str, float]
    identifiable: bool
    warnings: list[str]
    starts: list[StartResult]
    scenario: Scenario
    wall_time: float
    compile_time: float
    fit_time: float
    jacobian: np.ndarray
    units: dict[str, str]

    @property
    def estimates(self) -> dict[str, Any]:
        return dict(zip(self.names, self.values.tolist(), strict=True))

    @property
    def standard_errors(self) -> dict[str, float]:
        return dict(zip(self.names, self.std_errors.tolist(), strict=True))

    def summary(self) -> str:
        w = max(len(n) for n in self.names) + 2
        lines = [f"{'parameter':<{w}} {'start':>12} {'estimate':>14} {'std error':>11} {'rel.':>8}  unit"]
        for i, n in enumerate(self.names):
            rel = self.std_errors[i] / abs(self.values[i]) if self.values[i] != 0 else math.inf
            lines.append(
                f"{n:<{w}} {self.start_values[i]:>12.5g} {self.values[i]:>14.8g} "
                f"{self.std_errors[i]:>11.3g} {100 * rel:>7.2g}%  {self.units.get(n, '')}"
            )
        if len(self.names) > 1:
            lines.append("correlations:")
            for i, n in enumerate(self.names):
                lines.append(f"  {n:<{w}} " + " ".join(f"{c:+.3f}" for c in self.correlation[i]))
        noise = "given noise levels (σ² = 1)" if self.noise_known else f"σ² = RSS/(n-p) = {self.sigma2:.4g}"
        lines += [
            f"fit: {self.iterations} LM iterations ({self.accepted_steps} accepted), "
            f"{'converged' if self.converged else 'NOT converged: ' + self.message}; "
            f"cost 0.5Σr² = {self.cost:.6g} over {self.n_residuals} residuals; "
            f"χ²/dof = {self.chi2_reduced:.4g}",
            f"covariance: Gauss-Newton at the optimum, {noise}; condition number of JᵀJ (relative units) "
            f"{self.condition_number:.3g}",
            f"simulation at the estimate: {self.solve_status.name.lower()}, {self.solver_steps} steps; "
            f"wall time {self.wall_time:.3g} s (compile or load {self.compile_time:.3g} s, "
            f"fit {self.fit_time:.3g} s"
            + (f" over {len(self.starts)} starts)" if len(self.starts) > 1 else ")"),
        ]
        if self.identifiable:
            lines.append("identifiable: yes")
        else:
            lines.append("identifiable: NO")
        lines += [f"warning: {w}" for w in self.warnings]
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (no arrays of the time series)."""
        return {
            "estimates": {
                n: {
                    "value": float(v),
                    "std_error": float(s),
                    "start": float(s0),
                    "unit": self.units.get(n, ""),
                }
                for n, v, s, s0 in zip(
                    self.names, self.values, self.std_errors, self.start_values, strict=True
                )
            },
            "correlation": self.correlation.tolist(),
            "covariance": self.covariance.tolist(),
            "sigma2": self.sigma2,
            "noise_known": self.noise_known,
            "chi2_reduced": self.chi2_reduced,
            "sigma": self.sigma,
            "cost": self.cost,
            "n_residuals": self.n_residuals,
            "iterations": self.iterations,
            "accepted_steps": self.accepted_steps,
            "converged": self.converged,
            "message": self.message,
            "solve_status": self.solve_status.name.lower(),
            "solver_steps": self.solver_steps,
            "condition_number": self.condition_number,
            "weak_direction": self.weak_direction,
            "identifiable": self.identifiable,
            "warnings": self.warnings,
            "rms_residuals": {k: float(np.sqrt(np.mean(v**2))) for k, v in self.residuals.items()},
            "starts": [dataclasses.asdict(s) for s in self.starts],
            "wall_time_s": self.wall_time,
            "compile_time_s": self.compile_time,
            "fit_time_s": self.fit_time,
        }


def covariance_report(
    J: np.ndarray,
    r: np.ndarray,
    theta: np.ndarray,
    names: Sequence[str],
    *,
    noise_known: bool,
    scales: np.ndarray | None = None,
    max_relative_se: float = 0.5,
    condition_limit: float = 1e12,
) -> dict[str, Any]:
    """Gauss-Newton covariance and identifiability at a least-squares optimum (host side, numpy).

    **Arguments**
    - `J`: d(whitened residual)/dθ, (n, p); `r`: the whitened residuals (n,); `theta`: θ̂ (p,); `names`.
    - `noise_known`: residuals whitened by true noise levels (σ² = 1); else σ² = RSS/(n - p).
    - `scales`: the size of a parameter that is zero at θ̂, for relative units (default 1).

    **Returns** a dict: `covariance` σ²(JᵀJ)⁻¹ (p, p), `std_errors`, `correlation`, `sigma2`,
    `chi2_reduced` = RSS/(n - p), `condition_number` of JᵀJ in relative units (columns scaled by |θ̂|),
    `weak_direction` (its least-determined unit vector, by name, largest component positive),
    `identifiable` (no relative standard error above `max_relative_se` and condition number at most
    `condition_limit`), `warnings` (a sentence naming what cannot be identified, and why). Parameters on an
    exactly singular direction get infinite standard errors.
    """
    J, r, theta = (np.asarray(x, dtype=np.float64) for x in (J, r, theta))
    n, p = J.shape
    scales = np.ones(p) if scales is None else np.asarray(scales, dtype=np.float64)
    chi2 = float(np.sum(r**2)) / max(n - p, 1)
    sigma2 = 1.0 if noise_known else chi2
    rel_scale = np.where(theta != 0, np.abs(theta), scales)
    Jn = J * rel_scale[None, :]  # sensitivity to relative changes Δθ/θ
    _, Sn, Vtn = np.linalg.svd(Jn, full_matrices=False)
    cond = float((Sn[0] / Sn[-1]) ** 2) if Sn[-1] > 0 else math.inf
    tiny = Sn <= Sn[0] * 1e-12
    inv_s2 = np.where(tiny, 0.0, 1.0 / np.where(tiny, 1.0, Sn) ** 2)
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        cov = sigma2 * ((Vtn.T * inv_s2) @ Vtn) * rel_scale[:, None] * rel_scale[None, :]
        if np.any(tiny):  # singular: parameters on a null direction have no finite error
            null = np.any(np.abs(Vtn[tiny]) > 1e-6, axis=0)
            cov[null, :] = np.inf
            cov[:, null] = np.inf
        se = np.sqrt(np.maximum(np.diag(cov), 0.0))
        corr = cov / np.outer(se, se)
    corr[~np.isfinite(corr)] = np.nan
    np.fill_diagonal(corr, 1.0)
    weak = Vtn[-1] * np.sign(Vtn[-1][np.argmax(np.abs(Vtn[-1]))])
    weak_direction = {str(k): float(c) for k, c in zip(names, weak, strict=True)}
    rel_se = se / np.where(theta != 0, np.abs(theta), 1.0)
    poorly = [k for k, e in zip(names, rel_se, strict=True) if not (e <= max_relative_se)]
    identifiable = not poorly and cond <= condition_limit
    warnings = []
    if not identifiable:
        what = (
            f"{', '.join(poorly)} (relative standard error "
            f"{', '.join(f'{100 * rel_se[list(names).index(k)]:.3g} %' for k in poorly)})"
            if poorly
            else "the parameters jointly"
        )
        if p == 1:
            info = float(Sn[0] ** 2 / sigma2) if sigma2 > 0 else math.inf
            why = (
                f"the fitted signals barely depend on it (information JᵀJ/σ² = {info:.3g} per unit relative "
                f"change Δθ/θ)"
            )
        else:
            direction = " ".join(
                f"{c:+.2f} Δ{_short(k)}/{_short(k)}" for k, c in weak_direction.items() if abs(c) >= 0.05
            )
            kind = "singular" if math.isinf(cond) else "near-singular" if cond > condition_limit else "weak"
            why = (
                f"the information matrix JᵀJ is {kind} (condition number {cond:.3g} in relative units); the "
                f"poorly determined direction is {direction} (moving along it barely changes the fit)"
            )
        warnings.append(f"the data cannot identify {what}: {why}")
    elif cond > 1e8:
        warnings.append(
            f"the information matrix is ill-conditioned (condition number {cond:.3g}); "
            f"poorly determined direction {weak_direction}"
        )
    return {
        "covariance": cov,
        "std_errors": se,
        "correlation": corr,
        "sigma2": sigma2,
        "chi2_reduced": chi2,
        "condition_number": cond,
        "weak_direction": weak_direction,
        "identifiable": identifiable,
        "warnings": warnings,
    }


def _short(name: str) -> str:
    return SYMBOLS.get(name, name)


# ------------------------------------------------------------------------------------- plotting


_DEGREES = {"rad": "deg", "rad/s": "deg/s"}  # SI angle units and how `plot_fit` shows them


def plot_fit(result: IdentificationResult, *, max_signals: int = 12, title: str | None = None):
    """Measured (dots) against fitted (line) signals, one panel per signal, in SI units except angles
    (Euler angles in deg, angular velocities in deg/s); returns a matplotlib Figure."""
    from matplotlib.figure import Figure

    names = list(result.measured)[:max_signals]
    ncols = 1 if len(names) < 4 else 2
    nrows = math.ceil(len(names) / ncols)
    fig = Figure(figsize=(7.0 * ncols, 2.2 * nrows + 0.6), layout="constrained")
    axes = np.atleast_1d(fig.subplots(nrows, ncols, sharex=True, squeeze=False)).ravel()
    for ax, n in zip(axes, names, strict=False):
        unit = SIGNALS[n].unit
        k = 1.0
        if unit in _DEGREES:  # angles in degrees, as in every other plot
            unit, k = _DEGREES[unit], 180.0 / math.pi
        ax.plot(result.t, k * result.measured[n], ".", ms=2.5, color="0.45", label="measured")
        ax.plot(result.t, k * result.fitted[n], "-", lw=1.2, color="tab:red", label="fitted")
        ax.set_ylabel(f"{n} [{unit}]")
        ax.grid(alpha=0.3)
    for ax in axes[len(names) :]:
        ax.set_visible(False)
    for ax in axes[max(0, len(names) - ncols) : len(names)]:
        ax.set_xlabel("t [s]")
    axes[0].legend(loc="best", fontsize=8)
    est = ", ".join(
        f"{_short(n)} = {v:.5g} ± {s:.2g}"
        for n, v, s in zip(result.names, result.values, result.std_errors, strict=True)
    )
    fig.suptitle(title or f"measured vs fitted: {est}", fontsize=9)
    return fig
