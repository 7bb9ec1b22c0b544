"""A linearly implicit Rosenbrock-W integrator that treats the model's stiff forces implicitly.

The method is ROS34PW2 (Rang & Angermann, BIT 45 (2005) 761-787): four stages, order 3 with an embedded
order-2 solution for the error estimate, stiffly accurate and L-stable, and a *W-method*: it keeps order 3 for
any approximation W of the Jacobian. That is what lets the solver use `physics.linearise` (the velocity and
displacement derivatives of the contact, rope and boom forces, reduced to a 6x6 system and a rank-one update
per member) instead of the full Jacobian: the modes that make the elastic model stiff (friction slope μN/ε,
foundation and rope dampers, ../shared/notes/stiffness.md) are inside W, so the step is set by accuracy, not
by ε.

One step from (t, y) with step h, in the transformed variables u_i = Σ_{j<=i} γ_ij k_j (Hairer & Wanner,
Solving ODEs II, §IV.7, (7.25)) so that no product J u is needed:

    (I/(hγ) - W) u_i = f(t + α_i h, y + Σ_{j<i} a_ij u_j) + Σ_{j<i} (c_ij / h) u_j + γ_i h ∂f/∂t(t, y),
    y_1 = y + Σ m_i u_i,    error = Σ (m_i - m̂_i) u_i,

with a = α Γ⁻¹, c = diag(1/γ) - Γ⁻¹, m = bᵀ Γ⁻¹ (Γ the lower-triangular matrix of γ_ij, γ on its
diagonal) and γ_i = Σ_j γ_ij. Time enters through the hoist law: the rope's rest length shortens at the
hoist speed, so ∂f/∂t is the stiff rope's force rate c_l v_l (4.2e6 N/s on paper-4.2) acting on the boom tip
and the load. A W-method may leave ∂f/∂t out (it is the time column of the autonomous system's W); the ramp in
the rope's stretch then enters each step only through the explicit stage values, and the boom tip's
velocity error set the step (98 % of the error norm, a script since removed). By default
(`RosenbrockW(time_derivative=True)`) the stages carry γ_i h ∂f/∂t (one forward-mode derivative in t per
step, at the step's start, held fixed like W). On a stiff spring pulled at a constant rate with a W 30 %
off its Jacobian that more than halves the error of a long step (tests/test_rosenbrock.py), and on
paper-4.2 it takes 40 % of the steps at the same accuracy (docs/performance.md);
`time_derivative=False` leaves it out.

`RosenbrockW` is a diffrax solver: it runs inside `diffrax.diffeqsolve` with any step-size controller,
`SaveAt`, adjoint (forward mode, checkpointed reverse mode) and under `jax.vmap`, like diffrax's own solvers.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import ClassVar

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from diffrax import AbstractTerm

from .._physics.linearise import linearise as elastic_linearise
from ._tree import lin_comb


class WTableau(eqx.Module):
    """Coefficients of a Rosenbrock-W method in the transformed form used by `w_step` (see the module
    docstring): `a` (stage states), `c` (stage couplings, divided by h), `alpha` (stage times), `m` and
    `m_err` (solution and error weights), `gamma`, `gamma_t` (the weights γ_i = Σ_j γ_ij of the time
    derivative ∂f/∂t in each stage), the `order` and the order of the embedded solution."""

    a: tuple = eqx.field(static=True)
    c: tuple = eqx.field(static=True)
    alpha: tuple = eqx.field(static=True)
    m: tuple = eqx.field(static=True)
    m_err: tuple = eqx.field(static=True)
    gamma: float = eqx.field(static=True)
    gamma_t: tuple = eqx.field(static=True)
    order: int = eqx.field(static=True)
    embedded_order: int = eqx.field(static=True)


def w_tableau(alpha, gamma_lower, gamma: float, b, b_hat, order: int, embedded_order: int) -> WTableau:
    """Build a `WTableau` from a method's coefficients in the Hairer-Wanner form (α_ij, γ_ij for j < i,
    the diagonal γ, weights b and embedded weights b̂)."""
    alpha = np.asarray(alpha, dtype=np.float64)
    Gam = np.asarray(gamma_lower, dtype=np.float64) + gamma * np.eye(len(b))
    Ginv = np.linalg.inv(Gam)
    a = alpha @ Ginv
    c = np.diag(1.0 / np.diag(Gam)) - Ginv
    m = np.asarray(b, dtype=np.float64) @ Ginv
    m_hat = np.asarray(b_hat, dtype=np.float64) @ Ginv

    def frozen(x):  # hashable static coefficients: nested tuples of floats
        x = np.asarray(x, dtype=np.float64)
        return tuple(map(frozen, x)) if x.ndim else float(x)

    return WTableau(
        a=frozen(a),  # pyright: ignore[reportArgumentType]  # frozen() of a matrix is a tuple
        c=frozen(c),  # pyright: ignore[reportArgumentType]  # frozen() of a matrix is a tuple
        alpha=frozen(alpha.sum(axis=1)),  # pyright: ignore[reportArgumentType]  # frozen() of a matrix is a tuple
        m=frozen(m),  # pyright: ignore[reportArgumentType]  # frozen() of a matrix is a tuple
        m_err=frozen(m - m_hat),  # pyright: ignore[reportArgumentType]  # frozen() of a matrix is a tuple
        gamma=float(gamma),
        gamma_t=frozen(Gam.sum(axis=1)),  # pyright: ignore[reportArgumentType]  # frozen() of a vector is a tuple
        order=order,
        embedded_order=embedded_order,
    )


_G = 4.3586652150845900e-01
#: ROS34PW2, Rang & Angermann (2005), Table 4 (γ_ij for j < i and α_ij; b and the embedded b̂).
ROS34PW2 = w_tableau(
    alpha=[
        [0, 0, 0, 0],
        [8.7173304301691801e-01, 0, 0, 0],
        [8.4457060015369423e-01, -1.1299064236484185e-01, 0, 0],
        [0, 0, 1.0, 0],
    ],
    gamma_lower=[
        [0, 0, 0, 0],
        [-8.7173304301691801e-01, 0, 0, 0],
        [-9.0338057013044082e-01, 5.4180672388095326e-02, 0, 0],
        [2.4212380706095346e-01, -1.2232505839045147e00, 5.4526025533510214e-01, 0],
    ],
    gamma=_G,
    b=[2.4212380706095346e-01, -1.2232505839045147e00, 1.5452602553351020e00, _G],
    b_hat=[3.7810903145819369e-01, -9.6042292212423178e-02, 0.5, 2.1793326075422950e-01],
    order=3,
    embedded_order=2,
)


def w_step(
    f, linearise, tab: WTableau, t, y, h, args, f0=None, quadrature=None, time_derivative=False,
    time_column=None, stage_loop=False,
):  # fmt: skip
    """One Rosenbrock-W step of size h from (t, y).

    - `f(t, y, args)`: the vector field; `linearise(t, y, args)`: an object with `factor(hγ)` and
      `solve(factors, r, hγ)` solving (I/(hγ) - W) u = r (e.g. `physics.linearise.Linearisation`).
    - `f0`: f(t, y, args) if already known (the previous step's `f1`).
    - `quadrature`: None, or `where(y)` selecting leaves that are pure quadratures ∫ g(t, y) dt of the other
      components (they do not feed back). Those are integrated by the trapezoidal rule on the step's end
      points instead of through the stages, and left out of the error estimate: the stage values of the
      stiff components of a linearly implicit method are not accurate (only the step's result is), so a
      quadrature of a nonlinear function of them (a damper's loss h ṗ²) through the stages is biased, by a
      factor 3 for the foundation and rope dampers' loss on paper-4.2.
    - `time_derivative`: add γ_i h ∂f/∂t(t, y) to each stage (module docstring); False (the default here, a
      plain W-method step) leaves it out. `RosenbrockW` passes True by default.
    - `time_column`: with `time_derivative`, `(f, t, y, args) -> ∂f/∂t` (a pytree like y); None: the
      forward-mode derivative of f in t. Like W, it may be any approximation: it is the time column of the
      autonomous system's W, and the method keeps its order for any W.
    - `stage_loop`: run the stages after the first as a `jax.lax.fori_loop` (the vector field traced and
      compiled once for them instead of once per stage; the coefficients as arrays, zero-padded), else
      unrolled (the default: the unrolled stages ran 4 % faster in a 256-member step loop,
      docs/performance.md). The forward sensitivities' augmented system, whose vector field is a
      Jacobian-vector product and whose compile dominated its cost, takes the loop.

    **Returns** `(y1, error, f1)`: the order-3 solution, the difference to the embedded solution, and
    f(t + h, y1) (for the next step's first stage and the dense output).
    """
    # W is not differentiated: a W-method may use any W, and with W held fixed the derivative of the step is
    # the same W-method applied to the variational equations (consistent, and as stable as the step). The
    # derivative *of* W (the friction slope's own derivative, ~μN/ε² per corner) made forward-mode
    # sensitivities of paper-4.2 grow to 1e77 and NaN over 25 s.
    lin = jax.lax.stop_gradient(linearise(t, y, args))
    hg = h * tab.gamma
    # Barriers keep XLA from fusing (and so recomputing) the linearisation and its factors into every
    # stage that reads them.
    # ∂f/∂t, the time column of W, is held fixed like W (no derivative of it is traced) and goes behind the
    # same barrier (None, an empty pytree, without `time_derivative`).
    f_t = None
    if time_derivative:
        y_, args_, t_ = jax.lax.stop_gradient((y, args, t))
        f_t = (time_derivative_of if time_column is None else time_column)(f, t_, y_, args_)
    lin, lu, f_t = jax.lax.optimization_barrier((lin, lin.factor(hg), f_t))
    if stage_loop:
        us, f_start = _looped_stages(f, lin, lu, hg, tab, t, y, h, args, f0, f_t)
    else:
        us, f_start = _unrolled_stages(f, lin, lu, hg, tab, t, y, h, args, f0, f_t)
    y1 = lin_comb(list(zip(tab.m, us, strict=True)), base=y)
    err = lin_comb(list(zip(tab.m_err, us, strict=True)), like=y)
    f1 = f(t + h, y1, args)
    if quadrature is None:
        return y1, err, f1
    trapezoid = jax.tree_util.tree_map(
        lambda q, g0, g1: q + 0.5 * h * (g0 + g1), quadrature(y), quadrature(f_start), quadrature(f1)
    )
    y1 = eqx.tree_at(quadrature, y1, trapezoid)
    err = eqx.tree_at(quadrature, err, jax.tree_util.tree_map(jnp.zeros_like, quadrature(err)))
    return y1, err, f1


def _unrolled_stages(f, lin, lu, hg, tab: WTableau, t, y, h, args, f0, f_t):
    """The stage increments u_1..u_s of `w_step` (a list) and f at the step's start, one stage after the
    other in the traced program."""
    us = []
    f_start = None
    for i in range(len(tab.m)):
        if i == 0 and f0 is not None:
            fi = f0
        else:
            yi = lin_comb([(tab.a[i][j], us[j]) for j in range(i)], base=y)
            fi = f(t + float(tab.alpha[i]) * h, yi, args)
        if i == 0:
            f_start = fi
        if i:
            cu = lin_comb([(tab.c[i][j], us[j]) for j in range(i)], like=y)
            ri = jax.tree_util.tree_map(lambda fl, cl: fl + cl / h, fi, cu)
        else:
            ri = fi
        if f_t is not None and tab.gamma_t[i] != 0.0:
            g_i = float(tab.gamma_t[i])
            ri = jax.tree_util.tree_map(lambda r, d: r + (g_i * h) * d, ri, f_t)
        us.append(jax.lax.optimization_barrier(lin.solve(lu, ri, hg)))
    return us, f_start


def _looped_stages(f, lin, lu, hg, tab: WTableau, t, y, h, args, f0, f_t):
    """As `_unrolled_stages`, with the stages after the first in a `fori_loop`: the increments are kept
    stacked along a leading axis (zeros for the stages not yet taken, which the zero-padded coefficient rows
    a_ij, c_ij (j >= i) leave out)."""
    n = len(tab.m)
    # a and c are strictly lower triangular up to the rounding of the tableau's inverse (|x| < 1e-15 above):
    # zeroed, so that the loop sums exactly the unrolled stages' terms j < i
    a, c = np.tril(np.asarray(tab.a), -1), np.tril(np.asarray(tab.c), -1)
    alpha, gamma_t = np.asarray(tab.alpha), np.asarray(tab.gamma_t)
    f_start = f(t, y, args) if f0 is None else f0
    r0 = f_start
    if f_t is not None and gamma_t[0] != 0.0:
        r0 = jax.tree_util.tree_map(lambda r, d: r + (float(gamma_t[0]) * h) * d, r0, f_t)
    u0 = jax.lax.optimization_barrier(lin.solve(lu, r0, hg))
    stacked = jax.tree_util.tree_map(lambda u: jnp.zeros((n, *u.shape), u.dtype).at[0].set(u), u0)

    def stage(i, us):
        def comb(coef, base, scale=1.0):
            return jax.tree_util.tree_map(
                lambda b, u: b + jnp.tensordot(jnp.asarray(coef, u.dtype)[i], u, axes=1) * scale, base, us
            )

        t_i = t + jnp.asarray(alpha, jnp.result_type(t))[i] * h
        fi = f(t_i, comb(a, y), args)
        ri = comb(c, fi, 1.0 / h)
        if f_t is not None:  # γ_i in each leaf's dtype (a float32 state stays float32 under x64)
            ri = jax.tree_util.tree_map(lambda r, d: r + (jnp.asarray(gamma_t, d.dtype)[i] * h) * d, ri, f_t)
        ui = jax.lax.optimization_barrier(lin.solve(lu, ri, hg))
        return jax.tree_util.tree_map(lambda s_, u: s_.at[i].set(u), us, ui)

    stacked = jax.lax.fori_loop(1, n, stage, stacked)
    return [jax.tree_util.tree_map(lambda s_, k=k: s_[k], stacked) for k in range(n)], f_start


def time_derivative_of(f, t, y, args):
    """∂f/∂t(t, y): the forward-mode derivative of the vector field in t (`w_step`'s default time column)."""
    return jax.jvp(lambda tt: f(tt, y, args), (t,), (jnp.ones_like(t),))[1]


def elastic_quadratures(y):
    """The energy integrals of the elastic model's state (hoist work, damper loss, friction work [J]): pure
    quadratures of the motion."""
    return (y.hoist_work, y.damping_loss, y.friction_work)


class RosenbrockW(diffrax.AbstractAdaptiveSolver):
    """A linearly implicit Rosenbrock-W solver for diffrax that treats the stiff forces implicitly through
    a structured approximate Jacobian (see the module docstring).

    - `linearise`: `(t, y, args) -> Linearisation`; default `physics.linearise.linearise`, the elastic
      model's contact, rope and boom forces.
    - `quadrature`: `where(y)` selecting the state's pure quadratures (integrated by the trapezoidal rule
      on the steps' end points, see `w_step`); default the elastic model's energy integrals; None for none.
    - `tableau`: the method; default ROS34PW2 (order 3, embedded order 2, L-stable, stiffly accurate).
    - `tangent_weight`: the weight w of the sensitivities' error in the step-size control of forward-mode
      derivatives (`jax.jvp`, `jax.jacfwd`, `scan(derivatives=True)` with `adjoint=diffrax.ForwardMode()`):
      a step is accepted when max(‖e_y‖, w ‖e_s‖) <= 1, so a sensitivity may carry 1/w times the
      relative local error of the state (`_numerics/sensitivity.py`). Default 0.1.
    - `time_derivative`: whether the stages carry the γ_i h ∂f/∂t term (the module docstring). Default
      True; False takes about 2.4x the steps on paper-4.2 at the same accuracy (docs/performance.md).
    - `time_column`: how ∂f/∂t is taken (`w_step`); None (default): forward mode in t of the whole vector
      field. The forward sensitivities' augmented system takes it of the state's block only
      (`_numerics/sensitivity.py`).
    - `stage_loop`: the stages after the first as a loop (`w_step`); default False (unrolled). The
      sensitivities' augmented system takes the loop.

    f at each step's end is kept for the next step's first stage, so a step costs four evaluations of the
    vector field, one linearisation and one 6x6 factorisation (and, with `time_derivative`, one derivative
    of the vector field in t).

    Forward-mode derivatives (`SolverOptions(adjoint=diffrax.ForwardMode())`) are solved as their own
    error-controlled ODE beside the state (`_numerics/sensitivity.py`): differentiating the steps instead
    let the tangent grow without bound in stick-slip over 25 s of paper-4.2. Reverse mode (`jax.grad`, the
    default adjoint) goes through the steps with W held fixed: the derivative of the step map, whose error
    nothing controls. At tight tolerances it agrees with differences of the solution over short spans when
    every step is checkpointed (tests/test_rosenbrock.py, rtol 1e-7); at the default tolerances it can be far
    off: d x_C(1 s)/dμ of paper-4.2 at μ = 0.3 is 0.398 m by `jax.grad`, with or without every step
    checkpointed, against 0.337 m by forward mode and 0.339 m by central differences of Tsit5 solves at rtol
    1e-10 (`python experiments/figures/derivative_modes.py`). With fewer checkpoints than steps (the
    default) diffrax also recomputes steps in the backward pass, in a differently compiled program that
    rounds differently; where that flips a step's acceptance, the gradient belongs to a slightly different
    step sequence (0.5 % off over 0.5 s of paper-4.2 at rtol 1e-7, against all-step checkpoints,
    `adjoint=diffrax.RecursiveCheckpointAdjoint(checkpoints=max_steps)`). For derivatives use forward mode,
    or reverse mode at tight tolerances checked against it. Dense output
    between steps is the cubic Hermite interpolant of y and f at the step's ends (order 3, like the method;
    f at both ends is computed anyway), so steps need not land on the saved times: with 201 saved times
    over 25 s of paper-4.2 that saves the 3.6 % of steps that landing on them would cost.
    """

    linearise: Callable = eqx.field(static=True, default=elastic_linearise)
    quadrature: Callable | None = eqx.field(static=True, default=elastic_quadratures)
    tableau: WTableau = ROS34PW2
    tangent_weight: float = eqx.field(static=True, default=0.1)
    time_derivative: bool = eqx.field(static=True, default=True)
    time_column: Callable | None = eqx.field(static=True, default=None)
    stage_loop: bool = eqx.field(static=True, default=False)

    term_structure: ClassVar = AbstractTerm
    interpolation_cls: ClassVar = diffrax.ThirdOrderHermitePolynomialInterpolation

    def order(self, terms):
        return self.tableau.order

    def error_order(self, terms):
        return self.tableau.embedded_order + 1

    def init(self, terms, t0, t1, y0, args):
        return terms.vf(t0, y0, args)

    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        # The vector field is continuous in t (no jump_ts are used), so f(t0, y0) from the previous step
        # stays valid across `made_jump`.
        del made_jump
        y1, err, f1 = w_step(
            terms.vf, self.linearise, self.tableau, t0, y0, t1 - t0, args, solver_state, self.quadrature,
            time_derivative=self.time_derivative, time_column=self.time_column, stage_loop=self.stage_loop,
        )  # fmt: skip
        h = t1 - t0
        k0 = jax.tree_util.tree_map(lambda d: h * d, solver_state)
        k1 = jax.tree_util.tree_map(lambda d: h * d, f1)
        return y1, err, dict(y0=y0, y1=y1, k0=k0, k1=k1), f1, diffrax.RESULTS.successful

    def func(self, terms, t0, y0, args):
        return terms.vf(t0, y0, args)
