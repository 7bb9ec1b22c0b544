"""The saved times of a solve as one object: `Times(t1, n, ts)`, the one implementation of the time grid
(checks, defaults, the equally spaced grid) that every entry point reads."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Union

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import ArrayLike

from .._errors import ScenarioError

#: What `as_times` accepts: a `Times`, an end time t1 [s], the saved times ts [s], or None (the defaults).
TimesLike = Union["Times", ArrayLike, Sequence[float | int], None]


def is_tracer(x) -> bool:
    return isinstance(x, jax.core.Tracer)  # pyright: ignore[reportAttributeAccessIssue]  # jax.core is a lazily loaded submodule


def _concrete_float(x):
    return None if x is None or is_tracer(x) else float(np.asarray(x))


def check_times(t1, ts) -> None:
    """Host-side checks of the time grid (concrete values only): t1 > 0 finite; ts 1-D, at least 2 times,
    starting at 0, finite, strictly increasing; and, where both are given, ts ending at t1 (a contradiction
    is an error, never resolved silently).

    **Raises** `ScenarioError` naming `t1` or `ts`.
    """
    t1c = _concrete_float(t1)
    if t1c is not None and not (np.isfinite(t1c) and t1c > 0):
        raise ScenarioError(f"t1 must be a positive finite time [s], got {t1c}")
    if ts is not None and not is_tracer(ts):
        a = np.asarray(ts)
        if a.ndim != 1 or a.size < 2:
            raise ScenarioError(f"ts must be a 1-D array of at least 2 times [s], got shape {a.shape}")
        if not np.all(np.isfinite(a)) or a[0] != 0.0 or np.any(np.diff(a) <= 0):
            raise ScenarioError("ts must start at 0 s and be finite and strictly increasing")
        if t1c is not None and not abs(float(a[-1]) - t1c) <= 1e-12 * max(1.0, abs(t1c)):
            raise ScenarioError(
                f"t1 = {t1c:g} s contradicts ts, which ends at {float(a[-1]):g} s: give ts ending at t1, or "
                "leave t1 out (it defaults to ts[-1])"
            )


def _is_real(x) -> bool:
    """Whether `x` is a real, non-boolean number or an array of them (a tracer counts by its dtype)."""
    if isinstance(x, bool | str | bytes):
        return False
    try:
        dtype = jnp.result_type(x) if is_tracer(x) else np.asarray(x).dtype
    except (TypeError, ValueError):
        return False
    return bool(np.issubdtype(dtype, np.integer) or np.issubdtype(dtype, np.floating))


def _check_t1(t1) -> None:
    if t1 is None:
        return
    if not _is_real(t1) or np.ndim(t1) != 0:
        raise ScenarioError(f"t1 must be an end time [s] (one real number), got {t1!r}")
    check_times(t1, None)


def _check_ts(ts) -> None:
    if ts is not None and not _is_real(ts):
        raise ScenarioError(f"ts must be an array of saved times [s] (real numbers), got {ts!r}")


def _check_n(n) -> None:
    if n is None:
        return
    if isinstance(n, bool) or not isinstance(n, int | np.integer):
        raise ScenarioError(f"n (the number of saved times) must be an integer >= 2, got {n!r}")
    if int(n) < 2:
        raise ScenarioError(f"n (the number of saved times) must be >= 2, got {n}")


class Times(eqx.Module):
    """The saved times of a solve, from 0 to the end time t1.

    `Times(25.0)`: the entry point's default number of equally spaced times from 0 to 25 s;
    `Times(25.0, n=2001)`: 2001 of them; `Times(ts=ts)`: the given times; `Times()`: the defaults.

    - `t1`: the end time [s]; None: `ts[-1]` if `ts` is given, else the scenario's `t1`. A traced value
      (under `jax.jit` or `jax.grad`) stays traced.
    - `n`: the number of equally spaced saved times from 0 to t1 inclusive [-] (a static field: a change
      compiles anew); None: the entry point's default (501 for `simulate` and `simulate_rigid`, 201 for
      `scan`, `locate_bifurcation` and `trace_boundary`, 2501 for `classify_change`). Not used with `ts`.
    - `ts`: the saved times [s], 1-D, starting at 0, strictly increasing, ending at `t1` where both are
      given. Observables such as event times are interpolated on this grid.

    Entry points also take a plain number (t1 [s]) or a 1-D array (ts [s]) where they take a `Times`
    (`as_times`).

    **Raises** `ScenarioError`, before anything is compiled, for a t1 that is not a positive finite time,
    an `n` that is not an integer >= 2, `ts` that is not 1-D, does not start at 0 or is not strictly
    increasing, `ts` that does not end at `t1`, or an `n` that differs from the length of `ts`.
    """

    t1: Any = None
    n: int | None = eqx.field(default=None, static=True)
    ts: Any = None

    # Unannotated, like the parameter classes' constructors: any input reaches the checks below, which name
    # the field (`t1`: a real scalar or None; `n`: an integer or None; `ts`: a 1-D array, a sequence or None).
    def __init__(self, t1=None, n=None, ts=None):
        if isinstance(ts, list | tuple):
            ts = np.asarray(ts, dtype=np.float64) if _is_real(ts) else ts
        self.t1 = t1
        self.n = int(n) if isinstance(n, np.integer) else n
        self.ts = ts

    def __check_init__(self):
        _check_t1(self.t1)
        _check_n(self.n)
        _check_ts(self.ts)
        check_times(self.t1, self.ts)
        if self.n is not None and self.ts is not None and int(np.shape(self.ts)[0]) != self.n:
            raise ScenarioError(
                f"n = {self.n} contradicts ts, which holds {np.shape(self.ts)[0]} times: give one of them"
            )

    def resolve(self, scenario, default_n: int, xp=np) -> tuple[Any, Any]:
        """`(t1, ts)` [s] for `scenario`: `ts` as given, else `n` (or `default_n`) equally spaced times
        `linspace(0, 1, n) * t1`; t1 as given, else `ts[-1]`, else `scenario.t1`.

        **Arguments**
        - `scenario`: the `Scenario` whose `t1` [s] is the default end time.
        - `default_n`: the entry point's number of saved times when `n` is None.
        - `xp`: `numpy` or `jax.numpy`, which builds the grid: `jax.numpy` keeps a traced t1 traced.

        **Raises** `ScenarioError` for a scenario t1 that is not a positive finite time or a `default_n`
        below 2.
        """
        t1, ts = self.t1, self.ts
        if t1 is None:
            t1 = scenario.t1 if ts is None else (ts[-1] if xp is jnp else float(np.asarray(ts)[-1]))
            check_times(t1, ts)
        if ts is None:
            n = self.count(default_n)
            ts = xp.linspace(0.0, 1.0, n) * xp.asarray(t1, dtype=xp.float64)
        return t1, ts

    def count(self, default_n: int) -> int:
        """The number of saved times [-]: `len(ts)`, else `n`, else `default_n`.

        **Raises** `ScenarioError` for a `default_n` below 2 (where it is used)."""
        if self.ts is not None:
            return int(np.shape(self.ts)[0])
        n = default_n if self.n is None else self.n
        _check_n(n)
        return int(n)


def as_times(spec: Any) -> Times:
    """`spec` (a `TimesLike`; anything else is refused with a `ScenarioError`) as a `Times`: a `Times` as it
    is; None: `Times()` (the defaults); a number or a 0-d array: the end time t1 [s]; a 1-D array or
    sequence: the saved times ts [s].

    **Raises** `ScenarioError` for anything else (a string, a boolean, an array of 2 or more dimensions) or
    invalid times.
    """
    if isinstance(spec, Times):
        return spec
    if spec is None:
        return Times()
    if isinstance(spec, list | tuple):
        spec = np.asarray(spec) if _is_real(spec) else spec
    if not _is_real(spec):
        raise ScenarioError(
            "times must be a jaxhoist.Times, an end time t1 [s] or an array of saved times ts [s], "
            f"got {spec!r}"
        )
    ndim = np.ndim(spec)
    if ndim == 0:
        return Times(spec)  # pyright: ignore[reportArgumentType]  # a real scalar here (checked above)
    if ndim == 1:
        return Times(ts=spec)
    raise ScenarioError(f"times as an array must be 1-D (the saved times ts [s]), got shape {np.shape(spec)}")
