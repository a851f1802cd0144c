"""The independent reference implementation (``independent_crane.py``) checked on its own: finite differences,
an energy formulation and the closed form of eq. (18). The CLI is checked against it in
test_independent_agreement.py."""

from __future__ import annotations

import math
import os
import sys

import numpy as np
import pytest
from scipy.optimize import minimize

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))  # test/: independent_crane.py
import independent_crane as ic  # noqa: E402

from helpers.independent_cases import (  # noqa: E402
    CASES, CASE_NAMES, LAB_D, LAB_E, NO_EQUILIBRIUM, Case, reference, well_posed, wire_margin, ROTATED_DEG,
)



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
