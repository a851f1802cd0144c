"""Independent reference model of the NIST six-wire robot crane (quasi-static, nonlinear).

Written from the paper (Dagalakis et al., "Stiffness study of a parallel link robot crane for shipbuilding
applications") and its corrections (docs/physics.md) only.  It deliberately shares no code with the
``crane_stiffness`` package: it imports numpy, scipy, the standard library and its own rotations
(independent_rotation.py) and nothing else, so that the agreement test in ``test_independent_agreement.py``
compares two implementations written apart.

Conventions (paper frame of Fig. 3, z pointing DOWN, SI units)
-------------------------------------------------------------
* Overhead vertices A(-b, -b*sqrt3/3, -h), B(b, -b*sqrt3/3, -h), C(0, 2b*sqrt3/3, -h).
* Platform vertices in the body frame D(0, -2a*sqrt3/3, 0), E(a, a*sqrt3/3, 0), F(-a, a*sqrt3/3, 0).
* Wires 1..6 = AD, BD, BE, CE, CF, AF; unstretched length l0 = sqrt(h^2 + 4(a^2+b^2-ab)/3), plus optional
  per-wire offsets.  One wire stiffness k for all wires (given, or E*pi*d^2/4 / l0 with the nominal l0); an
  optional per-wire k_i = E*pi*d^2/4 / l0_i (``make_crane(..., per_wire_stiffness=True)``) for comparison.
* Pose: platform-centre displacement u from the unloaded rest position (the origin) and
  Q = Rz(phi) Rx(theta) Ry(psi) (body -> fixed, intrinsic z-x-y); Q ~ I + [w]x with w = (theta, psi, phi).
* l_i = top_i - (u + Q p_i); tension t_i = k(|l_i| - l0_i) if |l_i| >= l0_i else 0; f_i = t_i l_i/|l_i|.
* Net wrench on the platform (moments about the platform centre):
      force  = sum f_i + (0, 0, W) + F
      moment = sum (Q p_i) x f_i + (Q c) x (0, 0, W) + (Q p) x F + M
  with c the centre-of-mass offset and p the load point, both in the body frame; F and M in the fixed frame.

Formulation (chosen to differ from a Newton iteration on SO(3))
----------------------------------------------------------------
* Unknowns are six numbers x = (u_x, u_y, u_z, phi, theta, psi): Euler angles, not a rotation increment.
* Equilibrium: ``scipy.optimize.root`` (MINPACK hybrd) on the six wrench components as functions of x,
  inside a load continuation: first the centre-of-mass offset and the length offsets are ramped in from the
  symmetric pose under weight alone (whose drop h_w - h comes from the 1-D balance solved by ``brentq``), then
  F and M are ramped in.  Steps adapt: a step is accepted only if the solver converges, the pose moves little
  and the equilibrium stays stable (symmetric part of the tangent stiffness positive definite).  A final
  polish does Newton steps in Euler coordinates while the residual keeps falling.
* Tangent stiffness K = -dw/dx with rotations perturbed in the FIXED frame (Q -> (I + [dw]x) Q), F and M
  fixed in space, derived by hand (see ``tangent_stiffness``); the Euler-coordinate Jacobian used by the solver
  is K times the Euler-rate -> fixed-frame angular-velocity map.  ``tangent_stiffness_fd`` is a central-
  difference (Richardson-extrapolated) version with exact (Rodrigues) rotation perturbations for checking.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.optimize import brentq, root

# test/ is on sys.path wherever this module is imported from (the tests, helpers/independent_cases.py)
from independent_rotation import (cross, euler_rate_map, euler_zxy, rodrigues, rot_x, rot_y, rot_z,  # noqa: F401
                                  rot_zxy, skew)

SQRT3 = math.sqrt(3.0)

# Laboratory model of the paper: a = b = 114.3 mm, steel wire d = 1.08 mm, E = 206,831e6 N/m^2.
LAB_A = 0.1143
LAB_B = 0.1143
LAB_WIRE_DIAMETER = 1.08e-3
LAB_YOUNGS_MODULUS = 206831e6


class NoEquilibrium(RuntimeError):
    """The load cannot be reached by continuous loading from the pose under weight alone."""


# ----------------------------------------------------------------------------------------------------------
# Geometry
# ----------------------------------------------------------------------------------------------------------

def overhead_points(b: float, h: float) -> np.ndarray:
    """Overhead end of wires 1..6 (A, B, B, C, C, A), fixed frame, shape (6, 3)."""
    A = (-b, -b * SQRT3 / 3.0, -h)
    B = (b, -b * SQRT3 / 3.0, -h)
    C = (0.0, 2.0 * b * SQRT3 / 3.0, -h)
    return np.array([A, B, B, C, C, A], dtype=float)


def platform_points(a: float) -> np.ndarray:
    """Platform end of wires 1..6 (D, D, E, E, F, F), body frame, shape (6, 3)."""
    D = (0.0, -2.0 * a * SQRT3 / 3.0, 0.0)
    E = (a, a * SQRT3 / 3.0, 0.0)
    F = (-a, a * SQRT3 / 3.0, 0.0)
    return np.array([D, D, E, E, F, F], dtype=float)


def nominal_l0(a: float, b: float, h: float) -> float:
    return math.sqrt(h * h + 4.0 * (a * a + b * b - a * b) / 3.0)


@dataclass(frozen=True)
class Crane:
    a: float
    b: float
    h: float
    k: float
    weight: float
    com: np.ndarray = field(default_factory=lambda: np.zeros(3))
    length_offsets: np.ndarray = field(default_factory=lambda: np.zeros(6))
    k_wires: np.ndarray | None = None  # per-wire stiffness; None: k for every wire (the model of the brief)

    @property
    def kw(self) -> np.ndarray:
        return np.full(6, self.k) if self.k_wires is None else np.asarray(self.k_wires, dtype=float)

    @property
    def l0_nominal(self) -> float:
        return nominal_l0(self.a, self.b, self.h)

    @property
    def l0(self) -> np.ndarray:
        return self.l0_nominal + np.asarray(self.length_offsets, dtype=float)

    @property
    def top(self) -> np.ndarray:
        return overhead_points(self.b, self.h)

    @property
    def body(self) -> np.ndarray:
        return platform_points(self.a)


def make_crane(a, b, h, weight, *, k=None, wire_diameter=None, youngs_modulus=None, com=None,
               length_offsets=None, per_wire_stiffness=False) -> Crane:
    """Crane from the CLI-style parameters: either k, or (wire_diameter, youngs_modulus) -> k = E A / l0.

    By default k uses the nominal l0 and is the same for all wires, as the brief specifies.  With
    per_wire_stiffness=True (only meaningful with wire_diameter/youngs_modulus and length offsets) wire i gets
    E A / l0_i instead: an alternative reading, kept so the two can be compared.
    """
    offsets = np.zeros(6) if length_offsets is None else np.asarray(length_offsets, dtype=float).copy()
    k_wires = None
    if k is None:
        if wire_diameter is None or youngs_modulus is None:
            raise ValueError("give k, or wire_diameter and youngs_modulus")
        EA = youngs_modulus * math.pi * wire_diameter ** 2 / 4.0
        k = EA / nominal_l0(a, b, h)
        if per_wire_stiffness:
            k_wires = EA / (nominal_l0(a, b, h) + offsets)
    return Crane(float(a), float(b), float(h), float(k), float(weight),
                 np.zeros(3) if com is None else np.asarray(com, dtype=float).copy(), offsets, k_wires)


def lab_crane(h, weight, **kw) -> Crane:
    return make_crane(LAB_A, LAB_B, h, weight, wire_diameter=LAB_WIRE_DIAMETER,
                      youngs_modulus=LAB_YOUNGS_MODULUS, **kw)


# ----------------------------------------------------------------------------------------------------------
# Statics
# ----------------------------------------------------------------------------------------------------------

@dataclass
class WireState:
    vectors: np.ndarray  # (6, 3), platform vertex -> overhead vertex
    lengths: np.ndarray  # (6,)
    tensions: np.ndarray  # (6,)
    slack: np.ndarray  # (6,) bool
    forces: np.ndarray  # (6, 3) force of each wire on the platform
    arms: np.ndarray  # (6, 3) Q p_i


def wire_state(crane: Crane, u, Q) -> WireState:
    u = np.asarray(u, dtype=float)
    Q = np.asarray(Q, dtype=float)
    arms = crane.body @ Q.T
    vec = crane.top - (u + arms)
    L = np.sqrt(np.einsum("ij,ij->i", vec, vec))
    l0 = crane.l0
    slack = L < l0
    t = np.where(slack, 0.0, crane.kw * (L - l0))
    forces = (t / L)[:, None] * vec
    return WireState(vec, L, t, slack, forces, arms)


def net_wrench(crane: Crane, u, Q, force=(0, 0, 0), moment=(0, 0, 0), load_point=(0, 0, 0)) -> np.ndarray:
    """Net force and moment (about the platform centre) on the platform, fixed frame, shape (6,)."""
    Q = np.asarray(Q, dtype=float)
    ws = wire_state(crane, u, Q)
    Fext = np.asarray(force, dtype=float)
    gravity = np.array([0.0, 0.0, crane.weight])
    f = ws.forces.sum(axis=0) + gravity + Fext
    m = (cross(ws.arms, ws.forces).sum(axis=0) + cross(Q @ crane.com, gravity)
         + cross(Q @ np.asarray(load_point, dtype=float), Fext) + np.asarray(moment, dtype=float))
    return np.concatenate([f, m])


def tangent_stiffness(crane: Crane, u, Q, force=(0, 0, 0), load_point=(0, 0, 0)) -> np.ndarray:
    """K = -dw/dx, x = (u, fixed-frame rotation increment), F and M held fixed in space.

    Derivation.  With r_i = Q p_i, a fixed-frame rotation increment dw moves r_i by dw x r_i = -[r_i]x dw, so
    dl_i = -du + [r_i]x dw.  For a taut wire f_i = t_i n_i, n_i = l_i/|l_i|, df_i = G_i dl_i with
    G_i = k n n^T + (t_i/|l_i|)(I - n n^T) (zero when slack).  Hence
        d(sum f_i)          = -G_i du + G_i [r_i]x dw
        d(r_i x f_i)        = [r_i]x df_i + (dw x r_i) x f_i = [r_i]x df_i + [f_i]x [r_i]x dw
        d((Q c) x w_g)      = [w_g]x [r_c]x dw      (w_g = (0, 0, W), r_c = Q c)
        d((Q p) x F)        = [F]x [r_p]x dw        (r_p = Q p; this is the only place F enters K)
    and K is minus the sum.
    """
    Q = np.asarray(Q, dtype=float)
    ws = wire_state(crane, u, Q)
    n = ws.vectors / ws.lengths[:, None]
    nn = n[:, :, None] * n[:, None, :]
    taut = (~ws.slack)[:, None, None]
    G = np.where(taut, crane.kw[:, None, None] * nn + (ws.tensions / ws.lengths)[:, None, None] * (np.eye(3) - nn), 0.0)
    R = np.array([skew(r) for r in ws.arms])
    Fx = np.array([skew(f) for f in ws.forces])
    GR = G @ R
    K = np.zeros((6, 6))
    K[:3, :3] = G.sum(axis=0)
    K[:3, 3:] = -GR.sum(axis=0)
    K[3:, :3] = (R @ G).sum(axis=0)
    K[3:, 3:] = -(R @ GR).sum(axis=0) - (Fx @ R).sum(axis=0)
    wg = np.array([0.0, 0.0, crane.weight])
    K[3:, 3:] -= skew(wg) @ skew(Q @ crane.com)
    F = np.asarray(force, dtype=float)
    K[3:, 3:] -= skew(F) @ skew(Q @ np.asarray(load_point, dtype=float))
    return K


def tangent_stiffness_fd(crane: Crane, u, Q, force=(0, 0, 0), moment=(0, 0, 0), load_point=(0, 0, 0),
                         step_length=None) -> np.ndarray:
    """-dw/dx by central differences (Richardson-extrapolated), rotations Q -> exp([dw]x) Q.

    step_length is the largest displacement of any attachment point per step; it should stay well below the
    distance of every wire from its slack threshold.
    """
    u = np.asarray(u, dtype=float)
    Q = np.asarray(Q, dtype=float)
    if step_length is None:
        step_length = 1e-5 * crane.l0_nominal
    rmax = max(np.linalg.norm(crane.body, axis=1).max(), np.linalg.norm(load_point), np.linalg.norm(crane.com),
               1e-3)

    def w(dx):
        return net_wrench(crane, u + dx[:3], rodrigues(dx[3:]) @ Q, force, moment, load_point)

    K = np.zeros((6, 6))
    for j in range(6):
        hj = step_length if j < 3 else step_length / rmax
        e = np.zeros(6)

        def central(hh):
            e[:] = 0.0
            e[j] = hh
            return (w(e) - w(-e)) / (2.0 * hh)

        K[:, j] = -(4.0 * central(hj / 2.0) - central(hj)) / 3.0
    return K


def potential_energy(crane: Crane, u, Q, force=(0, 0, 0), load_point=(0, 0, 0)) -> float:
    """Total potential (wires + gravity + a force F fixed in space applied at load_point).

    Only the conservative loads: the net force/moment of ``net_wrench`` (with M = 0) is minus its gradient.
    """
    ws = wire_state(crane, u, Q)
    stretch = np.maximum(ws.lengths - crane.l0, 0.0)
    elastic = 0.5 * float(crane.kw @ (stretch * stretch))
    u = np.asarray(u, dtype=float)
    Q = np.asarray(Q, dtype=float)
    gravity = -crane.weight * float((u + Q @ crane.com)[2])
    external = -float(np.asarray(force, dtype=float) @ (u + Q @ np.asarray(load_point, dtype=float)))
    return elastic + gravity + external


# ----------------------------------------------------------------------------------------------------------
# Paper eq. (18)
# ----------------------------------------------------------------------------------------------------------

def weighted_height(a, b, h, k, weight) -> float:
    """h_w solving 6 k (l_w - l0) h_w / l_w = W, l_w = sqrt(h_w^2 + 4(a^2+b^2-ab)/3), h_w >= h."""
    s2 = 4.0 * (a * a + b * b - a * b) / 3.0
    l0 = math.sqrt(h * h + s2)
    if weight == 0:
        return h

    def g(hw):
        lw = math.sqrt(hw * hw + s2)
        return 6.0 * k * (lw - l0) * hw / lw - weight

    # On [h, hi] g rises from -W; l_w - l0 <= W l0 / (6 k h) bounds the root.
    hi = l0 + weight * l0 / (6.0 * k * h) + h
    hw = brentq(g, h, hi, xtol=1e-300, rtol=4 * np.finfo(float).eps, maxiter=500)
    # one Newton polish step (g is smooth and monotone there)
    for _ in range(2):
        lw = math.sqrt(hw * hw + s2)
        dg = 6.0 * k * ((1.0 - l0 / lw) + l0 * hw * hw / lw ** 3)
        hw = hw - g(hw) / dg
    return hw


def paper_stiffness(a, b, h, k, weight) -> np.ndarray:
    """Linearized stiffness of eq. (18) with h_w from the implicit vertical balance (docs/physics.md)."""
    l0 = nominal_l0(a, b, h)
    hw = weighted_height(a, b, h, k, weight)
    lw = math.sqrt(hw * hw + 4.0 * (a * a + b * b - a * b) / 3.0)
    c = l0 / lw ** 3
    W = weight
    K1 = 4 * k * (a * a + b * b - a * b) * c + W / hw
    K2 = 2 * k * a * (2 * a - b) * hw * c
    K3 = 6 * k * hw * hw * c + W / hw
    K4 = 4 * k * a * a * hw * hw * c + a * b * W / (3 * hw)
    K5 = 8 * k * a * a * b * b * c + a * b * 2 * W / (3 * hw)
    K = np.zeros((6, 6))
    K[0, 0] = K[1, 1] = K1
    K[2, 2] = K3
    K[3, 3] = K[4, 4] = K4
    K[5, 5] = K5
    K[0, 4] = K[4, 0] = -K2
    K[1, 3] = K[3, 1] = K2
    return K


# ----------------------------------------------------------------------------------------------------------
# Equilibrium
# ----------------------------------------------------------------------------------------------------------

@dataclass
class Equilibrium:
    displacement: np.ndarray
    rotation: np.ndarray
    euler_zxy: np.ndarray
    wire_lengths: np.ndarray
    wire_tensions: np.ndarray
    slack: np.ndarray
    residual: np.ndarray
    continuation_steps: int

    @property
    def rotation_angle(self) -> float:
        return float(math.acos(max(-1.0, min(1.0, (np.trace(self.rotation) - 1.0) / 2.0))))


def _pose(x):
    return x[:3], rot_zxy(x[3], x[4], x[5])


def _euler_jacobian(crane, x, force, load_point):
    u, Q = _pose(x)
    K = tangent_stiffness(crane, u, Q, force, load_point)
    T = np.eye(6)
    T[3:, 3:] = euler_rate_map(x[3], x[4])
    return -K @ T


def _scales(crane, force, moment):
    fscale = crane.weight + float(np.linalg.norm(force)) + float(np.linalg.norm(moment)) / max(crane.a, 1e-3)
    lscale = max(crane.a, crane.b)
    return fscale, lscale


def _stable(crane, x, force, load_point):
    """No real eigenvalue of the (scaled) tangent stiffness has crossed zero: the path has not passed a fold.

    For conservative loads K is symmetric and this is positive definiteness; an external couple fixed in space
    makes K slightly non-symmetric, so the eigenvalues' real parts are used.
    """
    u, Q = _pose(x)
    K = tangent_stiffness(crane, u, Q, force, load_point)
    d = np.r_[np.ones(3), np.full(3, 1.0 / max(crane.a, crane.b))]
    ev = np.linalg.eigvals(d[:, None] * K * d[None, :])
    return ev.real.min() > 1e-12 * np.abs(ev).max()


def _corrector(crane, x0, force, moment, load_point):
    def fun(x):
        return net_wrench(crane, *_pose(x), force, moment, load_point)

    def jac(x):
        return _euler_jacobian(crane, x, force, load_point)
    sol = root(fun, x0, jac=jac, method="hybr", options={"xtol": 1e-9, "maxfev": 400})
    x = sol.x
    r = fun(x)
    # Newton polish in Euler coordinates while the residual keeps falling.
    for _ in range(20):
        try:
            dx = np.linalg.solve(jac(x), -r)
        except np.linalg.LinAlgError:
            break
        xn = x + dx
        rn = fun(xn)
        if np.linalg.norm(rn) < np.linalg.norm(r):
            x, r = xn, rn
        else:
            break
    return x, r


def _continue(crane_of, load_of, x, *, max_step_rot=0.03, max_steps=4000):
    """Follow the equilibrium from s = 0 (x known) to s = 1; crane_of(s), load_of(s) -> (F, M, p)."""
    s, ds, steps = 0.0, 0.125, 0
    x_prev, s_prev_step = None, 1.0
    while s < 1.0:
        steps += 1
        if steps > max_steps:
            raise NoEquilibrium(f"continuation did not finish in {max_steps} steps (at s = {s:.6g})")
        s_new = min(1.0, s + ds)
        crane = crane_of(s_new)
        force, moment, p = load_of(s_new)
        fscale, lscale = _scales(crane, force, moment)
        # secant predictor
        guess = x if x_prev is None else x + (x - x_prev) * (s_new - s) / s_prev_step
        ok = False
        try:
            xn, r = _corrector(crane, guess, force, moment, p)
            ok = (np.all(np.isfinite(xn))
                  and np.linalg.norm(r[:3]) <= 1e-9 * fscale
                  and np.linalg.norm(r[3:]) <= 1e-9 * fscale * lscale
                  and np.linalg.norm(xn[:3] - x[:3]) <= 0.05 * crane.l0_nominal
                  and np.abs(xn[3:] - x[3:]).max() <= max_step_rot
                  and _below_overhead(crane, xn)
                  and _stable(crane, xn, force, p))
        except (np.linalg.LinAlgError, ValueError, FloatingPointError):
            ok = False
        if ok:
            x_prev, x, s_prev_step, s = x, xn, s_new - s, s_new
            ds = min(0.25, ds * 1.5)
        else:
            ds *= 0.5
            if ds < 1e-6:
                raise NoEquilibrium(f"no equilibrium reachable by continuous loading beyond s = {s:.6g}")
    return x, steps


def _below_overhead(crane, x):
    u, Q = _pose(x)
    pts = u + crane.body @ Q.T
    return bool(np.all(pts[:, 2] > -crane.h + 1e-9 * crane.h))


def solve(crane: Crane, force=(0, 0, 0), moment=(0, 0, 0), load_point=(0, 0, 0), *,
          max_steps=4000) -> Equilibrium:
    """Equilibrium reached by loading continuously from the pose under weight alone.

    max_steps bounds the continuation steps (accepted and rejected) of each stage; NoEquilibrium beyond it.
    """
    if crane.weight <= 0:
        raise ValueError("weight must be positive")
    force = np.asarray(force, dtype=float)
    moment = np.asarray(moment, dtype=float)
    load_point = np.asarray(load_point, dtype=float)
    hw = weighted_height(crane.a, crane.b, crane.h, crane.k, crane.weight)
    x = np.array([0.0, 0.0, hw - crane.h, 0.0, 0.0, 0.0])
    zero3 = np.zeros(3)
    steps = 0
    # Stage 1: ramp in the centre-of-mass offset and the wire length offsets under weight alone.
    if np.any(crane.com != 0) or np.any(crane.length_offsets != 0) or crane.k_wires is not None:
        base = replace(crane, com=np.zeros(3), length_offsets=np.zeros(6), k_wires=None)
        x, n = _continue(lambda s: replace(base, com=s * crane.com, length_offsets=s * crane.length_offsets,
                                           k_wires=crane.k + s * (crane.kw - crane.k)),
                         lambda s: (zero3, zero3, load_point), x,
                         max_steps=max_steps)
        steps += n
    # Stage 2: ramp in the external force and moment.
    if np.any(force != 0) or np.any(moment != 0):
        x, n = _continue(lambda s: crane, lambda s: (s * force, s * moment, load_point), x,
                         max_steps=max_steps)
        steps += n
    else:
        x, r = _corrector(crane, x, zero3, zero3, load_point)
    u, Q = _pose(x)
    r = net_wrench(crane, u, Q, force, moment, load_point)
    fscale, lscale = _scales(crane, force, moment)
    if np.linalg.norm(r[:3]) > 1e-9 * fscale or np.linalg.norm(r[3:]) > 1e-9 * fscale * lscale:
        raise NoEquilibrium("equilibrium solve did not converge")
    ws = wire_state(crane, u, Q)
    return Equilibrium(u.copy(), Q, euler_zxy(Q), ws.lengths, ws.tensions, ws.slack, r, steps)
