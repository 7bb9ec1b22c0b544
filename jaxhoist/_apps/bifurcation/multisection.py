"""The multisection search of `locate_bifurcation`: each round solves k points of the bracket in one
vmapped `scan` and keeps the first sign change of the indicator."""

from __future__ import annotations

import time

import numpy as np

from ..._numerics.options import SolverOptions
from ..._numerics.times import Times
from ..scan.layout import BatchOptions
from ..scan.result import ScanResult
from ..scan.run import scan
from .eval import Problem, indicator, level_from_ends
from .options import Multisection
from .result import Bifurcation, BifurcationError


def _raise_failed(r: ScanResult, param):
    if not np.all(r.ok):
        f = r.failures()[0]
        raise BifurcationError(f"the solve at {param} = {f['params'][param]!r} failed: {f['reason']}")


def _round(p: Problem, method: Multisection, xs) -> ScanResult:
    """One round: the observable at the values `xs` [unit of the parameter], solved in one vmapped scan."""
    r = scan(
        p.scenario,
        {p.param: xs},
        observables={p.obs.name: p.obs},
        times=Times(ts=p.ts),
        options=SolverOptions(
            solver=p.options.solver,
            rtol=p.options.rtol,
            atol=p.options.atol,
            dt0=p.options.dt0,
            max_steps=p.options.max_steps,
        ),
        batch=BatchOptions(lanes=method.lanes, sort=False),
    )
    _raise_failed(r, p.param)
    return r


def _first_change(pts):
    """(a, ga, ya, b, gb, yb) of the first neighbouring pair of `pts` = [(x, g, y), ...] across which the
    indicator changes sign (or reaches 0); None where there is none."""
    for (x0, g0, y0), (x1, g1, y1) in zip(pts[:-1], pts[1:], strict=True):
        if g1 == 0.0 or np.sign(g1) != np.sign(g0):
            return x0, g0, y0, x1, g1, y1
    return None


def _report(p: Problem, rounds: int, xs, ys, gs, a, b, n_solves: int) -> None:
    if p.progress is not None:
        p.progress(
            dict(
                iteration=rounds,
                param=[float(x) for x in xs],
                value=[float(y) for y in ys],
                indicator=[float(g) for g in gs],
                kind="multisection",
                bracket=(float(a), float(b)),
                width=float(b - a),
                tol=p.tol,
                n_solves=n_solves,
                elapsed=time.perf_counter() - p.wall0,
            )
        )


def multisection(p: Problem) -> Bifurcation:
    """Each round solves `points_per_round` points in one vmapped scan and keeps the first sign change.

    Every round solves exactly k points (one compiled shape): the first round spans the bracket, ends
    included; later rounds put k points strictly inside the current bracket."""
    method = p.search.method
    assert isinstance(method, Multisection)
    k, tol, lo, hi = method.points_per_round, p.tol, p.lo, p.hi
    xs = np.linspace(lo, hi, k)
    first = _round(p, method, xs)
    ys = np.asarray(first[p.obs.name], dtype=np.float64)
    y_a, y_b = float(ys[0]), float(ys[-1])
    y_lo_end = y_a
    lev = level_from_ends(p.level, y_a, y_b)
    gs = [indicator(float(y), lev, y_lo_end) for y in ys]
    if np.sign(gs[0]) == np.sign(gs[-1]) or gs[0] == 0 or gs[-1] == 0:
        raise BifurcationError(
            f"{p.obs.name} - level has the same sign at both ends of the bracket "
            f"({lo:g}: {y_a:g}, {hi:g}: {y_b:g}, level {lev:g})",
            n_solves=k,
        )
    history = [(float(x), g, None, "multisection") for x, g in zip(xs, gs, strict=True)]
    n_solves, compile_time = k, first.attrs["timings_s"]["compile"]
    steps = int(np.sum(first.num_accepted_steps))
    change = _first_change(list(zip(xs.tolist(), gs, ys.tolist(), strict=True)))
    assert change is not None  # the ends have opposite signs
    a, ga, ya, b, gb, yb = change
    rounds = 1
    _report(p, rounds, xs, ys, gs, a, b, n_solves)
    while b - a > tol and n_solves + k <= p.search.max_solves:
        xs = a + (b - a) * np.arange(1, k + 1) / (k + 1)
        r = _round(p, method, xs)
        n_solves += k
        compile_time += r.attrs["timings_s"]["compile"]
        steps += int(np.sum(r.num_accepted_steps))
        ys = np.asarray(r[p.obs.name], dtype=np.float64)
        gs = [indicator(float(y), lev, y_lo_end) for y in ys]
        history += [(float(x), g, None, "multisection") for x, g in zip(xs, gs, strict=True)]
        pts = [(a, ga, ya)] + list(zip(xs.tolist(), gs, ys.tolist(), strict=True)) + [(b, gb, yb)]
        change = _first_change(pts)
        if change is not None:
            a, ga, ya, b, gb, yb = change
        rounds += 1
        _report(p, rounds, xs, ys, gs, a, b, n_solves)
    stats = dict(
        n_solves=n_solves,
        n_derivative_solves=0,
        history=history,
        method="multisection",
        compile_time=compile_time,
        steps=steps,
    )
    return p.result(a, b, ya, yb, lev, y_a, y_b, **stats)
