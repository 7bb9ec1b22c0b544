"""Statics of the load resting flat on the rigid ground (paper §2.1, eqs. 2.1-2.9).

The load stands on its bottom face with its body axes ξηζ parallel to the world axes XYZ (yaw ψ = 0), so
body coordinates measured from corner D are also world coordinates measured from D. A rope force S
(a vector, in these axes) acts at the rope point B; the weight G = m g acts at the mass centre C.

What this module gives:

- `rest_statics(scenario, S)`: the corner reactions N_i of the linear law (2.3)/(2.8), the resultant
  N = G - S_z, the point R = (x_R, y_R) where N acts, the friction resultant T = |(S_x, S_y)| and its
  moment M_T about R, the paper's equilibrium conditions (2.9) as signed margins, and the exact corner
  friction utilisation ρ* (see below).
- `thresholds(scenario, direction)`: for a fixed rope direction, the rope-force magnitudes |S| at which each
  condition of (2.9) first fails ("lift", "slide", "twist", "tip"), in closed form where one exists
  (lift, slide, tip) and by 1-D root finding otherwise (twist, and the exact "slip").
- `first_failure(scenario, S)`: which condition fails first as the pull grows along the direction of S.

The paper's conditions (2.9), with the names used here:

- "lift":  N > 0;
- "slide": T < μ N (the resultant friction within the friction disc);
- "twist": |M_T| < max_i |T_x (y_i - y_R) - T_y (x_i - x_R)|, i = D, E, F, H (the line of action of the
  resultant friction crosses the contact rectangle);
- "tip-edge" / "tip-corner": 0 < x_R < a and 0 < y_R < b; R leaves through an edge (tipping about that
  edge) or, if both coordinates leave at the same pull, through a corner (tipping about the corner).

"slide" and "twist" together are necessary, not sufficient, for the corner friction forces to satisfy
(2.4), |T_i| <= μ N_i, with the corner loads of (2.3): a rope force off the friction centre also has to be
resisted by a moment, and the corner discs cannot give the full μN and a moment at once. The exact test
is the *friction utilisation*

    ρ* = min { ρ : there are T_i with |T_i| <= ρ μ N_i,  Σ T_i = -S_h,  Σ r_i × T_i = -M_S },

(the load rests iff ρ* <= 1), computed from its dual: ρ* is the largest ratio, over rigid planar
velocity fields (twists), of the power of the applied horizontal load to the friction power
Σ μ N_i |v_i| (see `friction_utilisation`). Its threshold is reported as "slip".
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._typing import PerCorner, Scalar, Vec3
from . import kinematics
from .equilibrium import linear_corner_loads
from .params import Scenario

#: Names of the paper's equilibrium conditions (2.9), in the order they are reported.
CONDITIONS = ("lift", "slide", "twist", "tip")

# The twist direction w with Σ w_i = Σ w_i x_i = Σ w_i y_i = 0 over the rectangle's corners D, E, F, H:
# adding t w to the corner loads changes neither the resultant nor its moments (the 4-point indeterminacy).
_W = np.array([1.0, -1.0, 1.0, -1.0])


# ------------------------------------------------------------------------------------ corner loads


def nonnegative_corner_loads(loads: PerCorner) -> tuple[PerCorner, Scalar]:
    """The corner loads closest to `loads` (the minimum-norm / linear-law ones, 2.3) among the statically
    equivalent ones that are all >= 0, and the feasibility margin [N].

    Four coplanar corners are statically indeterminate: N + t w, w = (1, -1, 1, -1), carries the same
    resultant and moments for every t. Outside the central diamond |x_R/a - ½| + |y_R/b - ½| <= ½ the linear
    law gives a negative corner load although the load can still rest; the nonnegative loads of least norm
    move t to the nearest end of the interval where N + t w >= 0.

    **Returns** `(loads >= 0, margin)`, margin = (min(N_D, N_F) + min(N_E, N_H)) / 2
    = N/4 (1 - 2 max(|u|, |v|)) with u = x_R/a - ½, v = y_R/b - ½: >= 0 iff R lies in the rectangle.
    """
    lo = jnp.maximum(-loads[0], -loads[2])
    hi = jnp.minimum(loads[1], loads[3])
    t = jnp.where(lo <= hi, jnp.clip(0.0, lo, hi), 0.5 * (lo + hi))
    return loads + t * jnp.asarray(_W), 0.5 * (hi - lo)


# ------------------------------------------------------------------------------ friction utilisation


def _fibonacci_sphere(n: int) -> np.ndarray:
    i = np.arange(n) + 0.5
    z = 1.0 - 2.0 * i / n
    r = np.sqrt(1.0 - z**2)
    phi = np.pi * (3.0 - np.sqrt(5.0)) * i
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


_SPHERE = _fibonacci_sphere(1500)


def _twist_ratio(u, force_h, moment, points, loads, mu, length):
    """(power of the load) / (friction power) for the twist u = (v_x, v_y, ω L) (any scale)."""
    v, w = u[:2], u[2] / length
    vel = v[None, :] + w * jnp.stack([-points[:, 1], points[:, 0]], axis=1)
    speed = jnp.sqrt(jnp.sum(vel**2, axis=1) + (1e-30 * length) ** 2)
    num = jnp.dot(force_h, v) + moment * w
    den = mu * jnp.sum(loads * speed)
    return num / jnp.maximum(den, 1e-300)


def friction_utilisation(
    force_h: Float[Array, "2"],
    moment: Scalar,
    points: Float[Array, "4 2"],
    loads: PerCorner,
    mu: Scalar,
    length: Scalar | float = 1.0,
    newton_iterations: int = 25,
):
    """Exact friction utilisation ρ* of four point contacts with loads N_i >= 0, and the onset twist.

    The friction forces T_i (|T_i| <= μ N_i) must balance a horizontal load: force `force_h` = F [N] and
    moment `moment` = M [N m] about the origin of `points`. Their attainable set is the limit surface whose
    support function is the friction power h(v, ω) = Σ μ N_i |v + ω k × r_i|, so

        ρ* = max over twists (v, ω) of (F·v + M ω) / h(v, ω),

    the load rests iff ρ* <= 1, and the maximising twist is the rigid planar motion in which slipping
    starts. The maximum is searched on a 1500-point grid of twist directions (v_x, v_y, ω L) plus the four
    pivots about the corners (where h has kinks), then refined by a safeguarded Newton iteration in the
    tangent plane of the best point; the ratio is quasi-concave (its super-level sets are convex cones), so
    the local maximum found is the global one.

    **Arguments**: `points` r_i [m] (4, 2); `loads` N_i [N] (>= 0); `mu` μ [-]; `length` [m] scales ω so that
    the twist grid is even (use a size of the contact area).

    **Returns** `(rho, twist)`: ρ* [-] and the maximising twist (v_x, v_y, ω L), unit norm. With no load
    on the ground (Σ N_i = 0) and a nonzero load, ρ* is huge (1e300 scale).
    """
    f = lambda u: _twist_ratio(u, force_h, moment, points, loads, mu, length)  # noqa: E731
    pivots = jnp.stack([points[:, 1], -points[:, 0], jnp.full(4, length)], axis=1)
    pivots = pivots / jnp.linalg.norm(pivots, axis=1, keepdims=True)
    cands = jnp.concatenate([jnp.asarray(_SPHERE), pivots, -pivots], axis=0)
    vals = jax.vmap(f)(cands)
    k = jnp.argmax(vals)
    u0, best0 = cands[k], vals[k]

    # Tangent basis at u0; refine in (α, β) with u(α, β) = normalise(u0 + α e1 + β e2).
    a = jnp.where(jnp.abs(u0[0]) < 0.9, jnp.array([1.0, 0.0, 0.0]), jnp.array([0.0, 1.0, 0.0]))
    e1 = jnp.cross(u0, a)
    e1 = e1 / jnp.linalg.norm(e1)
    e2 = jnp.cross(u0, e1)

    def g(ab):
        u = u0 + ab[0] * e1 + ab[1] * e2
        return f(u / jnp.linalg.norm(u))

    grad, hess = jax.grad(g), jax.hessian(g)

    def step(_, carry):
        ab, best = carry
        gr, H = grad(ab), hess(ab)
        # Newton if H is negative definite, else a gradient step of a size set by the local curvature.
        neg_def = (H[0, 0] < 0) & (jnp.linalg.det(H) > 0)
        d_newton = -jnp.linalg.solve(jnp.where(neg_def, H, -jnp.eye(2)), gr)
        d = jnp.where(neg_def, d_newton, 0.05 * gr / (jnp.linalg.norm(gr) + 1e-300))
        d = d * jnp.minimum(1.0, 0.5 / (jnp.linalg.norm(d) + 1e-300))  # trust region of half a radian

        def try_scale(s):
            return g(ab + s * d)

        scales = 0.5 ** jnp.arange(8.0)
        trial = jax.vmap(try_scale)(scales)
        j = jnp.argmax(trial)
        ok = trial[j] > best
        return jnp.where(ok, ab + scales[j] * d, ab), jnp.where(ok, trial[j], best)

    ab, best = jax.lax.fori_loop(0, newton_iterations, step, (jnp.zeros(2), best0))
    u = u0 + ab[0] * e1 + ab[1] * e2
    return best, u / jnp.linalg.norm(u)


# ------------------------------------------------------------------------------------- rest statics


def rest_statics_loads(scenario: Scenario, rope_force: Vec3) -> PerCorner:
    """Only the nonnegative corner loads of `rest_statics` [N] (cheap: no friction utilisation)."""
    load = scenario.load
    N_i = linear_corner_loads(
        load.size, load.mass_centre, load.mass * scenario.gravity, rope_force, scenario.rope.attachment
    )
    return nonnegative_corner_loads(N_i)[0]


class RestStatics(eqx.Module):
    """Static quantities of the load resting flat under a rope force S (paper §2.1). Forces [N], lengths [m].

    - `corner_loads`: N_D, N_E, N_F, N_H of the linear law (2.3)/(2.8) (the minimum-norm solution; a
      negative entry means that (2.3) is not a valid distribution, see `nonnegative_corner_loads`).
    - `nonnegative_loads`: the least-norm corner loads >= 0 with the same resultant (equal to
      `corner_loads` when those are >= 0).
    - `normal`: N = G - S_z; `reaction_point`: R = (x_R, y_R) from D, where N acts.
    - `friction_vector`: (T_x, T_y) = -(S_x, S_y), the resultant ground friction;
      `friction`: T = |(T_x, T_y)|.
    - `friction_moment`: M_T, moment of the corner friction forces about the vertical through R [N m]
      (counter-clockwise positive seen from above), eq. (2.6).
    - `twist_limit`: max_i |T_x (y_i - y_R) - T_y (x_i - x_R)| [N m], the bound in (2.9).
    - `friction_utilisation`: ρ* of `friction_utilisation` with the `nonnegative_loads` [-].
    - `margins`: the conditions (2.9) as numbers that are > 0 when the condition holds, in `CONDITIONS`
      order: N/G, (μN - T)/G, (limit - |M_T|)/(G L), min(x_R, a - x_R, y_R, b - y_R)/L with L = (a + b)/2.
    """

    corner_loads: PerCorner
    nonnegative_loads: PerCorner
    normal: Scalar
    reaction_point: Float[Array, "2"]
    friction_vector: Float[Array, "2"]
    friction: Scalar
    friction_moment: Scalar
    twist_limit: Scalar
    friction_utilisation: Scalar
    margins: Float[Array, "4"]

    def holds(self) -> dict[str, bool]:
        """Condition name -> True where it holds (host side, concrete values)."""
        m = np.asarray(self.margins)
        return {name: bool(m[i] > 0) for i, name in enumerate(CONDITIONS)}


def _geometry(scenario: Scenario, attachment, mass_centre):
    load = scenario.load
    B = scenario.rope.attachment if attachment is None else jnp.asarray(attachment, dtype=jnp.float64)
    C = load.mass_centre if mass_centre is None else jnp.asarray(mass_centre, dtype=jnp.float64)
    return load.size, B, C, load.mass * scenario.gravity


def rest_statics(
    scenario: Scenario, rope_force: Vec3, *, attachment: Vec3 | None = None, mass_centre: Vec3 | None = None
) -> RestStatics:
    """Statics of the flat, unrotated load under the rope force `rope_force` S [N] at B (paper 2.3-2.9).

    Pure JAX (jit/vmap/grad-friendly). `attachment` B and `mass_centre` C default to the scenario's [m].
    """
    size, B, C, G = _geometry(scenario, attachment, mass_centre)
    mu = scenario.foundation.friction_coefficient
    S = jnp.asarray(rope_force, dtype=jnp.float64)
    a, b = size[0], size[1]
    N_i = linear_corner_loads(size, C, G, S, B)  # eq. (2.8)
    N = G - S[2]
    # Moments about the horizontal axes through D (the rows of linear_corner_loads): N x_R and N y_R.
    Nx = G * C[0] + B[2] * S[0] - B[0] * S[2]
    Ny = G * C[1] + B[2] * S[1] - B[1] * S[2]
    Nsafe = jnp.where(N > 0, N, 1.0)
    xR = jnp.where(N > 0, Nx / Nsafe, jnp.nan)
    yR = jnp.where(N > 0, Ny / Nsafe, jnp.nan)
    Tv = -S[:2]
    T = jnp.sqrt(jnp.sum(Tv**2))
    # Moment balance about the vertical through R: the friction moment cancels the rope's horizontal force
    # acting at (x_B, y_B): M_T + (x_B - x_R) S_y - (y_B - y_R) S_x = 0.
    M_T = (B[1] - yR) * S[0] - (B[0] - xR) * S[1]
    xy = kinematics.bottom_corners(size)[:, :2]
    limit = jnp.max(jnp.abs(Tv[0] * (xy[:, 1] - yR) - Tv[1] * (xy[:, 0] - xR)))
    nn, _ = nonnegative_corner_loads(N_i)
    rho, _ = friction_utilisation(
        S[:2], B[0] * S[1] - B[1] * S[0], xy, jnp.maximum(nn, 0.0), mu, 0.5 * (a + b)
    )
    L = 0.5 * (a + b)
    margins = jnp.stack(
        [
            N / G,
            (mu * N - T) / G,
            (limit - jnp.abs(M_T)) / (G * L),
            jnp.minimum(jnp.minimum(xR, a - xR), jnp.minimum(yR, b - yR)) / L,
        ]
    )
    margins = jnp.where(N > 0, margins, jnp.where(jnp.arange(4) == 0, margins, -jnp.inf))
    return RestStatics(
        corner_loads=N_i,
        nonnegative_loads=nn,
        normal=N,
        reaction_point=jnp.stack([xR, yR]),
        friction_vector=Tv,
        friction=T,
        friction_moment=M_T,
        twist_limit=limit,
        friction_utilisation=rho,
        margins=margins,
    )


#: `rest_statics` compiled once per scenario structure (for repeated host-side calls).
rest_statics_jit = eqx.filter_jit(rest_statics)


# ------------------------------------------------------------------------------------- thresholds


def _unit(direction) -> np.ndarray:
    e = np.asarray(direction, dtype=np.float64)
    n = np.linalg.norm(e)
    if e.shape != (3,) or not np.isfinite(n) or n == 0.0:
        raise ValueError(f"direction must be a nonzero finite 3-vector, got {e.tolist()}")
    return e / n


def _host(scenario, attachment, mass_centre):
    size, B, C, G = _geometry(scenario, attachment, mass_centre)
    mu = float(np.asarray(scenario.foundation.friction_coefficient))
    return np.asarray(size), np.asarray(B), np.asarray(C), float(np.asarray(G)), mu


def lift_threshold(scenario: Scenario, direction, *, attachment=None, mass_centre=None) -> float:
    """|S| [N] at which N = G - S_z reaches 0 for a pull along `direction`: G / e_z (inf if e_z <= 0)."""
    e = _unit(direction)
    _, _, _, G, _ = _host(scenario, attachment, mass_centre)
    return G / e[2] if e[2] > 0 else math.inf


def slide_threshold(scenario: Scenario, direction, *, attachment=None, mass_centre=None) -> float:
    """|S| [N] at which T = μN for a pull along unit e: T = s h, N = G - s e_z, h = |(e_x, e_y)|, so

    s = μ G / (h + μ e_z)   (inf if h + μ e_z <= 0 or h = 0, i.e. a vertical pull never slides).
    """
    e = _unit(direction)
    _, _, _, G, mu = _host(scenario, attachment, mass_centre)
    h = math.hypot(e[0], e[1])
    d = h + mu * e[2]
    return mu * G / d if (h > 0 and d > 0) else math.inf


def tip_threshold(
    scenario: Scenario, direction, *, attachment=None, mass_centre=None, corner_tol: float = 1e-9
) -> tuple[float, str, tuple[str, ...]]:
    """|S| [N] at which R leaves the rectangle, for a pull along unit e, in closed form.

    N x_R = G x_C + s (z_B e_x - x_B e_z) and N = G - s e_z, so x_R = 0 at s = -G x_C / (z_B e_x - x_B e_z)
    and x_R = a at s = G (a - x_C) / (z_B e_x - (x_B - a) e_z); likewise in y. The smallest positive s
    below the lift threshold is the tipping pull.

    **Returns** `(s, kind, edges)`: kind "tip-edge" or "tip-corner" (two edges reached at the same s,
    relative `corner_tol`), edges named by their corners ("DH" for x = 0, "EF" for x = a, "DE" for y = 0,
    "FH" for y = b). `(inf, "", ())` if R never leaves the rectangle before the load lifts.
    """
    e = _unit(direction)
    size, B, C, G, _ = _host(scenario, attachment, mass_centre)
    s_lift = G / e[2] if e[2] > 0 else math.inf
    cands = []
    for k, (lo_name, hi_name) in enumerate((("DH", "EF"), ("DE", "FH"))):
        lever = B[2] * e[k] - B[k] * e[2]  # d(N x_R)/ds
        for bound, name in ((0.0, lo_name), (size[k], hi_name)):
            den = lever + bound * e[2]  # d(N x_R - bound N)/ds
            num = G * (bound - C[k])
            if den != 0.0:
                s = num / den
                if 0.0 < s < s_lift:
                    cands.append((s, name))
    if not cands:
        return math.inf, "", ()
    cands.sort()
    s0 = cands[0][0]
    edges = tuple(n for s, n in cands if abs(s - s0) <= corner_tol * s0)
    return s0, ("tip-corner" if len(edges) > 1 else "tip-edge"), edges


def _first_root(fn, s_max: float, n_grid: int = 400) -> float:
    """Smallest s in (0, s_max) where fn goes from > 0 to <= 0 (geometric grid, then brentq); 0 if fn is
    already <= 0 for a vanishing pull; inf if there is no such s."""
    from scipy.optimize import brentq

    hi = s_max * (1.0 - 1e-12) if math.isfinite(s_max) else 1e9
    grid = np.geomspace(hi * 1e-9, hi, n_grid)
    prev_s, prev_v = grid[0], fn(grid[0])
    if prev_v <= 0:
        return 0.0
    for s in grid[1:]:
        v = fn(s)
        if v <= 0:
            return float(brentq(fn, prev_s, s, xtol=1e-15 * s, rtol=1e-15, maxiter=200))  # pyright: ignore[reportArgumentType]  # brentq returns a float without full_output
        prev_s, prev_v = s, v
    return math.inf


def twist_threshold(scenario: Scenario, direction, *, attachment=None, mass_centre=None) -> float:
    """|S| [N] at which the twist condition of (2.9) fails, by root finding on |S| (inf if it never does).

    Both sides of the condition are proportional to |S| at a fixed R, so the root is where R(s) has moved
    to a place where max_i |ê×(r_i - R)| = |ê×(B - R)| (ê the horizontal pull direction).
    """
    e = _unit(direction)
    size, B, C, G, _ = _host(scenario, attachment, mass_centre)
    h = math.hypot(e[0], e[1])
    if h == 0.0:
        return math.inf
    xy = np.array([[0, 0], [size[0], 0], [size[0], size[1]], [0, size[1]]], dtype=float)

    def margin(s):
        N = G - s * e[2]
        if N <= 0:
            return -1.0
        xR = (G * C[0] + s * (B[2] * e[0] - B[0] * e[2])) / N
        yR = (G * C[1] + s * (B[2] * e[1] - B[1] * e[2])) / N
        Tx, Ty = -e[0], -e[1]
        M_T = (B[1] - yR) * e[0] - (B[0] - xR) * e[1]
        lim = np.max(np.abs(Tx * (xy[:, 1] - yR) - Ty * (xy[:, 0] - xR)))
        return (lim - abs(M_T)) / (size[0] + size[1])

    s_lift = G / e[2] if e[2] > 0 else math.inf
    return _first_root(margin, s_lift)


def slip_threshold(scenario: Scenario, direction, *, attachment=None, mass_centre=None) -> float:
    """|S| [N] at which the exact corner friction utilisation ρ* reaches 1 (root finding; inf if never
    before the load lifts). Not one of the paper's conditions: the exact form of (2.4) with the loads
    (2.3)."""
    e = _unit(direction)
    _, _, _, G, _ = _host(scenario, attachment, mass_centre)
    e_j = jnp.asarray(e)
    B = None if attachment is None else jnp.asarray(attachment, dtype=jnp.float64)
    C = None if mass_centre is None else jnp.asarray(mass_centre, dtype=jnp.float64)

    def margin(s):
        st = rest_statics_jit(scenario, s * e_j, attachment=B, mass_centre=C)
        return 1.0 - float(st.friction_utilisation)

    s_lift = G / e[2] if e[2] > 0 else math.inf
    return _first_root(margin, s_lift)


def thresholds(
    scenario: Scenario, direction, *, attachment=None, mass_centre=None, include_slip: bool = True
) -> dict[str, float]:
    """Rope-force magnitudes |S| [N] at which each condition first fails for a pull along `direction`.

    **Returns** a dict with keys "lift", "slide", "twist", "tip" (and "slip", the exact friction limit, if
    `include_slip`), inf where the condition holds up to lift-off, and "tip_kind" / "tip_edges" describing
    how R leaves the rectangle.
    """
    kw = dict(attachment=attachment, mass_centre=mass_centre)
    s_tip, kind, edges = tip_threshold(scenario, direction, **kw)  # pyright: ignore[reportArgumentType]  # corner_tol has a default
    out = {
        "lift": lift_threshold(scenario, direction, **kw),
        "slide": slide_threshold(scenario, direction, **kw),
        "twist": twist_threshold(scenario, direction, **kw),
        "tip": s_tip,
        "tip_kind": kind,
        "tip_edges": edges,
    }
    if include_slip:
        out["slip"] = slip_threshold(scenario, direction, **kw)
    return out


def first_failure(
    scenario: Scenario, rope_force, *, attachment=None, mass_centre=None, include_slip: bool = False
) -> tuple[str | None, float]:
    """Which condition of (2.9) fails first as the pull grows along the direction of `rope_force` S.

    **Returns** `(name, |S|)` with name one of "lift", "slide", "twist", "tip-edge", "tip-corner" (or "slip"
    if `include_slip`), or `(None, inf)` if none fails. The name is about the ray, not about whether
    `rope_force` itself already violates it; compare |S| with the returned magnitude for that.
    """
    th = thresholds(
        scenario, rope_force, attachment=attachment, mass_centre=mass_centre, include_slip=include_slip
    )
    names = ["lift", "slide", "twist", "tip"] + (["slip"] if include_slip else [])
    best = min(names, key=lambda n: th[n])
    if not math.isfinite(th[best]):
        return None, math.inf
    return (th["tip_kind"] if best == "tip" else best), th[best]  # pyright: ignore[reportReturnType]  # a tip_kind is a str
