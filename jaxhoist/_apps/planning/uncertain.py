"""Uncertain inputs as objects: probability distributions over scenario leaves, and their samples by
randomised quasi-Monte Carlo (scrambled Sobol points mapped through each distribution's inverse CDF).

    import jaxhoist as jh
    uncertain = {
        "foundation.friction_coefficient": jh.Uniform(0.2, 0.4),
        "load.mass_centre[0]": jh.Normal(1.0, 0.05),
    }

A path is spelled as for `jaxhoist.scan`: dotted field names, with `[i]` for one component of a vector
leaf. Values are in the SI unit of the field. Every distribution checks its numbers on construction
(finite, std > 0, low < high) and raises `ScenarioError` naming the offending argument.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
import warnings
from collections.abc import Mapping

import numpy as np

from ..._errors import ScenarioError


def _number(kind: str, name: str, value) -> float:
    """`value` as a finite float, or a one-line `ScenarioError` naming `kind.name`."""
    try:
        x = float(value)
    except (TypeError, ValueError, OverflowError):
        raise ScenarioError(f"{kind}: {name} must be a number, got {value!r:.60}") from None
    if not math.isfinite(x):
        raise ScenarioError(f"{kind}: {name} must be finite, got {x}")
    return x


class AbstractDistribution:
    """A distribution of one scalar input [the SI unit of the leaf it is given to].

    Subclasses give `ppf(u)`, the inverse cumulative distribution function (the quantile function), which
    maps uniform numbers u in (0, 1) to samples, and `cdf(x)`.
    """

    def ppf(self, u: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def cdf(self, x) -> np.ndarray:
        raise NotImplementedError

    @property
    def is_fixed(self) -> bool:
        """True for a distribution of zero width (`Fixed`): it takes no dimension of the Sobol points."""
        return False

    def describe(self) -> str:
        """The distribution as text, e.g. `Uniform(low=0.2, high=0.4)`."""
        if not dataclasses.is_dataclass(self):
            return repr(self)
        fields = ", ".join(f"{f.name}={getattr(self, f.name)!r}" for f in dataclasses.fields(self))
        return f"{type(self).__name__}({fields})"


@dataclasses.dataclass(frozen=True)
class Fixed(AbstractDistribution):
    """A known value [SI unit of the leaf]: every sample is `value` (zero width).

    **Raises** `ScenarioError` if `value` is not a finite number.
    """

    value: float

    def __post_init__(self):
        object.__setattr__(self, "value", _number("Fixed", "value", self.value))

    @property
    def is_fixed(self) -> bool:
        return True

    def ppf(self, u):
        return np.full(np.shape(u), self.value)

    def cdf(self, x):
        return np.where(np.asarray(x, dtype=np.float64) >= self.value, 1.0, 0.0)


@dataclasses.dataclass(frozen=True)
class Uniform(AbstractDistribution):
    """Uniform on [low, high], in the SI unit of the leaf.

    **Raises** `ScenarioError` unless low and high are finite and low < high.
    """

    low: float
    high: float

    def __post_init__(self):
        low, high = _number("Uniform", "low", self.low), _number("Uniform", "high", self.high)
        if not low < high:
            raise ScenarioError(f"Uniform: low must be < high, got low = {low}, high = {high}")
        object.__setattr__(self, "low", low)
        object.__setattr__(self, "high", high)

    def ppf(self, u):
        return self.low + np.asarray(u) * (self.high - self.low)

    def cdf(self, x):
        return np.clip((np.asarray(x, dtype=np.float64) - self.low) / (self.high - self.low), 0.0, 1.0)


@dataclasses.dataclass(frozen=True)
class Normal(AbstractDistribution):
    """Normal (Gaussian) with mean `mean` and standard deviation `std` [SI unit of the leaf].

    Its tails are unbounded: for a leaf that must stay in a range (μ ≥ 0, a mass centre inside the box) use
    `TruncatedNormal`; a sample outside the leaf's valid range makes that member `INVALID_PARAMETER`.

    **Raises** `ScenarioError` unless mean and std are finite and std > 0.
    """

    mean: float
    std: float

    def __post_init__(self):
        mean, std = _number("Normal", "mean", self.mean), _number("Normal", "std", self.std)
        if not std > 0:
            raise ScenarioError(f"Normal: std must be > 0, got {std} (use Fixed(value) for a known value)")
        object.__setattr__(self, "mean", mean)
        object.__setattr__(self, "std", std)

    def ppf(self, u):
        from scipy import stats

        return stats.norm.ppf(u, loc=self.mean, scale=self.std)

    def cdf(self, x):
        from scipy import stats

        return stats.norm.cdf(x, loc=self.mean, scale=self.std)


@dataclasses.dataclass(frozen=True)
class TruncatedNormal(AbstractDistribution):
    """A normal distribution of mean `mean` and standard deviation `std` (those of the normal before
    truncation) restricted to [low, high], in the SI unit of the leaf; low = -inf or high = +inf leave that
    side open.

    **Raises** `ScenarioError` unless mean and std are finite, std > 0, low < high and the interval holds
    some probability (it lies within 30 std of the mean).
    """

    mean: float
    std: float
    low: float = -math.inf
    high: float = math.inf

    def __post_init__(self):
        kind = "TruncatedNormal"
        mean, std = _number(kind, "mean", self.mean), _number(kind, "std", self.std)
        if not std > 0:
            raise ScenarioError(f"{kind}: std must be > 0, got {std} (use Fixed(value) for a known value)")
        low, high = (float(v) if isinstance(v, float | int) else v for v in (self.low, self.high))
        if not isinstance(low, float) or math.isnan(low) or low == math.inf:
            raise ScenarioError(f"{kind}: low must be a number below +inf, got {self.low!r:.60}")
        if not isinstance(high, float) or math.isnan(high) or high == -math.inf:
            raise ScenarioError(f"{kind}: high must be a number above -inf, got {self.high!r:.60}")
        if not low < high:
            raise ScenarioError(f"{kind}: low must be < high, got low = {low}, high = {high}")
        if (low - mean) / std > 30 or (high - mean) / std < -30:
            raise ScenarioError(
                f"{kind}: [low, high] = [{low}, {high}] lies more than 30 std from the mean {mean}: it holds "
                f"no probability to speak of"
            )
        for name, v in (("mean", mean), ("std", std), ("low", low), ("high", high)):
            object.__setattr__(self, name, v)

    def _dist(self):
        from scipy import stats

        a, b = (self.low - self.mean) / self.std, (self.high - self.mean) / self.std
        return stats.truncnorm(a, b, loc=self.mean, scale=self.std)

    def ppf(self, u):
        return self._dist().ppf(u)

    def cdf(self, x):
        return self._dist().cdf(x)


@dataclasses.dataclass(frozen=True)
class LogNormal(AbstractDistribution):
    """Log-normal: ln X is normal with mean ln(`median`) and standard deviation `sigma` [-], so X > 0 has
    median `median` [SI unit of the leaf] and X/median has the spread exp(±sigma) at one standard deviation
    (sigma = 0.1: about ±10 %). Its mean is median · exp(sigma²/2).

    **Raises** `ScenarioError` unless median > 0 and sigma > 0 (both finite).
    """

    median: float
    sigma: float

    def __post_init__(self):
        median, sigma = _number("LogNormal", "median", self.median), _number("LogNormal", "sigma", self.sigma)
        if not median > 0:
            raise ScenarioError(f"LogNormal: median must be > 0, got {median}")
        if not sigma > 0:
            raise ScenarioError(
                f"LogNormal: sigma must be > 0, got {sigma} (use Fixed(value) for a known value)"
            )
        object.__setattr__(self, "median", median)
        object.__setattr__(self, "sigma", sigma)

    def ppf(self, u):
        from scipy import stats

        return stats.lognorm.ppf(u, self.sigma, scale=self.median)

    def cdf(self, x):
        from scipy import stats

        return stats.lognorm.cdf(x, self.sigma, scale=self.median)


def check_uncertain(uncertain) -> dict[str, AbstractDistribution]:
    """`uncertain` as a dict path -> distribution, or a `ScenarioError` naming the bad entry (a number is
    taken as `Fixed(number)`)."""
    if not isinstance(uncertain, Mapping) or not uncertain:
        raise ScenarioError(
            "uncertain must be a non-empty mapping of parameter path -> distribution, e.g. "
            "{'foundation.friction_coefficient': jh.Uniform(0.2, 0.4)}"
        )
    out: dict[str, AbstractDistribution] = {}
    for path, dist in uncertain.items():
        if not isinstance(path, str) or not path.strip():
            raise ScenarioError(f"uncertain: a parameter path must be a dotted name, got {path!r}")
        if isinstance(dist, numbers.Real) and not isinstance(dist, bool | np.bool_):
            try:
                dist = Fixed(float(dist))
            except ScenarioError as e:
                raise ScenarioError(f"uncertain[{path!r}]: {e}") from None
        if not isinstance(dist, AbstractDistribution):
            raise ScenarioError(
                f"uncertain[{path!r}] must be a distribution (Uniform, Normal, TruncatedNormal, LogNormal, "
                f"Fixed), got {type(dist).__name__}"
            )
        out[path] = dist
    return out


def sample(
    uncertain: Mapping[str, AbstractDistribution], n: int, replicates: int, seed: int
) -> dict[str, np.ndarray]:
    """Randomised quasi-Monte Carlo samples of the inputs: `replicates` independent scrambles of a Sobol
    sequence (`scipy.stats.qmc.Sobol`, Owen scrambling), `n // replicates` points each, mapped through each
    distribution's `ppf`; the dimensions are the non-`Fixed` inputs in the order given.

    **Returns** path -> values of shape (replicates, n // replicates), repeatable for a given `seed`.
    """
    from scipy.stats import qmc

    m = n // replicates
    random = [p for p, d in uncertain.items() if not d.is_fixed]
    rngs = np.random.default_rng(seed).spawn(replicates)
    u = np.empty((replicates, m, len(random)))
    if random:
        with warnings.catch_warnings():  # "balance properties ... power of 2": documented in lift_risk
            warnings.simplefilter("ignore", UserWarning)
            for r, rng in enumerate(rngs):
                try:  # scipy >= 1.15 names the generator `rng`
                    sobol = qmc.Sobol(len(random), scramble=True, rng=rng)
                except TypeError:  # scipy 1.13, 1.14: `seed`
                    sobol = qmc.Sobol(len(random), scramble=True, seed=rng)  # pyright: ignore[reportCallIssue]
                u[r] = sobol.random(m)
    # Sobol points may be exactly 0 (probability 2^-32 per point after scrambling): keep every u inside (0, 1)
    u = np.clip(u, 0.5 / 2**53, 1.0 - 0.5 / 2**53)
    out = {}
    for path, dist in uncertain.items():
        if dist.is_fixed:
            out[path] = np.asarray(dist.ppf(np.empty((replicates, m))), dtype=np.float64)
        else:
            out[path] = np.asarray(dist.ppf(u[..., random.index(path)]), dtype=np.float64)
    return out
