"""Compiled kernels of the design questions at a pose: the inverse problem, slack margins, whole maps.

- :func:`inverse_tensions`: the wire tensions that hold the platform in equilibrium at a given pose under its weight
  (six wires, six balance equations: one linear solve), and from them the unstretched lengths that put it there.
- :func:`slack_margin`: the smallest magnitude s of a load s·d (d a unit force or moment direction) at which a wire
  goes slack, loading quasi-statically from an equilibrium: predictor–corrector continuation on the load with
  Newton's method on s for the onset, on the nonlinear model.
- :func:`map_points`: both for many (geometry, pose) points in parallel.

The balance is :func:`crane_stiffness.model._kernels.assemble_model` (the one implementation); the continuation
uses its ``bilateral`` form (wires that may push), which equals the real model up to the first slack onset and is
smooth through it, so Newton's method locates the onset to rounding error. Frames and units as in
:mod:`._kernels`: fixed frame, z down, m, rad, N, N·m.
"""
from __future__ import annotations

import math

import numpy as np

from crane_stiffness.model import _kernels as kern
from crane_stiffness.model._batch_kernels import newton_plain
from crane_stiffness.model._kernels import njit, prange, solve6_into

# slack_margin status codes
FOUND = 0          # a wire goes slack at the margin returned
NONE = 1           # no wire slack up to the cap: margin inf
LIMIT_POINT = 2    # the platform loses equilibrium (swings or twists away) before any wire goes slack
SLACK_AT_START = 3  # a wire is slack (or at zero tension) already: margin 0
# inverse_tensions / map_points status codes
REACHABLE = 0
UNREACHABLE = 1    # a wire would need zero or negative tension (it cannot push)
SINGULAR = 2       # the wires' lines of action are degenerate at this pose

#: Largest predicted motion of one continuation step: a share of the wire length and an angle [rad].
STEP_SHARE = 0.02
STEP_TURN = 0.05
#: Newton iterations per corrector and continuation iterations per margin.
CORRECTOR_ITER = 30
MARGIN_ITER = 200


@njit(cache=True)
def inverse_tensions(top, plat, weight, com, u, q, lengths, tensions, am, rhs, m, y):
    """Tensions (6,) [N] that balance the weight W (at body offset com (3,)) at the pose (u (3,), q (3, 3)).

    Column n of the 6×6 system is the unit wrench of wire n, [e_n; r_n × e_n]; fills lengths (6,) [m].
    Returns REACHABLE, UNREACHABLE (some tension <= 0) or SINGULAR."""
    for n in range(6):
        r0 = q[0, 0] * plat[n, 0] + q[0, 1] * plat[n, 1] + q[0, 2] * plat[n, 2]
        r1 = q[1, 0] * plat[n, 0] + q[1, 1] * plat[n, 1] + q[1, 2] * plat[n, 2]
        r2 = q[2, 0] * plat[n, 0] + q[2, 1] * plat[n, 1] + q[2, 2] * plat[n, 2]
        lx = top[n, 0] - u[0] - r0
        ly = top[n, 1] - u[1] - r1
        lz = top[n, 2] - u[2] - r2
        length = math.sqrt(lx * lx + ly * ly + lz * lz)
        lengths[n] = length
        e0 = lx / length
        e1 = ly / length
        e2 = lz / length
        am[0, n] = e0
        am[1, n] = e1
        am[2, n] = e2
        am[3, n] = r1 * e2 - r2 * e1
        am[4, n] = r2 * e0 - r0 * e2
        am[5, n] = r0 * e1 - r1 * e0
    rc0 = q[0, 0] * com[0] + q[0, 1] * com[1] + q[0, 2] * com[2]
    rc1 = q[1, 0] * com[0] + q[1, 1] * com[1] + q[1, 2] * com[2]
    rhs[0] = 0.0
    rhs[1] = 0.0
    rhs[2] = -weight
    rhs[3] = -rc1 * weight
    rhs[4] = rc0 * weight
    rhs[5] = 0.0
    if not solve6_into(am, rhs, tensions, m, y):
        return SINGULAR
    for n in range(6):
        if not tensions[n] > 0.0:
            return UNREACHABLE
    return REACHABLE


@njit(cache=True)
def wire_lengths_for(lengths, tensions, ae, k, l0, kw):
    """Unstretched lengths l0 (6,) and stiffnesses kw (6,) giving these tensions at these lengths: with a wire
    material (ae = A·E > 0 [N]) k_n = AE/l0_n, so l0_n = AE·L_n/(t_n + AE); otherwise k_n = k and l0_n = L_n − t_n/k."""
    for n in range(6):
        if ae > 0.0:
            l0[n] = ae * lengths[n] / (tensions[n] + ae)
            kw[n] = ae / l0[n]
        else:
            l0[n] = lengths[n] - tensions[n] / k
            kw[n] = k


@njit(cache=True)
def _rates(top, plat, q, u, v, lengths, rates):
    """dL_n/ds = −(e_n·du + (r_n × e_n)·dω) for the path tangent v = [du; dω] (6,)."""
    for n in range(6):
        r0 = q[0, 0] * plat[n, 0] + q[0, 1] * plat[n, 1] + q[0, 2] * plat[n, 2]
        r1 = q[1, 0] * plat[n, 0] + q[1, 1] * plat[n, 1] + q[1, 2] * plat[n, 2]
        r2 = q[2, 0] * plat[n, 0] + q[2, 1] * plat[n, 1] + q[2, 2] * plat[n, 2]
        e0 = (top[n, 0] - u[0] - r0) / lengths[n]
        e1 = (top[n, 1] - u[1] - r1) / lengths[n]
        e2 = (top[n, 2] - u[2] - r2) / lengths[n]
        rates[n] = -(e0 * v[0] + e1 * v[1] + e2 * v[2] + (r1 * e2 - r2 * e1) * v[3] + (r2 * e0 - r0 * e2) * v[4]
                     + (r0 * e1 - r1 * e0) * v[5])


@njit(cache=True)
def slack_margin(top, plat, l0, kw, weight, com, ploc, u0, q0, d, s_max, rtol, xtol, lc, l_ref):
    """Smallest s >= 0 at which loading with s·d from the equilibrium (u0, q0) under no external load slackens a
    wire. d (6,) = [force [N] at body offset ploc; moment [N·m]] per unit of s, fixed frame.

    Returns (s, wire index or −1, status): FOUND, NONE (s = inf, nothing slack up to s_max), LIMIT_POINT (s = the
    load where the path ends) or SLACK_AT_START (s = 0). rtol: relative tolerance on s; xtol: pose tolerance of
    each corrector [m]; lc: length that scales rotations [m]; l_ref: length that bounds a step's motion [m]."""
    u = u0.copy()
    q = q0.copy()
    us = np.empty(3)
    qs = np.empty((3, 3))
    load = np.zeros(6)
    w = np.empty(6)
    kmat = np.empty((6, 6))
    lengths = np.empty(6)
    tensions = np.empty(6)
    ks = np.empty((6, 6))
    rhs = np.empty(6)
    dx = np.empty(6)
    m = np.empty((6, 6))
    y = np.empty(6)
    q_new = np.empty((3, 3))
    dw = np.empty(3)
    m33 = np.empty((3, 3, 3))
    v3 = np.empty((4, 3))
    b = np.empty(6)
    v = np.empty(6)
    rates = np.empty(6)
    s = 0.0
    s_lo = 0.0
    s_hi = math.inf
    for it in range(MARGIN_ITER):
        if it == 0:  # later iterations start from the corrector's last evaluation, at this very pose and load
            kern.assemble_model(top, plat, l0, kw, weight, com, ploc, load, u, q, w, kmat, lengths, tensions,
                                True, True, m33, v3)
        worst = math.inf
        for n in range(6):
            worst = min(worst, lengths[n] - l0[n])
        if it == 0 and worst <= 0.0:
            first = 0
            for n in range(6):
                if lengths[n] - l0[n] < lengths[first] - l0[first]:
                    first = n
            return 0.0, first, SLACK_AT_START
        if worst >= 0.0:
            s_lo = max(s_lo, s)
        else:
            s_hi = min(s_hi, s)
        # Path tangent v = dx/ds = K⁻¹ ∂w/∂s, solved in scaled units like the Newton steps.
        rp0 = q[0, 0] * ploc[0] + q[0, 1] * ploc[1] + q[0, 2] * ploc[2]
        rp1 = q[1, 0] * ploc[0] + q[1, 1] * ploc[1] + q[1, 2] * ploc[2]
        rp2 = q[2, 0] * ploc[0] + q[2, 1] * ploc[1] + q[2, 2] * ploc[2]
        b[0] = d[0]
        b[1] = d[1]
        b[2] = d[2]
        b[3] = d[3] + rp1 * d[2] - rp2 * d[1]
        b[4] = d[4] + rp2 * d[0] - rp0 * d[2]
        b[5] = d[5] + rp0 * d[1] - rp1 * d[0]
        for i in range(6):
            si = 1.0 if i < 3 else 1.0 / lc
            rhs[i] = b[i] * si
            for j in range(6):
                sj = 1.0 if j < 3 else 1.0 / lc
                ks[i, j] = kmat[i, j] * si * sj
        if not solve6_into(ks, rhs, v, m, y):
            return s, -1, LIMIT_POINT
        move = 0.0
        turn = 0.0
        for i in range(3):
            move = max(move, abs(v[i]))
            v[3 + i] /= lc
            turn = max(turn, abs(v[3 + i]))
        _rates(top, plat, q, u, v, lengths, rates)
        # Newton on s for each wire's stretch L_n − l0_n = 0 (those shortening); the earliest root is the onset.
        s_next = math.inf
        wire = -1
        for n in range(6):
            if rates[n] < 0.0:
                root = s - (lengths[n] - l0[n]) / rates[n]
                if root < s_next:
                    s_next = root
                    wire = n
        if wire >= 0 and abs(s_next - s) <= rtol * max(s, 1e-300) and worst > -1e-9 * l_ref:
            return s_next, wire, FOUND
        max_ds = math.inf
        if move > 0.0:
            max_ds = STEP_SHARE * l_ref / move
        if turn > 0.0:
            max_ds = min(max_ds, STEP_TURN / turn)
        if s_next > s + max_ds:
            s_next = s + max_ds
        if not (s_lo < s_next < s_hi) and s_hi < math.inf:
            s_next = 0.5 * (s_lo + s_hi)
        if s_next > s_max:
            if s >= s_max:
                return math.inf, -1, NONE
            s_next = s_max
        # Corrector: predict along the tangent, then Newton at the load s_next·d; halve the step when it fails.
        for i in range(3):
            us[i] = u[i]
            for j in range(3):
                qs[i, j] = q[i, j]
        for _ in range(60):
            ds = s_next - s
            for i in range(3):
                u[i] = us[i] + ds * v[i]
                dw[i] = ds * v[3 + i]
            kern._rotate(qs, dw, q, m33)
            for i in range(6):
                load[i] = s_next * d[i]
            ok, _ = newton_plain(top, plat, l0, kw, weight, com, ploc, load, u, q, xtol, lc, CORRECTOR_ITER, True,
                                 w, kmat, lengths, tensions, ks, rhs, dx, m, y, q_new, dw, m33, v3)
            if ok:
                break
            s_next = s + 0.5 * ds
            if abs(s_next - s) <= 1e-13 * max(abs(s), 1e-300):
                break
        if not ok:
            return s, -1, LIMIT_POINT
        s = s_next
    return s, -1, LIMIT_POINT


@njit(cache=True)
def _platform_pose(a, b, h):
    """Overhead points and platform points (6, 3) of wires AD, BD, BE, CE, CF, AF (geometry.py's layout)."""
    r3 = math.sqrt(3.0)
    abc = np.array([[-b, -b * r3 / 3, -h], [b, -b * r3 / 3, -h], [0.0, 2 * b * r3 / 3, -h]])
    dfe = np.array([[0.0, -2 * a * r3 / 3, 0.0], [a, a * r3 / 3, 0.0], [-a, a * r3 / 3, 0.0]])
    tops = (0, 1, 1, 2, 2, 0)
    plats = (0, 0, 1, 1, 2, 2)
    top = np.empty((6, 3))
    plat = np.empty((6, 3))
    for n in range(6):
        for i in range(3):
            top[n, i] = abc[tops[n], i]
            plat[n, i] = dfe[plats[n], i]
    return top, plat


@njit(parallel=True, cache=True)
def map_points(pa, pb, ph, pw, pcom, ppos, q, ae, k, ploc, dirs, cap, rtol, xtol, status, tensions, l0_out,
               kmats, margins, margin_wires, margin_status):
    """Every point p of a map in parallel: the inverse problem at the pose (ppos[p] (3,), q), the tangent K there,
    and the slack margin along every direction of dirs (m, 6).

    Per point: half sides pa, pb [m], height ph [m], weight pw [N], centre of mass pcom (P, 3) body frame [m].
    ae = A·E [N] (> 0: k per wire = AE/l0), else every wire has stiffness k [N/m]. A direction's cap is
    cap·W (forces) or cap·W·max(a, b) (moments). Unreachable points get status != REACHABLE and NaN outputs."""
    npts = pa.shape[0]
    ndir = dirs.shape[0]
    for p in prange(npts):
        top, plat = _platform_pose(pa[p], pb[p], ph[p])
        u = ppos[p].copy()
        com = pcom[p].copy()
        lengths = np.empty(6)
        t = np.empty(6)
        am = np.empty((6, 6))
        rhs = np.empty(6)
        mm = np.empty((6, 6))
        y = np.empty(6)
        st = inverse_tensions(top, plat, pw[p], com, u, q, lengths, t, am, rhs, mm, y)
        status[p] = st
        if st != REACHABLE:
            for n in range(6):
                tensions[p, n] = math.nan
                l0_out[p, n] = math.nan
            for i in range(6):
                for j in range(6):
                    kmats[p, i, j] = math.nan
            for c in range(ndir):
                margins[p, c] = math.nan
                margin_wires[p, c] = -1
                margin_status[p, c] = -1
            continue
        l0 = np.empty(6)
        kw = np.empty(6)
        wire_lengths_for(lengths, t, ae, k, l0, kw)
        w = np.empty(6)
        kmat = np.empty((6, 6))
        tt = np.empty(6)
        kern.assemble_model(top, plat, l0, kw, pw[p], com, ploc, np.zeros(6), u, q, w, kmat, lengths, tt, True,
                            False, np.empty((3, 3, 3)), np.empty((4, 3)))
        for n in range(6):
            tensions[p, n] = t[n]
            l0_out[p, n] = l0[n]
        for i in range(6):
            for j in range(6):
                kmats[p, i, j] = kmat[i, j]
        lc = max(pa[p], pb[p])
        l_ref = 0.0
        for n in range(6):
            l_ref = max(l_ref, l0[n])
        for c in range(ndir):
            is_force = dirs[c, 0] != 0.0 or dirs[c, 1] != 0.0 or dirs[c, 2] != 0.0
            s_max = cap * pw[p] * (1.0 if is_force else lc)
            s, wire, mst = slack_margin(top, plat, l0, kw, pw[p], com, ploc, u, q, dirs[c], s_max, rtol, xtol, lc,
                                        l_ref)
            margins[p, c] = s
            margin_wires[p, c] = wire
            margin_status[p, c] = mst
