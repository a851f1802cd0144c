"""Compiled kernels for many equilibria at once: a lean Newton path spread over every core.

The balance itself is :func:`crane_stiffness.model._kernels.assemble_into` (the one implementation of the wire
forces and their Jacobian); this module only drives it. Per load case: a linear predictor from the rest pose
(x = K0⁻¹·∂w/∂load·load, K0 the tangent at rest), then chord steps with K0⁻¹ (one wrench each, no Jacobian) while
they contract fast, else plain Newton steps with the analytic Jacobian; in place, with no allocation. A case is
accepted when the steps shrink every iteration, the last one is below xtol, and the result lies within one
continuation step of the rest pose (the robust solver's own acceptance test); any other case is solved again by the
robust damped Newton (:func:`_kernels.solve_step`) from the rest pose, then to load continuation
(:func:`continuation_path`); what that cannot reach is left to solve_equilibrium (status not CONVERGED), which
raises the error that says why.

Units and frames as in :mod:`._kernels`: fixed frame, z down, u [m], Q body→fixed, loads [N, N·m].
"""
from __future__ import annotations

import math

import numpy as np

from crane_stiffness.model import _kernels as kern
from crane_stiffness.model._kernels import njit, prange, solve6_into

#: Newton iterations of the fast path before a case goes to the robust solver.
FAST_MAX_ITER = 12
#: Chord iterations (rest-pose compliance) before a case switches to Newton.
CHORD_MAX_ITER = 8


@njit(cache=True)
def newton_plain(top, plat, l0, kw, weight, com, ploc, load, u, q, xtol, lc, max_iter, bilateral, w, kmat,
                 lengths, tensions, ks, rhs, dx, m, y, q_new, dw, m33, v3):
    """Plain Newton on (u (3,), q (3, 3)) in place for w = 0; no line search, no allocation.

    Steps are solved in scaled units ([m, lc·rad]); each must be smaller than the one before. On convergence w,
    kmat, lengths and tensions are those of the final pose. Returns (converged, iterations)."""
    prev = 1e300
    for it in range(1, max_iter + 1):
        kern.assemble_model(top, plat, l0, kw, weight, com, ploc, load, u, q, w, kmat, lengths, tensions, True,
                            bilateral, m33, v3)
        for i in range(6):
            si = 1.0 if i < 3 else 1.0 / lc
            rhs[i] = w[i] * si
            for j in range(6):
                sj = 1.0 if j < 3 else 1.0 / lc
                ks[i, j] = kmat[i, j] * si * sj
        if not solve6_into(ks, rhs, dx, m, y):
            return False, it
        size = 0.0
        for j in range(6):
            size = max(size, abs(dx[j]))
        if not size < prev:  # not contracting (or NaN): not in Newton's basin, hand over
            return False, it
        prev = size
        for i in range(3):
            u[i] += dx[i]
            dw[i] = dx[3 + i] / lc
        kern._rotate(q, dw, q_new, m33)
        for i in range(3):
            for j in range(3):
                q[i, j] = q_new[i, j]
        if size <= xtol:  # the final pose's wrench and Jacobian (slack_margin continues from them)
            kern.assemble_model(top, plat, l0, kw, weight, com, ploc, load, u, q, w, kmat, lengths, tensions,
                                True, bilateral, m33, v3)
            return True, it
    return False, max_iter


@njit(cache=True)
def chord_solve(top, plat, l0, kw, weight, com, ploc, load, u, q, c0, xtol, lc, max_iter, w, kmat, lengths,
                tensions, dx, q_new, dw, m33, v3):
    """Chord (simplified Newton) iterations on (u, q) in place: dx = C0·w with the rest pose's compliance C0,
    so each iteration costs one wrench and no Jacobian or solve. Each step must be less than half the one before
    (a load that changes K much, e.g. a wire going slack, fails this at once); converged when the step, or the
    error left after it at the observed rate, is below xtol. Returns (converged, iterations)."""
    prev = 1e300
    for it in range(1, max_iter + 1):
        kern.assemble_model(top, plat, l0, kw, weight, com, ploc, load, u, q, w, kmat, lengths, tensions, False,
                            False, m33, v3)
        size = 0.0
        for i in range(6):
            acc = 0.0
            for j in range(6):
                acc += c0[i, j] * w[j]
            dx[i] = acc
            size = max(size, abs(acc) if i < 3 else abs(acc) * lc)
        if not size < 0.5 * prev:
            return False, it
        # Linear convergence at the rate size/prev: what remains after this step is about size²/(prev − size).
        done = size <= xtol or (it > 1 and size * size <= xtol * (prev - size))
        prev = size
        for i in range(3):
            u[i] += dx[i]
            dw[i] = dx[3 + i]
        kern._rotate(q, dw, q_new, m33)
        for i in range(3):
            for j in range(3):
                q[i, j] = q_new[i, j]
        if done:
            kern.assemble_model(top, plat, l0, kw, weight, com, ploc, load, u, q, w, kmat, lengths, tensions,
                                False, False, m33, v3)
            return True, it
    return False, max_iter


@njit(cache=True)
def _predict(loads, c, c0, rp0, u0, q0, u, q, b, dw, m33):
    """Linear predictor from the rest pose: x = C0·[F; M + rp0 × F] with C0 = K0⁻¹ (6, 6)."""
    f0 = loads[c, 0]
    f1 = loads[c, 1]
    f2 = loads[c, 2]
    b[0] = f0
    b[1] = f1
    b[2] = f2
    b[3] = loads[c, 3] + rp0[1] * f2 - rp0[2] * f1
    b[4] = loads[c, 4] + rp0[2] * f0 - rp0[0] * f2
    b[5] = loads[c, 5] + rp0[0] * f1 - rp0[1] * f0
    for i in range(6):
        acc = 0.0
        for j in range(6):
            acc += c0[i, j] * b[j]
        if i < 3:
            u[i] = u0[i] + acc
        else:
            dw[i - 3] = acc
    kern._rotate(q0, dw, q, m33)


@njit(cache=True)
def continuation_path(top, plat, l0, kw, weight, com, ploc, load, u, q, xtol, max_iter, lc, max_move, min_cos_turn,
                      max_shift, lengths, tensions, w, max_steps, min_fraction):
    """Load continuation from the equilibrium (u, q) under no load to ``load``, in place: the compiled twin of
    equilibrium._continuation (steps doubled after a success, halved after a failure, down to min_fraction).
    Returns (status, iterations): CONVERGED, or the last step's failure when the path ends."""
    lam = 0.0
    step = 1.0
    iters = 0
    target_load = np.empty(6)
    for _ in range(max_steps):
        target = min(1.0, lam + step)
        for i in range(6):
            target_load[i] = target * load[i]
        st, it = kern.solve_step(top, plat, l0, kw, weight, com, ploc, target_load, u, q, xtol, max_iter, lc,
                                 max_move, min_cos_turn, max_shift, lengths, tensions, w)
        iters += it
        if st == kern.CONVERGED:
            lam = target
            if lam >= 1.0:
                return kern.CONVERGED, iters
            step = min(2.0 * step, 1.0 - lam)
        else:
            step *= 0.5
            if step < min_fraction:
                return st, iters
    return kern.MAX_ITERATIONS, iters


@njit(parallel=True, cache=True)
def batch_solve_parallel(top, plat, l0, kw, weight, com, ploc, loads, u0, q0, c0, xtol, max_iter, lc, max_move,
                         min_cos_turn, max_shift, max_steps, min_fraction, chunks, u_out, q_out, lengths_out,
                         tensions_out, w_out, status_out, iters_out):
    """Equilibria of every row of loads (N, 6) from the rest pose (u0, q0), split into ``chunks`` blocks run in
    parallel. c0 = K0⁻¹ (6, 6) at rest. Cases the fast path cannot take go to the robust damped Newton, then to
    load continuation (max_steps steps, down to min_fraction of the load). status_out: CONVERGED, or the status
    where the path ended (the caller then lets solve_equilibrium say why)."""
    n = loads.shape[0]
    rp0 = np.empty(3)
    for i in range(3):
        rp0[i] = q0[i, 0] * ploc[0] + q0[i, 1] * ploc[1] + q0[i, 2] * ploc[2]
    for ch in prange(chunks):
        lo = ch * n // chunks
        hi = (ch + 1) * n // chunks
        u = np.empty(3)
        q = np.empty((3, 3))
        w = np.empty(6)
        kmat = np.empty((6, 6))
        lengths = np.empty(6)
        tensions = np.empty(6)
        ks = np.empty((6, 6))
        rhs = np.empty(6)
        dx = np.empty(6)
        m = np.empty((6, 6))
        y = np.empty(6)
        b = np.empty(6)
        q_new = np.empty((3, 3))
        dw = np.empty(3)
        m33 = np.empty((3, 3, 3))
        v3 = np.empty((4, 3))
        for c in range(lo, hi):
            load = loads[c]
            _predict(loads, c, c0, rp0, u0, q0, u, q, b, dw, m33)
            ok, it = chord_solve(top, plat, l0, kw, weight, com, ploc, load, u, q, c0, xtol, lc, CHORD_MAX_ITER,
                                 w, kmat, lengths, tensions, dx, q_new, dw, m33, v3)
            if not ok:
                _predict(loads, c, c0, rp0, u0, q0, u, q, b, dw, m33)
                ok, it2 = newton_plain(top, plat, l0, kw, weight, com, ploc, load, u, q, xtol, lc, FAST_MAX_ITER,
                                       False, w, kmat, lengths, tensions, ks, rhs, dx, m, y, q_new, dw, m33, v3)
                it += it2
            if ok:
                tr = 0.0
                for i in range(3):
                    for j in range(3):
                        tr += q[i, j] * q0[i, j]
                shift = math.sqrt((u[0] - u0[0]) ** 2 + (u[1] - u0[1]) ** 2 + (u[2] - u0[2]) ** 2)
                ok = 0.5 * (tr - 1.0) >= min_cos_turn and shift <= max_shift
            st = kern.CONVERGED
            if not ok:  # the robust damped Newton from the rest pose, as solve_batch does
                for i in range(3):
                    u[i] = u0[i]
                    for j in range(3):
                        q[i, j] = q0[i, j]
                st, it2 = kern.solve_step(top, plat, l0, kw, weight, com, ploc, load, u, q, xtol, max_iter, lc,
                                          max_move, min_cos_turn, max_shift, lengths, tensions, w)
                it += it2
                if st != kern.CONVERGED:  # load continuation, as solve_equilibrium does next
                    st, it2 = continuation_path(top, plat, l0, kw, weight, com, ploc, load, u, q, xtol, max_iter,
                                                lc, max_move, min_cos_turn, max_shift, lengths, tensions, w,
                                                max_steps, min_fraction)
                    it += it2
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
