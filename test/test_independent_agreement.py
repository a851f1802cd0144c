"""The ``crane-stiffness`` CLI against an independent reference implementation (``independent_crane.py``).

The reference was written from the paper and its corrections (docs/physics.md) without reading, importing or
copying anything from the ``crane_stiffness`` package.  The ``test_reference_*`` tests check the reference on its
own (finite differences, an energy formulation, the closed form of eq. 18); the ``test_cli_*`` tests run the CLI
as a subprocess and compare its JSON with the reference.

Done-when (from the issue): pose within 1e-9 m and 1e-9 rad, tensions within 1e-6 relative, stiffness within
1e-6 relative to the largest entry, on random geometries and loads with slack and rotated cases included.

Assumptions about the CLI contract (documented here because the contract leaves them open)
--------------------------------------------------------------------------------------
* ``wire_lengths`` are the geometric distances |l_i| between the attachment points (also for slack wires).
* ``slack[i]`` is ``|l_i| < l0_i``; a slack wire's tension is exactly 0.
* With ``--wire-diameter/--youngs-modulus`` each wire's stiffness is k_i = E*pi*d^2/4 / l0_i with its own
  unstretched length l0_i = l0 + d_i (a longer wire of the same cross-section is softer; with no offsets this is
  the paper's single k = E A / l0). ``--wire-stiffness`` gives the same k to every wire.
* ``tangent`` is -dw/dx of the NET wrench (wires + weight + external load), rotations perturbed in the fixed
  frame, F and M fixed in space.  The external force therefore contributes -[F]x[Q p]x to the moment block when
  a ``--load-point`` p is given (the moment arm of F turns with the platform); M contributes nothing.
* ``paper`` is eq. (18) as a formula of a, b, h, k and W (h_w from the implicit balance of docs/physics.md); it
  ignores ``--com``, ``--load-point`` and ``--length-offsets``.
* ``euler_zxy`` angles are compared modulo 2*pi (all cases here stay far from gimbal lock).
* ``wire_lengths`` are compared to 3e-9 m: a pose error of 1e-9 per component moves an attachment point by up to
  about that much.
* Numbers are passed in positional notation (``numpy.format_float_positional``, exact round trip), because
  Python 3.11's argparse takes an argument such as ``-1.5e-05`` for an option flag.
* The CLI is the console script in ``sysconfig.get_path('scripts')`` of the interpreter running the tests; the
  tests FAIL (not skip) when it is missing, so they cannot pass vacuously.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys
import sysconfig
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np
import pytest
from scipy.optimize import minimize

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import independent_crane as ic  # noqa: E402

POSE_TOL_M = 1e-9
POSE_TOL_RAD = 1e-9
LENGTH_TOL_M = 3e-9
TENSION_RTOL = 1e-6
STIFFNESS_RTOL = 1e-6

SEED = 20240611
N_RANDOM = 20
MIN_MARGIN = 1e-5  # every wire at least this fraction of l0 away from its slack threshold
MAX_ROTATION_DEG = 25.0
ROTATED_DEG = 2.0

LAB_D = 1.08e-3
LAB_E = 206831e6

# Wire stiffness with --wire-diameter/--youngs-modulus AND --length-offsets: k_i = E A / (l0 + d_i), the wire
# model of crane_stiffness.model.geometry (only the "combined_wire" case is affected by this choice).
PER_WIRE_K_FROM_E = True


# ----------------------------------------------------------------------------------------------------------
# Cases
# ----------------------------------------------------------------------------------------------------------

@dataclass
class Case:
    name: str
    a: float
    b: float
    h: float
    weight: float
    k: float | None = None  # --wire-stiffness
    wire: bool = False  # --wire-diameter 1.08e-3 --youngs-modulus 206831e6
    lab_model: bool = False  # --lab-model
    com: np.ndarray = field(default_factory=lambda: np.zeros(3))
    load_point: np.ndarray = field(default_factory=lambda: np.zeros(3))
    offsets: np.ndarray = field(default_factory=lambda: np.zeros(6))
    force: np.ndarray = field(default_factory=lambda: np.zeros(3))
    moment: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def crane(self) -> ic.Crane:
        if self.lab_model or self.wire:
            return ic.make_crane(self.a, self.b, self.h, self.weight, wire_diameter=LAB_D, youngs_modulus=LAB_E,
                                 com=self.com, length_offsets=self.offsets, per_wire_stiffness=PER_WIRE_K_FROM_E)
        return ic.make_crane(self.a, self.b, self.h, self.weight, k=self.k, com=self.com,
                             length_offsets=self.offsets)

    def solve(self, max_steps=4000) -> ic.Equilibrium:
        return ic.solve(self.crane(), self.force, self.moment, self.load_point, max_steps=max_steps)

    def cli_args(self, command: str) -> list[str]:
        args = [command]
        if self.lab_model:
            args += ["--lab-model"]
        else:
            args += ["--a", num(self.a), "--b", num(self.b)]
        args += ["--height", num(self.h), "--weight", num(self.weight)]
        if not self.lab_model:
            if self.wire:
                args += ["--wire-diameter", num(LAB_D), "--youngs-modulus", num(LAB_E)]
            else:
                args += ["--wire-stiffness", num(self.k)]
        if np.any(self.com != 0):
            args += ["--com", *map(num, self.com)]
        if np.any(self.load_point != 0):
            args += ["--load-point", *map(num, self.load_point)]
        if np.any(self.offsets != 0):
            args += ["--length-offsets", *map(num, self.offsets)]
        args += ["--force", *map(num, self.force), "--moment", *map(num, self.moment), "--json"]
        return args


def num(x: float) -> str:
    return np.format_float_positional(float(x), unique=True, trim="0")


def exact(x):
    """Round values through their CLI text so that the reference sees exactly what the CLI parses."""
    return np.array([float(num(v)) for v in np.atleast_1d(x)]) if np.ndim(x) else float(num(x))


def wire_margin(crane: ic.Crane, eq: ic.Equilibrium) -> float:
    return float(np.min(np.abs(eq.wire_lengths - crane.l0)) / crane.l0_nominal)


def well_posed(case: Case) -> ic.Equilibrium | None:
    """The reference equilibrium, or None when the case is too close to a kink or a fold to compare."""
    crane = case.crane()
    try:
        eq = case.solve(max_steps=200)  # the accepted cases need well under 100 steps
    except ic.NoEquilibrium:
        return None
    if wire_margin(crane, eq) < MIN_MARGIN or math.degrees(eq.rotation_angle) > MAX_ROTATION_DEG:
        return None
    if eq.slack.sum() > 3:
        return None
    K = ic.tangent_stiffness(crane, eq.displacement, eq.rotation, case.force, case.load_point)
    d = np.r_[np.ones(3), np.full(3, 1.0 / max(case.a, case.b))]
    ev = np.linalg.eigvalsh(d[:, None] * (0.5 * (K + K.T)) * d[None, :])
    if ev[0] < 1e-5 * ev[-1]:
        return None
    return eq


def _load_direction(rng, a, b):
    d = rng.normal(size=6)
    d[2] *= 0.3  # mostly side forces
    d[3:] *= max(a, b)
    return d


def _draw_random_case(rng, index: int) -> Case | None:
    a, b = rng.uniform(0.05, 0.3, 2)
    h = rng.uniform(0.3, 2.0)
    W = rng.uniform(5.0, 200.0)
    if index % 2:
        wire = rng.random() < 0.4
        k = None if wire else 10 ** rng.uniform(3.0, 5.0)
    else:  # rotations of several degrees with every wire taut need soft wires
        wire = False
        k = 10 ** rng.uniform(3.0, 4.0)
    base = Case(f"random{index:02d}", exact(a), exact(b), exact(h), exact(W), k=None if wire else exact(k),
                wire=wire)
    crane = base.crane()
    eq0 = ic.solve(crane)
    K0 = ic.tangent_stiffness(crane, eq0.displacement, eq0.rotation)
    direction = _load_direction(rng, a, b)
    dx = np.linalg.solve(K0, direction)
    if index % 2:  # aim past the slack threshold of the most unloaded wire (linear prediction)
        ws = ic.wire_state(crane, eq0.displacement, eq0.rotation)
        n = ws.vectors / ws.lengths[:, None]
        dL = np.einsum("ij,ij->i", n, -dx[:3] + ic.cross(ws.arms, dx[3:]))
        scale = rng.uniform(1.2, 2.5) * ws.tensions.min() / max(-crane.k * dL.min(), 1e-300)
    else:  # aim at a rotation of a few degrees (linear prediction)
        scale = math.radians(rng.uniform(2.0, 8.0)) / np.linalg.norm(dx[3:])
    load = scale * direction
    # keep the loads moderate: side forces up to ~W/2, moments up to ~W a/2
    cap = max(np.linalg.norm(load[:3]) / (0.5 * W), np.linalg.norm(load[3:]) / (0.5 * W * max(a, b)), 1.0)
    load = load / cap
    for _ in range(4):
        case = Case(base.name, base.a, base.b, base.h, base.weight, k=base.k, wire=wire,
                    force=exact(load[:3]), moment=exact(load[3:]))
        eq = well_posed(case)
        if eq is not None:
            _REFERENCE[case.name] = eq
            return case
        load = 0.6 * load
    return None


def _special_cases(rng) -> list[Case]:
    cases = []
    # Weight alone: the tangent must equal eq. (18).
    cases.append(Case("weight_only", exact(0.17), exact(0.23), exact(1.1), exact(40.0), k=exact(8000.0)))
    # Centre of mass below and beside the platform centre, with side force and moment.
    cases.append(Case("com_offset", exact(0.2), exact(0.15), exact(0.9), exact(80.0), k=exact(6000.0),
                      com=exact([0.03, -0.02, 0.25]), force=exact([6.0, -4.0, 3.0]),
                      moment=exact([0.4, 0.3, -1.2])))
    # Force applied below the platform centre.
    cases.append(Case("load_point", exact(0.12), exact(0.18), exact(1.4), exact(60.0), k=exact(4000.0),
                      load_point=exact([0.02, 0.04, 0.2]), force=exact([-1.5, 2.1, 0.6]),
                      moment=exact([0.0, 0.0, 0.5])))
    # Length offsets of the order of the stretch under weight, all wires taut.
    crane = ic.make_crane(0.15, 0.15, 0.8, 50.0, k=20000.0)
    stretch = float(crane.weight / 6 / crane.k * crane.l0_nominal / 0.8)
    cases.append(Case("length_offsets_taut", exact(0.15), exact(0.15), exact(0.8), exact(50.0), k=exact(20000.0),
                      offsets=exact(stretch * np.array([0.3, -0.2, 0.25, -0.35, 0.1, 0.0])),
                      force=exact([2.0, 1.0, 0.0]), moment=exact([0.1, -0.2, 0.3])))
    # Uneven wires and a side load that slackens one of them.
    cases.append(Case("length_offsets_slack", exact(0.15), exact(0.15), exact(0.8), exact(50.0), k=exact(20000.0),
                      offsets=exact(stretch * np.array([0.5, -3.0, 0.0, 1.0, 0.0, 0.0])),
                      force=exact([-3.0, 6.0, 0.0]), moment=exact([0.0, 0.2, -0.1])))
    # Soft wires, heavy load: a twist of several degrees with every wire taut.
    cases.append(Case("soft_twist", exact(0.25), exact(0.25), exact(0.5), exact(150.0), k=exact(1500.0),
                      force=exact([1.0, -0.5, 0.0]), moment=exact([0.3, -0.2, 10.0])))
    # Everything at once, with the lab wire.
    cases.append(Case("combined_wire", exact(0.25), exact(0.2), exact(1.6), exact(120.0), wire=True,
                      com=exact([-0.01, 0.02, 0.1]), load_point=exact([0.05, 0.0, 0.12]),
                      offsets=exact([2e-5, -1e-5, 0.0, 1e-5, -2e-5, 0.0]),
                      force=exact([3.0, -2.0, 5.0]), moment=exact([0.3, 0.2, 0.6])))
    # --lab-model: side force along y, as in the paper's tests; low weight, long wires: wires go slack (Fig. 9).
    cases.append(Case("lab_model_side_force", ic.LAB_A, ic.LAB_B, exact(1.5), exact(20.0), lab_model=True,
                      force=exact([0.0, 3.0, 0.0]), moment=exact([0.0, 0.0, 0.0])))
    cases.append(Case("lab_model_twist", ic.LAB_A, ic.LAB_B, exact(0.6), exact(90.0), lab_model=True,
                      force=exact([0.0, 0.0, 0.0]), moment=exact([0.0, 0.0, 1.5])))
    return cases


@lru_cache(maxsize=None)
def all_cases() -> tuple[Case, ...]:
    rng = np.random.default_rng(SEED)
    cases = []
    index = 0
    while len(cases) < N_RANDOM:
        index += 1
        if index > 4 * N_RANDOM:
            raise RuntimeError("could not draw enough well-posed random cases")
        case = _draw_random_case(rng, index)
        if case is not None:
            cases.append(case)
    return tuple(cases) + tuple(_special_cases(rng))


_REFERENCE: dict[str, ic.Equilibrium] = {}


def reference(name: str) -> ic.Equilibrium:
    if name not in _REFERENCE:
        _REFERENCE[name] = CASES[name].solve()
    return _REFERENCE[name]


CASES = {c.name: c for c in all_cases()}
CASE_NAMES = list(CASES)
NO_EQUILIBRIUM = Case("upward_force", exact(0.15), exact(0.2), exact(1.0), exact(30.0), k=exact(5000.0),
                      force=exact([0.0, 0.0, -45.0]), moment=exact([0.0, 0.0, 0.0]))


# ----------------------------------------------------------------------------------------------------------
# The reference on its own
# ----------------------------------------------------------------------------------------------------------

def test_case_set_is_not_vacuous():
    eqs = {n: reference(n) for n in CASE_NAMES}
    slack = [n for n, e in eqs.items() if e.slack.any()]
    multi_slack = [n for n, e in eqs.items() if e.slack.sum() >= 2]
    rotated = [n for n, e in eqs.items() if math.degrees(e.rotation_angle) >= ROTATED_DEG]
    taut_rotated = [n for n in rotated if not eqs[n].slack.any()]
    random_names = [n for n in CASE_NAMES if n.startswith("random")]
    assert len(random_names) >= 20
    assert sum(eqs[n].slack.any() for n in random_names) >= 6, slack
    assert sum(math.degrees(eqs[n].rotation_angle) >= ROTATED_DEG for n in random_names) >= 8, rotated
    assert len(multi_slack) >= 3, multi_slack
    assert len(taut_rotated) >= 3, taut_rotated
    assert sum(CASES[n].wire or CASES[n].lab_model for n in CASE_NAMES) >= 4
    assert any(np.any(CASES[n].com != 0) for n in CASE_NAMES)
    assert any(np.any(CASES[n].load_point != 0) for n in CASE_NAMES)
    assert any(np.any(CASES[n].offsets != 0) and eqs[n].slack.any() for n in CASE_NAMES)
    assert eqs["lab_model_side_force"].slack.any()
    # spread of the random geometry and loads
    ks = [CASES[n].crane().k for n in random_names]
    assert min(ks) < 3e3 and max(ks) > 1e5
    assert max(math.degrees(eqs[n].rotation_angle) for n in CASE_NAMES) > 8.0


@pytest.mark.parametrize("name", CASE_NAMES)
def test_reference_equilibrium_is_converged_and_well_posed(name):
    case = CASES[name]
    crane = case.crane()
    eq = reference(name)
    assert well_posed(case) is not None
    fscale = crane.weight + np.linalg.norm(case.force) + np.linalg.norm(case.moment) / crane.a
    assert np.linalg.norm(eq.residual[:3]) <= 1e-11 * fscale
    assert np.linalg.norm(eq.residual[3:]) <= 1e-11 * fscale * max(crane.a, crane.b)
    # consistency of the reported quantities
    assert np.allclose(eq.rotation.T @ eq.rotation, np.eye(3), atol=1e-14)
    assert np.allclose(ic.rot_zxy(*eq.euler_zxy), eq.rotation, atol=1e-14)
    assert np.array_equal(eq.slack, eq.wire_lengths < crane.l0)
    assert np.all(eq.wire_tensions[eq.slack] == 0)
    assert np.all(eq.wire_tensions[~eq.slack] > 0)


def test_reference_rotation_convention():
    # small-angle form, eq. (22): Q ~ I + [w]x with w = (theta, psi, phi)
    phi, theta, psi = 1e-7, -2e-7, 3e-7
    Q = ic.rot_zxy(phi, theta, psi)
    assert np.allclose(Q, np.eye(3) + ic.skew([theta, psi, phi]), atol=1e-13)
    assert np.allclose(Q - np.eye(3), [[0, -phi, psi], [phi, 0, -theta], [-psi, theta, 0]], atol=1e-13)
    # intrinsic z-x-y: Q = Rz Rx Ry, body x axis after phi about z only
    assert np.allclose(ic.rot_zxy(0.3, 0, 0)[:, 0], [math.cos(0.3), math.sin(0.3), 0])
    rng = np.random.default_rng(1)
    for _ in range(20):
        e = rng.uniform([-3, -1.4, -3], [3, 1.4, 3])
        assert np.allclose(ic.euler_zxy(ic.rot_zxy(*e)), e, atol=1e-12)
        # Euler-rate map: dQ Q^T = [w]x
        T = ic.euler_rate_map(e[0], e[1])
        for j in range(3):
            de = np.zeros(3)
            de[j] = 1e-6
            dQ = (ic.rot_zxy(*(e + de)) - ic.rot_zxy(*(e - de))) / 2e-6
            W = dQ @ ic.rot_zxy(*e).T
            assert np.allclose(W, -W.T, atol=1e-8)
            assert np.allclose([W[2, 1], W[0, 2], W[1, 0]], T[:, j], atol=1e-8)


@pytest.mark.parametrize("params", [(0.1143, 0.1143, 1.0, None, 20.0), (0.05, 0.3, 0.3, 1e3, 5.0),
                                    (0.3, 0.05, 2.0, 1e5, 200.0), (0.2, 0.1, 0.7, 3e4, 75.0),
                                    (0.1143, 0.1143, 0.4, None, 150.0)])
def test_reference_paper_eq18_closed_form(params):
    """docs/physics.md: with h_w from the implicit balance, eq. (18) IS the exact tangent at the loaded rest pose."""
    a, b, h, k, W = params
    crane = (ic.make_crane(a, b, h, W, k=k) if k else
             ic.make_crane(a, b, h, W, wire_diameter=LAB_D, youngs_modulus=LAB_E))
    hw = ic.weighted_height(a, b, h, crane.k, W)
    lw = math.sqrt(hw * hw + 4 * (a * a + b * b - a * b) / 3)
    assert 6 * crane.k * (lw - crane.l0_nominal) * hw / lw == pytest.approx(W, rel=1e-9)  # l_w - l0 cancels
    eq = ic.solve(crane)
    assert np.allclose(eq.displacement, [0, 0, hw - h], rtol=0, atol=1e-13 * h)
    assert np.allclose(eq.rotation, np.eye(3), atol=1e-13)
    assert np.allclose(eq.wire_tensions, crane.k * (lw - crane.l0_nominal), rtol=1e-10)
    K = ic.tangent_stiffness(crane, eq.displacement, eq.rotation)
    P = ic.paper_stiffness(a, b, h, crane.k, W)
    assert np.abs(K - P).max() <= 1e-11 * np.abs(P).max()
    # eq. (19) reading of docs/physics.md: K1 - K2^2/K4 is 1/C_yy with C = K^-1
    assert P[1, 1] - P[1, 3] ** 2 / P[3, 3] == pytest.approx(1 / np.linalg.inv(P)[1, 1], rel=1e-9)
    # appendix I: the elastic part at W -> 0 is eq. (28); appendix II: the pendulum part
    K1p = 4 * crane.k * (a * a + b * b - a * b) / crane.l0_nominal ** 2
    assert ic.paper_stiffness(a, b, h, crane.k, 1e-12 * W)[0, 0] == pytest.approx(K1p, rel=1e-9)


@pytest.mark.parametrize("name", CASE_NAMES)
def test_reference_tangent_matches_finite_differences(name):
    case = CASES[name]
    crane = case.crane()
    eq = reference(name)
    step = min(1e-6 * crane.l0_nominal, 0.05 * wire_margin(crane, eq) * crane.l0_nominal)
    K = ic.tangent_stiffness(crane, eq.displacement, eq.rotation, case.force, case.load_point)
    Kfd = ic.tangent_stiffness_fd(crane, eq.displacement, eq.rotation, case.force, case.moment, case.load_point,
                                  step_length=step)
    assert np.abs(K - Kfd).max() <= 1e-7 * np.abs(K).max()
    if not np.any(case.moment) and not np.any(case.com) and not np.any(case.load_point):
        # weight and forces through the platform centre: symmetric at an equilibrium
        assert np.abs(K - K.T).max() <= 1e-9 * np.abs(K).max()


def test_reference_euler_jacobian_matches_finite_differences():
    """The Jacobian the solver uses (K times the Euler-rate map) against differences in Euler coordinates."""
    for name in CASE_NAMES[:6] + ["com_offset", "load_point", "combined_wire"]:
        case = CASES[name]
        crane = case.crane()
        eq = reference(name)
        x = np.r_[eq.displacement, eq.euler_zxy]
        J = ic._euler_jacobian(crane, x, case.force, case.load_point)
        step = min(1e-6 * crane.l0_nominal, 0.05 * wire_margin(crane, eq) * crane.l0_nominal)
        Jfd = np.zeros((6, 6))
        for j in range(6):
            hj = step if j < 3 else step / max(crane.a, crane.b, np.linalg.norm(case.load_point),
                                               np.linalg.norm(case.com))
            e = np.zeros(6)
            e[j] = hj
            wp = ic.net_wrench(crane, *ic._pose(x + e), case.force, case.moment, case.load_point)
            wm = ic.net_wrench(crane, *ic._pose(x - e), case.force, case.moment, case.load_point)
            Jfd[:, j] = (wp - wm) / (2 * hj)
        assert np.abs(J - Jfd).max() <= 1e-6 * np.abs(J).max(), name


def test_reference_wrench_is_minus_energy_gradient():
    """Force and moment of ``net_wrench`` (M = 0) equal -dV/du and -dV/dw (fixed-frame rotation) of the
    potential energy: checks the signs and arms of every moment term, slack wires included."""
    rng = np.random.default_rng(7)
    n_slack = 0
    for _ in range(30):
        a, b = rng.uniform(0.05, 0.3, 2)
        h = rng.uniform(0.3, 2.0)
        crane = ic.make_crane(a, b, h, rng.uniform(5, 200), k=10 ** rng.uniform(3, 5),
                              com=rng.normal(scale=0.1, size=3), length_offsets=rng.normal(scale=1e-3, size=6))
        u = rng.normal(scale=0.01, size=3) + [0, 0, 0.002]
        Q = ic.rot_zxy(*rng.normal(scale=0.05, size=3))
        F = rng.normal(scale=10, size=3)
        p = rng.normal(scale=0.1, size=3)
        ws = ic.wire_state(crane, u, Q)
        n_slack += ws.slack.sum()
        if np.min(np.abs(ws.lengths - crane.l0)) < 1e-5:
            continue
        w = ic.net_wrench(crane, u, Q, F, (0, 0, 0), p)
        g = np.zeros(6)
        hstep = 1e-7
        for j in range(6):
            e = np.zeros(3)
            e[j % 3] = hstep
            if j < 3:
                g[j] = (ic.potential_energy(crane, u + e, Q, F, p) - ic.potential_energy(crane, u - e, Q, F, p))
            else:
                g[j] = (ic.potential_energy(crane, u, ic.rodrigues(e) @ Q, F, p)
                        - ic.potential_energy(crane, u, ic.rodrigues(-e) @ Q, F, p))
            g[j] /= 2 * hstep
        assert np.allclose(w, -g, rtol=0, atol=1e-5 * (np.abs(w).max() + crane.weight))
    assert n_slack > 0


def test_reference_equilibrium_minimises_energy():
    """Without an external couple the loads are conservative: minimising the potential energy with BFGS, in a
    rotation-vector parametrisation from the pose under weight alone, must land on the same equilibrium as the
    continuation solver.  Run on the cases with their moment removed."""
    checked = slack = 0
    for name in CASE_NAMES:
        c = CASES[name]
        case = Case(name + "_no_moment", c.a, c.b, c.h, c.weight, k=c.k, wire=c.wire, lab_model=c.lab_model,
                    com=c.com, load_point=c.load_point, offsets=c.offsets, force=c.force)
        eq = well_posed(case)
        if eq is None:
            continue
        crane = case.crane()
        start = ic.solve(ic.make_crane(case.a, case.b, case.h, case.weight, k=crane.k))
        ls = max(case.a, case.b)

        def V(y):
            return ic.potential_energy(crane, y[:3] * ls, ic.rodrigues(y[3:]), case.force, case.load_point)

        y0 = np.r_[start.displacement / ls, 0, 0, 0]
        V0 = V(y0)
        res = minimize(lambda y: V(y) - V0, y0, method="BFGS", jac="3-point", options={"gtol": 1e-12})
        u = res.x[:3] * ls
        Q = ic.rodrigues(res.x[3:])
        assert np.abs(u - eq.displacement).max() <= 1e-7, name
        assert np.abs(Q - eq.rotation).max() <= 1e-7, name
        checked += 1
        slack += bool(eq.slack.any())
    assert checked >= 12 and slack >= 2, (checked, slack)


def test_reference_no_equilibrium_for_upward_load():
    with pytest.raises(ic.NoEquilibrium):
        NO_EQUILIBRIUM.solve()
    # just below the threshold there still is one
    almost = Case("almost", NO_EQUILIBRIUM.a, NO_EQUILIBRIUM.b, NO_EQUILIBRIUM.h, NO_EQUILIBRIUM.weight,
                  k=NO_EQUILIBRIUM.k, force=np.array([0.0, 0.0, -0.9 * NO_EQUILIBRIUM.weight]))
    eq = almost.solve()
    assert np.allclose(eq.wire_tensions, eq.wire_tensions[0]) and eq.wire_tensions[0] > 0


# ----------------------------------------------------------------------------------------------------------
# The CLI against the reference
# ----------------------------------------------------------------------------------------------------------

def cli_path() -> str:
    path = os.path.join(sysconfig.get_path("scripts"), "crane-stiffness")
    if os.path.exists(path):
        return path
    found = shutil.which("crane-stiffness")
    if found:
        return found
    pytest.fail(f"console script crane-stiffness not found at {path} or on PATH")


def run_cli(args: list[str]) -> subprocess.CompletedProcess:
    return subprocess.run([cli_path(), *args], capture_output=True, text=True, timeout=120,
                          env=dict(os.environ))


@pytest.fixture(scope="module")
def cli_outputs():
    """Every CLI call at once, two at a time (one case per call)."""
    cli_path()
    jobs = {(name, cmd): CASES[name].cli_args(cmd) for name in CASE_NAMES for cmd in ("solve", "stiffness")}
    jobs[("upward_force", "solve")] = NO_EQUILIBRIUM.cli_args("solve")
    jobs[("upward_force", "stiffness")] = NO_EQUILIBRIUM.cli_args("stiffness")
    with ThreadPoolExecutor(max_workers=max(2, min(4, os.cpu_count() or 2))) as pool:
        futures = {key: pool.submit(run_cli, args) for key, args in jobs.items()}
        return {key: f.result() for key, f in futures.items()}


def _json(proc: subprocess.CompletedProcess, args) -> dict:
    assert proc.returncode == 0, f"crane-stiffness {' '.join(args)}\nexit {proc.returncode}\n{proc.stderr}"
    try:
        return json.loads(proc.stdout)
    except json.JSONDecodeError as exc:
        raise AssertionError(f"stdout is not one JSON document: {exc}\n{proc.stdout[:2000]}") from exc


def _wrap(d):
    return (np.asarray(d) + np.pi) % (2 * np.pi) - np.pi


@pytest.mark.parametrize("name", CASE_NAMES)
def test_cli_solve_matches_reference(cli_outputs, name):
    case = CASES[name]
    ref = reference(name)
    out = _json(cli_outputs[(name, "solve")], case.cli_args("solve"))
    for key in ("converged", "displacement", "rotation", "euler_zxy", "wire_lengths", "wire_tensions", "slack"):
        assert key in out, f"missing key {key}"
    assert out["converged"] is True
    u = np.asarray(out["displacement"], dtype=float)
    Q = np.asarray(out["rotation"], dtype=float)
    eul = np.asarray(out["euler_zxy"], dtype=float)
    L = np.asarray(out["wire_lengths"], dtype=float)
    t = np.asarray(out["wire_tensions"], dtype=float)
    slack = np.asarray(out["slack"])
    assert u.shape == (3,) and Q.shape == (3, 3) and eul.shape == (3,)
    assert L.shape == (6,) and t.shape == (6,) and slack.shape == (6,)
    assert slack.dtype == bool, f"slack must be booleans, got {out['slack']}"

    assert np.abs(u - ref.displacement).max() <= POSE_TOL_M, (u, ref.displacement)
    # rotation: matrix entries and the angle of Q_cli Q_ref^T
    assert np.abs(Q - ref.rotation).max() <= POSE_TOL_RAD, (Q, ref.rotation)
    R = Q @ ref.rotation.T
    assert np.linalg.norm([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]]) / 2 <= POSE_TOL_RAD
    assert np.abs(_wrap(eul - ref.euler_zxy)).max() <= POSE_TOL_RAD, (eul, ref.euler_zxy)
    assert np.abs(L - ref.wire_lengths).max() <= LENGTH_TOL_M, (L, ref.wire_lengths)
    assert np.array_equal(slack, ref.slack), (slack, ref.slack)
    assert np.abs(t - ref.wire_tensions).max() <= TENSION_RTOL * ref.wire_tensions.max(), (t, ref.wire_tensions)
    assert np.all(t[slack] == 0)


@pytest.mark.parametrize("name", CASE_NAMES)
def test_cli_stiffness_matches_reference(cli_outputs, name):
    case = CASES[name]
    crane = case.crane()
    ref = reference(name)
    out = _json(cli_outputs[(name, "stiffness")], case.cli_args("stiffness"))
    assert "tangent" in out and "paper" in out
    K = np.asarray(out["tangent"], dtype=float)
    P = np.asarray(out["paper"], dtype=float)
    assert K.shape == (6, 6) and P.shape == (6, 6)
    K_ref = ic.tangent_stiffness(crane, ref.displacement, ref.rotation, case.force, case.load_point)
    P_ref = ic.paper_stiffness(crane.a, crane.b, crane.h, crane.k, crane.weight)
    err = np.abs(K - K_ref).max() / np.abs(K_ref).max()
    assert err <= STIFFNESS_RTOL, f"tangent off by {err:.3g} of max entry\n{K}\n{K_ref}"
    err = np.abs(P - P_ref).max() / np.abs(P_ref).max()
    assert err <= STIFFNESS_RTOL, f"paper off by {err:.3g} of max entry\n{P}\n{P_ref}"
    if name == "weight_only":
        assert np.abs(K - P).max() <= STIFFNESS_RTOL * np.abs(P).max()


@pytest.mark.parametrize("command", ["solve", "stiffness"])
def test_cli_no_equilibrium_exits_nonzero(cli_outputs, command):
    proc = cli_outputs[("upward_force", command)]
    assert proc.returncode != 0
    assert proc.stdout.strip() == ""
    assert proc.stderr.strip() != ""
    assert "Traceback" not in proc.stderr, proc.stderr
