"""Coulomb's law in its maximum-dissipation form for the rigid model's choice of the next contact
configuration (`coulomb_pattern`): which resting contacts stick and in which direction the others start
to slide. Host-side numpy."""

from __future__ import annotations

import numpy as np

from ..._physics.rigid import FREE, SLIDE, STICK


def coulomb_pattern(
    mats, in_contact, resting, mu: float, G: float, g: float, n_outer: int = 12, debug: bool = False
):
    """Which resting contacts stick and in which direction the others start to slide, for the contact set
    `in_contact`, from Coulomb's law in its maximum-dissipation form.

    For given normal forces Ñ the accelerations u̇ = (dv_C/dt, dω/dt) minimise the convex function

        ½ u̇ᵀ M u̇ - f̃·u̇ + Σ_{resting contacts i} μ Ñ_i |a_i,h(u̇)|   subject to a_i,z(u̇) = target_i (contacts),

    (f̃: applied forces plus the known friction -μÑ_i t̂_i of contacts that already slide), whose optimality
    conditions are exactly: a resting corner with a_i,h = 0 sticks with |T_i| <= μÑ_i, one with a_i,h != 0
    slides with T_i = -μÑ_i a_i,h / |a_i,h|. The norm is smoothed, sqrt(|a|² + ε²), and ε decreased from
    1e-2 g to 1e-13 g with Newton's method in the null space of the contact constraints; the normal forces
    are the (minimum-norm) multipliers and are iterated to a fixed point (`n_outer` times). Host-side numpy.
    With the taut inextensible rope (`mats.rope_row`), u̇ includes the boom tip's acceleration and the
    rope's d²|AB|/dt² is one more equality constraint (its multiplier is the tension).

    **Returns** `(modes, hints)`: per corner FREE / SLIDE / STICK and the sliding directions (4, 2).
    """
    M, f, jac, bias = mats.mass, mats.force, mats.jacobians, mats.bias
    cv, target = mats.corner_velocity, mats.target
    idx = np.nonzero(in_contact)[0]
    modes = np.full(4, FREE, dtype=np.int32)
    hints = np.zeros((4, 2))
    if idx.size == 0:
        return modes, hints
    speed = np.linalg.norm(cv[:, :2], axis=1)
    res = in_contact & resting
    mov = in_contact & ~resting
    tdir = np.zeros((4, 2))
    tdir[mov] = cv[mov, :2] / speed[mov, None]
    Gz = jac[idx, 2, :]  # (n_c, 6)
    rz = target[idx, 2] - bias[idx, 2]
    if mats.rope_row is not None:  # the taut inextensible rope: one more equality (coordinates incl. tip)
        Gz = np.concatenate([Gz, mats.rope_row[None, :]], axis=0)
        rz = np.append(rz, mats.rope_rhs)
    u0 = np.linalg.lstsq(Gz, rz, rcond=None)[0]
    _, sv, Vt = np.linalg.svd(Gz)
    rank = int(np.sum(sv > 1e-10 * sv.max()))
    Z = Vt[rank:].T  # null space of the contact rows (6, 6 - rank)
    A = jac[:, :2, :]  # horizontal rows (4, 2, 6)
    b = bias[:, :2]

    def multipliers(u, Nt, eps):
        r = M @ u - f
        for i in np.nonzero(mov)[0]:
            r = r - A[i].T @ (-mu * Nt[i] * tdir[i])
        for i in np.nonzero(res)[0]:
            s = A[i] @ u + b[i]
            r = r - A[i].T @ (-mu * Nt[i] * s / np.sqrt(s @ s + eps**2))
        lam = np.linalg.lstsq(Gz.T, r, rcond=None)[0]
        N = np.zeros(4)
        N[idx] = lam[: idx.size]
        return N

    def minimise(Nt, q, eps_list):
        w = mu * np.maximum(Nt, 0.0)
        ft = f.copy()
        for i in np.nonzero(mov)[0]:
            ft = ft + A[i].T @ (-w[i] * tdir[i])
        ri = np.nonzero(res)[0]

        def phi(q, eps):
            u = u0 + Z @ q
            val = 0.5 * u @ M @ u - ft @ u
            for i in ri:
                s = A[i] @ u + b[i]
                val += w[i] * np.sqrt(s @ s + eps**2)
            return val

        for eps in eps_list:
            for _ in range(30):
                u = u0 + Z @ q
                grad = M @ u - ft
                H = M.copy()
                for i in ri:
                    s = A[i] @ u + b[i]
                    r = np.sqrt(s @ s + eps**2)
                    grad = grad + w[i] * A[i].T @ (s / r)
                    H = H + w[i] * A[i].T @ (np.eye(2) / r - np.outer(s, s) / r**3) @ A[i]
                gq, Hq = Z.T @ grad, Z.T @ H @ Z
                if gq.size == 0:
                    break
                d = -np.linalg.solve(Hq, gq)
                f0, step = phi(q, eps), 1.0
                while phi(q + step * d, eps) > f0 + 1e-4 * step * (gq @ d) and step > 1e-12:
                    step *= 0.5
                q = q + step * d
                if np.linalg.norm(step * d) <= 1e-15 * (1.0 + np.linalg.norm(q)):
                    break
        return q

    eps_final = 1e-13 * g
    eps_all = list(g * 10.0 ** -np.arange(2.0, 13.5, 1.0))
    q = np.zeros(Z.shape[1])
    # Frictionless normal forces to start the fixed point.
    Nt = multipliers(u0 + Z @ minimise(np.zeros(4), q, [eps_final]), np.zeros(4), eps_final)
    for it in range(n_outer):
        q = minimise(Nt, q, eps_all if it == 0 else [eps_final])
        u = u0 + Z @ q
        N_new = multipliers(u, Nt, eps_final)
        if np.max(np.abs(N_new - Nt)) <= 1e-10 * G:
            Nt = N_new
            break
        Nt = N_new
    u = u0 + Z @ q
    if debug:
        ah = np.einsum("kij,j->ki", A, u) + b
        print(
            f"    coulomb_pattern {in_contact.astype(int)}: outer it {it}, N = {np.round(Nt, 3)}, "
            f"|a_h| = {np.linalg.norm(ah, axis=1)}, u = {u}"
        )
    _classify(modes, hints, idx, mov, tdir, A, b, u, eps_final)
    return modes, hints


def _classify(modes, hints, idx, mov, tdir, A, b, u, eps_final):
    """Fill `modes` and `hints` (in place) for the contacts `idx`: corners already sliding (`mov`) slide on
    along `tdir`; a resting one with a horizontal acceleration A_i u + b_i (above 1e3 `eps_final`) starts
    to slide along it; the others stick."""
    for i in idx:
        if mov[i]:
            modes[i], hints[i] = SLIDE, tdir[i]
        else:
            ah = A[i] @ u + b[i]
            na = np.linalg.norm(ah)
            if na > 1e3 * eps_final:
                modes[i], hints[i] = SLIDE, ah / na
            else:
                modes[i] = STICK
