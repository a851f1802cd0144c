"""Compiled kernels of the nonlinear model: net wrench, its Jacobian and damped Newton on SO(3).

This is the single implementation of the platform's force and moment balance (paper eqs. 13–16 as corrected in
docs/physics.md); everything else (solver front end, tangent stiffness, residual for scipy) calls it. Scalar loops
over the
six wires, compiled with numba when it is installed (about 100× faster than numpy on 6×6 problems, where numpy's
per-call overhead dominates); without numba the same code runs as plain Python, slower but identical.

Conventions: fixed frame of the paper (z down); pose = displacement u [m] of the platform centre and rotation Q
(body→fixed). Wrench w = [F; M]: net force [N] and net moment about the platform centre [N·m] on the platform.
The Jacobian returned is K = −∂w/∂x with x = [δu; δω] and rotations perturbed in the fixed frame, Q → (I + [δω]×)Q,
the external load held fixed in space.
"""
from __future__ import annotations

import math

import numpy as np

# The one no-numba fallback of the model's kernels (_batch_kernels and _pose_kernels take njit and prange from here).
try:  # numba is a dependency; the fallback keeps the model usable (slowly) where it cannot be installed.
    from numba import njit, prange
    HAVE_NUMBA = True
except ImportError:  # pragma: no cover - exercised only without numba
    HAVE_NUMBA = False
    prange = range  # type: ignore[misc]

    def njit(*args, **kwargs):  # type: ignore[no-redef]
        if args and callable(args[0]):
            return args[0]
        return lambda f: f

# Status codes of newton_solve.
CONVERGED = 0
MAX_ITERATIONS = 1
LINE_SEARCH_FAILED = 2
SINGULAR = 3
JUMPED = 4  # converged, but so far from the start that it may be another branch: take smaller load steps
#: Largest rotation of one Newton iteration [rad]: keeps Newton on the branch it starts on.
MAX_TURN = 0.2


@njit(cache=True)
def assemble(top, plat, l0, kw, weight, com, ploc, load, u, q, w, kmat, lengths, tensions, want_k):
    """Net wrench and Jacobian; see :func:`assemble_into` (this wrapper allocates its own scratch space)."""
    assemble_into(top, plat, l0, kw, weight, com, ploc, load, u, q, w, kmat, lengths, tensions, want_k,
                  np.empty((3, 3, 3)), np.empty((4, 3)))


@njit(cache=True)
def assemble_into(top, plat, l0, kw, weight, com, ploc, load, u, q, w, kmat, lengths, tensions, want_k, m33, v3):
    """Net wrench and, if want_k, its Jacobian of the model with slack wires; see :func:`assemble_model`."""
    assemble_model(top, plat, l0, kw, weight, com, ploc, load, u, q, w, kmat, lengths, tensions, want_k, False,
                   m33, v3)


@njit(cache=True)
def assemble_model(top, plat, l0, kw, weight, com, ploc, load, u, q, w, kmat, lengths, tensions, want_k,
                   bilateral, m33, v3):
    """Net wrench w (6,) on the platform and, if want_k, K = −∂w/∂x (6, 6). Fills lengths and tensions (6,).

    bilateral: treat every wire as a spring that also pushes (tension k(L − l0) of either sign): the smooth
    continuation of the all-taut model past a slack onset, used to locate that onset by Newton's method.

    top (6,3) overhead points [m]; plat (6,3) platform points, body frame [m]; l0 (6,) unstretched lengths [m];
    kw (6,) wire stiffnesses [N/m]; weight W [N] along +z at body offset com (3,); external load (6,) = force [N] at
    body offset ploc (3,) and moment [N·m], both fixed frame; u (3,) [m]; q (3,3) rotation body→fixed.
    """
    for i in range(6):
        w[i] = 0.0
        if want_k:
            for j in range(6):
                kmat[i, j] = 0.0
    # Scratch space comes from the caller: allocating it here would cost more than the arithmetic.
    r = v3[0]
    e = v3[1]
    g = m33[0]
    rx = m33[1]
    gr = m33[2]
    for n in range(6):
        for i in range(3):
            r[i] = q[i, 0] * plat[n, 0] + q[i, 1] * plat[n, 1] + q[i, 2] * plat[n, 2]
        lx = top[n, 0] - u[0] - r[0]
        ly = top[n, 1] - u[1] - r[1]
        lz = top[n, 2] - u[2] - r[2]
        length = math.sqrt(lx * lx + ly * ly + lz * lz)
        lengths[n] = length
        if length < l0[n] and not bilateral:  # slack: a wire carries no compression (eq. 14)
            tensions[n] = 0.0
            continue
        t = kw[n] * (length - l0[n])
        tensions[n] = t
        e[0] = lx / length
        e[1] = ly / length
        e[2] = lz / length
        f0 = t * e[0]
        f1 = t * e[1]
        f2 = t * e[2]
        w[0] += f0
        w[1] += f1
        w[2] += f2
        w[3] += r[1] * f2 - r[2] * f1
        w[4] += r[2] * f0 - r[0] * f2
        w[5] += r[0] * f1 - r[1] * f0
        if not want_k:
            continue
        # G = k e eᵀ + (t/L)(I − e eᵀ): axial spring plus the geometric (tension) stiffness.
        tl = t / length
        for i in range(3):
            for j in range(3):
                g[i, j] = (kw[n] - tl) * e[i] * e[j]
            g[i, i] += tl
        rx[0, 0] = 0.0
        rx[0, 1] = -r[2]
        rx[0, 2] = r[1]
        rx[1, 0] = r[2]
        rx[1, 1] = 0.0
        rx[1, 2] = -r[0]
        rx[2, 0] = -r[1]
        rx[2, 1] = r[0]
        rx[2, 2] = 0.0
        for i in range(3):
            for j in range(3):
                gr[i, j] = g[i, 0] * rx[0, j] + g[i, 1] * rx[1, j] + g[i, 2] * rx[2, j]
        for i in range(3):
            for j in range(3):
                kmat[i, j] += g[i, j]
                kmat[i, 3 + j] -= gr[i, j]
                # [r]×G = −(G[r]×)ᵀ because G is symmetric and [r]× skew.
                kmat[3 + i, j] -= gr[j, i]
                kmat[3 + i, 3 + j] -= rx[i, 0] * gr[0, j] + rx[i, 1] * gr[1, j] + rx[i, 2] * gr[2, j]
        _add_point_force_term(kmat, f0, f1, f2, r)
    # Weight at the centre of mass and the external force at its application point (fixed in space).
    rc = v3[2]
    rp = v3[3]
    for i in range(3):
        rc[i] = q[i, 0] * com[0] + q[i, 1] * com[1] + q[i, 2] * com[2]
        rp[i] = q[i, 0] * ploc[0] + q[i, 1] * ploc[1] + q[i, 2] * ploc[2]
    w[2] += weight
    w[3] += rc[1] * weight
    w[4] += -rc[0] * weight
    w[0] += load[0]
    w[1] += load[1]
    w[2] += load[2]
    w[3] += rp[1] * load[2] - rp[2] * load[1] + load[3]
    w[4] += rp[2] * load[0] - rp[0] * load[2] + load[4]
    w[5] += rp[0] * load[1] - rp[1] * load[0] + load[5]
    if want_k:
        _add_point_force_term(kmat, 0.0, 0.0, weight, rc)
        _add_point_force_term(kmat, load[0], load[1], load[2], rp)


@njit(cache=True)
def _add_point_force_term(kmat, f0, f1, f2, r):
    """Add −[f]×[r]× to the moment–rotation block: the moment r × f of a force f fixed in space turns with r."""
    # [f]×[r]× = r fᵀ − (f·r) I
    fr = f0 * r[0] + f1 * r[1] + f2 * r[2]
    f = (f0, f1, f2)
    for i in range(3):
        for j in range(3):
            kmat[3 + i, 3 + j] -= r[i] * f[j]
        kmat[3 + i, 3 + i] += fr


@njit(cache=True)
def solve6_into(a, b, x, m, y):
    """Solve a x = b (6×6) by Gaussian elimination with partial pivoting, into x, using scratch m (6, 6), y (6).

    Returns False when a pivot is numerically zero (the caller then takes another path)."""
    for i in range(6):
        y[i] = b[i]
        for j in range(6):
            m[i, j] = a[i, j]
    for c in range(6):
        p = c
        best = abs(m[c, c])
        for i in range(c + 1, 6):
            if abs(m[i, c]) > best:
                best = abs(m[i, c])
                p = i
        if not best > 1e-300 or not math.isfinite(best):
            return False
        if p != c:
            for j in range(6):
                tmp = m[c, j]
                m[c, j] = m[p, j]
                m[p, j] = tmp
            tmp = y[c]
            y[c] = y[p]
            y[p] = tmp
        for i in range(c + 1, 6):
            f = m[i, c] / m[c, c]
            if f != 0.0:
                for j in range(c, 6):
                    m[i, j] -= f * m[c, j]
                y[i] -= f * y[c]
    dmax = 0.0
    dmin = 1e300
    for i in range(6):
        d = abs(m[i, i])
        dmax = max(dmax, d)
        dmin = min(dmin, d)
    if not dmin > 1e-14 * dmax:
        return False
    for i in range(5, -1, -1):
        s = y[i]
        for j in range(i + 1, 6):
            s -= m[i, j] * x[j]
        x[i] = s / m[i, i]
    return True


@njit(cache=True)
def _solve6(a, b, x):
    """Solve a x = b for 6×6 a (:func:`solve6_into` with its own scratch). Returns False if singular."""
    return solve6_into(a, b, x, np.empty((6, 6)), np.empty(6))


@njit(cache=True)
def _rotate(q, dw, out, m33):
    """out = exp([dw]×) q (Rodrigues), a rotation update in the fixed frame. m33: scratch (3, 3, 3)."""
    ang = math.sqrt(dw[0] * dw[0] + dw[1] * dw[1] + dw[2] * dw[2])
    if ang < 1e-12:
        s = 1.0
        c1 = 0.5
    else:
        s = math.sin(ang) / ang
        c1 = (1.0 - math.cos(ang)) / (ang * ang)
    k = m33[0]
    r = m33[1]
    for i in range(3):
        for j in range(3):
            k[i, j] = 0.0
            r[i, j] = 1.0 if i == j else 0.0
    k[0, 1] = -dw[2]
    k[0, 2] = dw[1]
    k[1, 0] = dw[2]
    k[1, 2] = -dw[0]
    k[2, 0] = -dw[1]
    k[2, 1] = dw[0]
    for i in range(3):
        for j in range(3):
            kk = k[i, 0] * k[0, j] + k[i, 1] * k[1, j] + k[i, 2] * k[2, j]
            r[i, j] += s * k[i, j] + c1 * kk
    for i in range(3):
        for j in range(3):
            out[i, j] = r[i, 0] * q[0, j] + r[i, 1] * q[1, j] + r[i, 2] * q[2, j]


@njit(cache=True)
def _merit(w, lc):
    """Half the squared residual, moments scaled by the characteristic length lc to force units."""
    s = 0.0
    for i in range(3):
        s += w[i] * w[i]
    for i in range(3, 6):
        s += (w[i] / lc) * (w[i] / lc)
    return 0.5 * s


@njit(cache=True)
def _trial(top, plat, l0, kw, weight, com, ploc, load, u, q, dx, alpha, u_try, q_try, w_try, kmat, lengths,
           tensions, lc, dw, m33, v3):
    """Evaluate the pose (u, q) moved by alpha·dx; fills u_try, q_try, w_try, kmat; returns the merit there."""
    for i in range(3):
        u_try[i] = u[i] + alpha * dx[i]
        dw[i] = alpha * dx[3 + i]
    _rotate(q, dw, q_try, m33)
    assemble_into(top, plat, l0, kw, weight, com, ploc, load, u_try, q_try, w_try, kmat, lengths, tensions, True,
                  m33, v3)
    return _merit(w_try, lc)


@njit(cache=True)
def _take(u, q, w, u_new, q_new, w_new):
    """Copy a pose (u (3,), q (3,3)) and its wrench w (6,) into the current ones."""
    for i in range(3):
        u[i] = u_new[i]
        for j in range(3):
            q[i, j] = q_new[i, j]
    for i in range(6):
        w[i] = w_new[i]


@njit(cache=True)
def _energy(l0, kw, weight, com, ploc, load, u, q, lengths):
    """Potential energy [J] of wires, weight and external force (the couple is added by the caller, see below).

    Π = Σ ½ k (L − l0)² over taut wires − W·z_c − F·x_p. Along a line search the pose turns about one fixed axis,
    Q(α) = exp(α[δω]×)Q, so the work of a fixed couple M is exactly α M·δω and the energy is exact on that line."""
    e = 0.0
    for n in range(6):
        if lengths[n] >= l0[n]:
            d = lengths[n] - l0[n]
            e += 0.5 * kw[n] * d * d
    e -= weight * (u[2] + q[2, 0] * com[0] + q[2, 1] * com[1] + q[2, 2] * com[2])
    for i in range(3):
        e -= load[i] * (u[i] + q[i, 0] * ploc[0] + q[i, 1] * ploc[1] + q[i, 2] * ploc[2])
    return e


@njit(cache=True)
def _scaled_system(kmat, w, lc, ks, rhs):
    """K' = S K S and w' = S w with S = diag(1, 1, 1, 1/lc, 1/lc, 1/lc): unknowns [δu, lc·δω], equations
    [F, M/lc], all in metres and newtons, so pivoting and damping see comparable magnitudes."""
    for i in range(6):
        si = 1.0 if i < 3 else 1.0 / lc
        rhs[i] = w[i] * si
        for j in range(6):
            sj = 1.0 if j < 3 else 1.0 / lc
            ks[i, j] = kmat[i, j] * si * sj


@njit(cache=True)
def _newton_direction(kmat, w, lc, max_move, ks, rhs, dx):
    """Newton step dx = K⁻¹ w in [m, rad], shortened so the centre moves at most max_move [m] and the platform
    turns at most MAX_TURN [rad]. Returns (ok, size of the unshortened step [m], rotations times lc)."""
    _scaled_system(kmat, w, lc, ks, rhs)
    if not _solve6(ks, rhs, dx):
        return False, 0.0
    size = 0.0
    move = 0.0
    turn = 0.0
    for j in range(6):
        size = max(size, abs(dx[j]))
        if j < 3:
            move = max(move, abs(dx[j]))
        else:
            turn = max(turn, abs(dx[j]) / lc)
    scale = 1.0
    if move > max_move:
        scale = max_move / move
    if turn * scale > MAX_TURN:
        scale = MAX_TURN / turn
    for j in range(6):
        dx[j] *= scale
        if j >= 3:
            dx[j] /= lc
    return True, size


@njit(cache=True)
def newton_solve(top, plat, l0, kw, weight, com, ploc, load, u, q, xtol, max_iter, lc, max_move, lengths, tensions,
                 w):
    """Damped Newton on (u, Q) for the static balance w = 0, in place on u (3,) and q (3,3).

    Step Δ = K⁻¹ w, limited in size, with a backtracking line search on the merit ½|w'|². A straight step along
    the platform's swing (pendulum) mode stretches the stiff wires to second order, so the merit can rise although
    the step is good (the Maratos effect of SQP): each rejected trial gets a second-order correction, one more
    Newton step from the trial pose, before the step is shortened. Levenberg-Marquardt takes over when K is singular
    (all but a few wires slack) or no Newton step descends. Converged when a full Newton step moved every platform
    point less than xtol [m]. One iteration moves the centre by at most max_move [m].
    Returns (status, iterations, size of the last step [m]).
    """
    kmat = np.empty((6, 6))
    k_try = np.empty((6, 6))
    ks = np.empty((6, 6))
    rhs = np.empty(6)
    dx = np.empty(6)
    dc = np.empty(6)
    u_try = np.empty(3)
    q_try = np.empty((3, 3))
    w_try = np.empty(6)
    u_soc = np.empty(3)
    q_soc = np.empty((3, 3))
    w_soc = np.empty(6)
    dw = np.empty(3)
    lengths0 = np.empty(6)
    m33 = np.empty((3, 3, 3))
    v3 = np.empty((4, 3))
    assemble_into(top, plat, l0, kw, weight, com, ploc, load, u, q, w, kmat, lengths0, tensions, True, m33, v3)
    phi = _merit(w, lc)
    step = 0.0
    for it in range(1, max_iter + 1):
        ok, full_step = _newton_direction(kmat, w, lc, max_move, ks, rhs, dx)
        if ok and full_step <= xtol:
            # Newton's own correction is below the tolerance: apply it and stop.
            _trial(top, plat, l0, kw, weight, com, ploc, load, u, q, dx, 1.0, u_try, q_try, w_try, kmat,
                   lengths, tensions, lc, dw, m33, v3)
            _take(u, q, w, u_try, q_try, w_try)
            return CONVERGED, it, full_step
        accepted = False
        alpha = 1.0
        if ok:
            # Energy line search: the natural merit of a conservative system. A straight step along the swing mode
            # stretches the wires only to fourth order in energy but to second order in the residual.
            slope = 0.0
            for i in range(6):
                slope -= w[i] * dx[i]
            if slope < 0.0:
                e0 = _energy(l0, kw, weight, com, ploc, load, u, q, lengths0)
                for _ in range(30):
                    phi_try = _trial(top, plat, l0, kw, weight, com, ploc, load, u, q, dx, alpha, u_try, q_try,
                                     w_try, k_try, lengths, tensions, lc, dw, m33, v3)
                    e1 = _energy(l0, kw, weight, com, ploc, load, u_try, q_try, lengths)
                    e1 -= alpha * (load[3] * dx[3] + load[4] * dx[4] + load[5] * dx[5])
                    if e1 - e0 <= 1e-4 * alpha * slope:
                        accepted = True
                        break
                    alpha *= 0.5
        if ok and not accepted:
            alpha = 1.0
            for _ in range(30):
                phi_try = _trial(top, plat, l0, kw, weight, com, ploc, load, u, q, dx, alpha, u_try, q_try,
                                 w_try, k_try, lengths, tensions, lc, dw, m33, v3)
                if phi_try <= (1.0 - 1e-4 * alpha) * phi:
                    accepted = True
                    break
                # Second-order correction from the trial pose.
                ok2, _ = _newton_direction(k_try, w_try, lc, max_move, ks, rhs, dc)
                if ok2:
                    phi_soc = _trial(top, plat, l0, kw, weight, com, ploc, load, u_try, q_try, dc, 1.0, u_soc,
                                     q_soc, w_soc, k_try, lengths, tensions, lc, dw, m33, v3)
                    if phi_soc <= (1.0 - 1e-4 * alpha) * phi:
                        _take(u_try, q_try, w_try, u_soc, q_soc, w_soc)
                        phi_try = phi_soc
                        accepted = True
                        break
                alpha *= 0.5
        if not accepted:
            # Levenberg-Marquardt on the scaled system: (K'ᵀK' + μI) dx = K'ᵀ w', from Gauss-Newton towards
            # steepest descent.
            _scaled_system(kmat, w, lc, ks, rhs)
            ktk = np.empty((6, 6))
            ktr = np.empty(6)
            diag = 0.0
            for i in range(6):
                ktr[i] = 0.0
                for j in range(6):
                    acc = 0.0
                    for m in range(6):
                        acc += ks[m, i] * ks[m, j]
                    ktk[i, j] = acc
                for m in range(6):
                    ktr[i] += ks[m, i] * rhs[m]
                diag = max(diag, ktk[i, i])
            mu = 1e-8 * diag if diag > 0.0 else 1.0
            for _ in range(40):
                damped = ktk.copy()
                for i in range(6):
                    damped[i, i] += mu
                if _solve6(damped, ktr, dx):
                    for j in range(3, 6):
                        dx[j] /= lc
                    phi_try = _trial(top, plat, l0, kw, weight, com, ploc, load, u, q, dx, 1.0, u_try, q_try,
                                     w_try, k_try, lengths, tensions, lc, dw, m33, v3)
                    if phi_try < phi:
                        accepted = True
                        break
                mu *= 10.0
            if not accepted:
                return LINE_SEARCH_FAILED, it, step
        step = 0.0
        for i in range(3):
            step = max(step, abs(u_try[i] - u[i]))
        _take(u, q, w, u_try, q_try, w_try)
        phi = phi_try
        # The last evaluation was at the accepted pose: keep its K and wire lengths.
        for i in range(6):
            lengths0[i] = lengths[i]
            for j in range(6):
                kmat[i, j] = k_try[i, j]
    for i in range(6):
        lengths[i] = lengths0[i]
    return MAX_ITERATIONS, max_iter, step


@njit(cache=True)
def solve_step(top, plat, l0, kw, weight, com, ploc, load, u, q, xtol, max_iter, lc, max_move, min_cos_turn,
               max_shift, lengths, tensions, w):
    """newton_solve from (u, q), accepted only if the result turned the platform by less than acos(min_cos_turn)
    and moved its centre by less than max_shift [m]; u and q are updated only when accepted.
    Returns (status, iterations): CONVERGED, JUMPED, or newton_solve's failure status."""
    u1 = u.copy()
    q1 = q.copy()
    status, iters, _ = newton_solve(top, plat, l0, kw, weight, com, ploc, load, u1, q1, xtol, max_iter, lc,
                                    max_move, lengths, tensions, w)
    if status != CONVERGED:
        return status, iters
    tr = 0.0
    for i in range(3):
        for j in range(3):
            tr += q1[i, j] * q[i, j]  # trace(q1 qᵀ) = 1 + 2 cos(angle between the poses)
    shift = math.sqrt((u1[0] - u[0]) ** 2 + (u1[1] - u[1]) ** 2 + (u1[2] - u[2]) ** 2)
    if 0.5 * (tr - 1.0) < min_cos_turn or shift > max_shift:
        return JUMPED, iters
    for i in range(3):
        u[i] = u1[i]
        for j in range(3):
            q[i, j] = q1[i, j]
    return CONVERGED, iters


@njit(cache=True)
def batch_solve(top, plat, l0, kw, weight, com, ploc, loads, u0, q0, xtol, max_iter, lc, max_move, min_cos_turn,
                max_shift, u_out, q_out, lengths_out, tensions_out, w_out, status_out, iters_out):
    """solve_step for each row of loads (N, 6), every case started from the same pose (u0, q0)."""
    n = loads.shape[0]
    u = np.empty(3)
    q = np.empty((3, 3))
    lengths = np.empty(6)
    tensions = np.empty(6)
    w = np.empty(6)
    for c in range(n):
        for i in range(3):
            u[i] = u0[i]
            for j in range(3):
                q[i, j] = q0[i, j]
        st, it = solve_step(top, plat, l0, kw, weight, com, ploc, loads[c], u, q, xtol, max_iter, lc, max_move,
                            min_cos_turn, max_shift, lengths, tensions, w)
        status_out[c] = st
        iters_out[c] = it
        for i in range(3):
            u_out[c, i] = u[i]
            for j in range(3):
                q_out[c, i, j] = q[i, j]
        for i in range(6):
            lengths_out[c, i] = lengths[i]
            tensions_out[c, i] = tensions[i]
            w_out[c, i] = w[i]
