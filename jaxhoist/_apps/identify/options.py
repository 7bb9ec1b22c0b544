"""The choices of `identify` as objects: `FitOptions` (starts, Levenberg-Marquardt termination,
identifiability thresholds) and the fit's `SolverOptions`."""

from __future__ import annotations

from collections.abc import Mapping

import diffrax
import equinox as eqx
import numpy as np

from ..._errors import ScenarioError
from ..._numerics.options import SolverOptions


def _as_weights(weights):
    """A copy of a weights mapping: a later change of the caller's dict does not reach the options."""
    return dict(weights) if isinstance(weights, Mapping) else weights


class FitOptions(eqx.Module):
    """How `identify` fits: starts, the Levenberg-Marquardt termination, the identifiability thresholds and
    the weights of signals without a noise level.

    - `n_starts`, `start_spread`, `seed`: `n_starts - 1` extra starts drawn around the start (relative
      spread s [-]: θ·(1+s)^U(-1,1) for positive leaves) from `numpy.random.default_rng(seed)`; the lowest
      cost wins, all are reported in `IdentificationResult.starts`.
    - `lm_rtol`, `lm_atol`: Levenberg-Marquardt termination, the Cauchy test on the fit variables z and on
      the whitened residuals [-] (optimistix `rtol`, `atol`); the fit also stops when, after a rejected
      step, the next trial step in z is below that test's resolution (`core._LevenbergMarquardt`).
    - `max_iterations`: the step budget of each Levenberg-Marquardt run.
    - `max_relative_se`: a parameter whose standard error exceeds this fraction of its value [-] is not
      identifiable; `condition_limit`: nor are the parameters when the condition number of JᵀJ (in relative
      units) exceeds this [-].
    - `weights`: signal or group -> residual weight [1/unit of the signal] for signals without a known noise
      level (e.g. `{"position": 100.0}`: 1 cm counts as 1); signals with neither are scaled by their
      spread. Unless every fitted signal has a noise level, the covariance uses the residual variance
      estimate RSS/(n - p). Default None: no weights. (Before 0.2 an argument of `identify`.)

    **Raises** `ScenarioError` for `n_starts` or `max_iterations` below 1, a negative spread, a
    non-positive tolerance or threshold, or `weights` that is not a mapping from signal names (the weights'
    values and names are checked against the measurement by `identify`).
    """

    n_starts: int = 1
    start_spread: float = 0.3
    seed: int = 0
    lm_rtol: float = 1e-4
    lm_atol: float = 1e-6
    max_iterations: int = 100
    max_relative_se: float = 0.5
    condition_limit: float = 1e12
    weights: Mapping[str, float | int] | None = eqx.field(default=None, converter=_as_weights)

    def __check_init__(self):
        for name in ("n_starts", "max_iterations"):
            if int(getattr(self, name)) < 1:
                raise ScenarioError(f"{name} must be >= 1, got {getattr(self, name)}")
        if not (np.isfinite(self.start_spread) and self.start_spread >= 0):
            raise ScenarioError(f"start_spread must be >= 0, got {self.start_spread}")
        for name in ("lm_rtol", "lm_atol", "max_relative_se", "condition_limit"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ScenarioError(f"{name} must be a positive number, got {v}")
        if self.weights is not None and (
            not isinstance(self.weights, Mapping) or not all(isinstance(k, str) for k in self.weights)
        ):
            raise ScenarioError(
                f"weights must be a mapping from signal names to weights [1/unit], got {self.weights!r}"
            )


def fit_solver_options(options: SolverOptions | None) -> SolverOptions:
    """The fit's `SolverOptions`: default `SolverOptions(adjoint=diffrax.ForwardMode())`, the Rosenbrock-W
    solver at its defaults (rtol 5e-4, atol 1e-5, PI controller, the ∂f/∂t term), always with forward mode
    (`diffrax.ForwardMode`).

    The state and its parameter sensitivities are integrated as one system under one step-size control
    (`core._sensitivity_solve`); with `jaxhoist.RosenbrockW` its W serves every block, factorised
    once per step. It became the default on 2026-11-27: on paper-4.2
    (`python experiments/figures/identify_paper42.py
    --no-scipy --solver tsit5 --solver rosenbrock-w`, μ, k, h, c_l, b_l from 5 mm / 1 % noise) the 25 s fit
    took 20.0 s + 24.3 s compile against Tsit5's (rtol 1e-6, the default until then) 74.9 s + 15.8 s, the
    estimates within 0.018 standard errors of Tsit5's; with 10x stiffer friction W was faster still (Tsit5
    at its stability limit). It loses on short records, where the compile dominates: over 3 s 2.7 s + 32.0 s
    against 3.9 s + 16.6 s; pass `SolverOptions(diffrax.Tsit5())` there (docs/identification.md).

    **Raises** `ScenarioError` for options that are not a `SolverOptions`.
    """
    if options is None:
        return SolverOptions(adjoint=diffrax.ForwardMode())
    if not isinstance(options, SolverOptions):
        raise ScenarioError(f"options must be a jaxhoist.SolverOptions, got {type(options).__name__}")
    return options if options.forward_mode else options.replace(adjoint=diffrax.ForwardMode())
