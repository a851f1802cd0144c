"""Physics core against the paper's closed forms, the facts in docs/physics.md and finite differences."""
from __future__ import annotations

import math

import numpy as np
import pytest

from crane_stiffness.model import (ConvergenceError, CraneGeometry, GeometryError, NoEquilibriumError,
                                   axis_stiffness, compliance, elastic_stiffness, euler_zxy_to_matrix, lab_model,
                                   loaded_height, matrix_to_euler_zxy, net_wrench, paper_coefficients,
                                   paper_stiffness, pendulum_stiffness, rest_pose, single_wire_pendulum_stiffness,
                                   solve_batch, solve_equilibrium, solve_path, tangent_stiffness)
from crane_stiffness.model.rotation import (matrix_to_quaternion, quaternion_to_matrix, rotvec_to_matrix, skew)


def fd_stiffness(g: CraneGeometry, eq, h: float = 1e-7) -> np.ndarray:
    """−∂w/∂x by central differences, rotations perturbed in the fixed frame."""
    out = np.zeros((6, 6))
    for j in range(6):
        d = np.zeros(6)
        d[j] = h
        wp = net_wrench(g, eq.displacement + d[:3], rotvec_to_matrix(d[3:]) @ eq.rotation, eq.load)
        wm = net_wrench(g, eq.displacement - d[:3], rotvec_to_matrix(-d[3:]) @ eq.rotation, eq.load)
        out[:, j] = -(wp - wm) / (2 * h)
    return out


def random_geometry(rng: np.random.Generator, **extra) -> CraneGeometry:
    return CraneGeometry(a=rng.uniform(0.05, 0.3), b=rng.uniform(0.05, 0.3), height=rng.uniform(0.3, 2.0),
                         weight=rng.uniform(5, 200), wire_stiffness=rng.uniform(1e3, 1e5), **extra)


# --- closed forms ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize('seed', range(8))
def test_eq18_equals_exact_tangent_at_loaded_rest_pose(seed):
    """docs/physics.md: with h_w from the implicit balance, eq. (18) is the exact tangent at the rest pose, any a, b,
    W."""
    g = random_geometry(np.random.default_rng(seed))
    eq = rest_pose(g)
    kt = tangent_stiffness(g, eq)
    kp = paper_stiffness(g)
    assert np.abs(kt - kp).max() <= 1e-9 * np.abs(kp).max()
    assert not eq.slack.any()


def test_loaded_height_solves_vertical_balance_and_matches_solver():
    g = lab_model(height=0.8, weight=80.0)
    hw, lw = loaded_height(g)
    # l_w − l0 is a ~30 µm stretch of a 0.8 m wire: the subtraction alone costs ~1e-12 relative.
    assert 6 * g.k * (lw - g.l0) * hw / lw == pytest.approx(g.weight, rel=1e-10)
    assert lw == pytest.approx(math.sqrt(hw ** 2 + 4 * (g.a ** 2 + g.b ** 2 - g.a * g.b) / 3), rel=1e-15)
    eq = rest_pose(g)
    # The platform sinks from z = 0 to z = h_w − h (z down); every wire carries W/6 vertically.
    assert eq.displacement[2] == pytest.approx(hw - g.height, rel=1e-9)
    assert np.allclose(eq.wire_lengths, lw, rtol=1e-12)
    assert np.allclose(eq.wire_tensions * hw / lw, g.weight / 6, rtol=1e-9)


def test_paper_coefficients_by_hand_for_the_lab_model():
    g = lab_model(height=0.5, weight=50.0)
    c = paper_coefficients(g)
    a = b = 0.1143
    k = math.pi * 1.08e-3 ** 2 / 4 * 206_831e6 / g.l0
    base = k * g.l0 / c.l_w ** 3
    assert c.k1 == pytest.approx(4 * base * (a * a + b * b - a * b) + 50 / c.h_w, rel=1e-14)
    assert c.k2 == pytest.approx(2 * base * a * (2 * a - b) * c.h_w, rel=1e-14)
    assert c.k5 == pytest.approx(8 * base * a * a * b * b + 2 * a * b * 50 / (3 * c.h_w), rel=1e-14)
    assert c.side == pytest.approx(c.k1 - c.k2 ** 2 / c.k4)
    # eq. (19): K_j is 1/C_yy of the compliance (the coupled tilt left free).
    assert c.side == pytest.approx(1.0 / compliance(paper_stiffness(g))[1, 1], rel=1e-12)
    assert axis_stiffness(paper_stiffness(g), 'fy') == pytest.approx(c.side, rel=1e-12)


def test_elastic_and_pendulum_parts_are_the_two_terms_of_eq18_at_the_unloaded_geometry():
    g = lab_model(height=0.6, weight=40.0)
    k0, kw = elastic_stiffness(g), pendulum_stiffness(g)
    hw, _ = loaded_height(g)
    assert kw[0, 0] == pytest.approx(40.0 / hw)
    assert kw[5, 5] == pytest.approx(g.a * g.b * 2 * 40.0 / (3 * hw))
    # At W = 0 eq. (18) reduces to K0 (eq. 28) and Kw vanishes.
    g0 = g.replace(weight=0.0)
    assert np.allclose(paper_stiffness(g0), elastic_stiffness(g0), rtol=1e-14, atol=0)
    assert not np.any(pendulum_stiffness(g0))
    # For a light load the sum K0 + Kw is close to eq. (18) (the paper's superposition, App. II).
    assert np.allclose(k0 + kw, paper_stiffness(g), rtol=2e-3, atol=1e-6 * np.abs(k0).max())


def test_w0_tangent_is_the_bilateral_k0_but_real_stiffness_is_one_sided():
    g = lab_model(height=0.5, weight=0.0)
    eq = rest_pose(g)
    assert np.allclose(tangent_stiffness(g, eq), elastic_stiffness(g), rtol=1e-12, atol=1e-9)
    # Pulling down meets K3 ...
    fz = 1.0
    down = solve_equilibrium(g, force=[0, 0, fz])
    assert down.displacement[2] == pytest.approx(fz / elastic_stiffness(g)[2, 2], rel=1e-4)
    # ... pushing up meets nothing: no equilibrium, and a side push alone cannot be held either.
    with pytest.raises(NoEquilibriumError, match='not positive'):
        solve_equilibrium(g, force=[0, 0, -1.0])
    with pytest.raises(NoEquilibriumError):
        solve_equilibrium(g, force=[0, 1.0, 0])


def test_single_wire_pendulum_lateral_stiffness_is_w_over_h():
    """Eq. (30): shrink both triangles to a point and the six wires act as one pendulum of stiffness W/h."""
    g = CraneGeometry(a=1e-5, b=1e-5, height=1.2, weight=30.0, wire_stiffness=5e4)
    hw, _ = loaded_height(g)
    eq = rest_pose(g)
    assert axis_stiffness(tangent_stiffness(g, eq), 'fx') == pytest.approx(30.0 / hw, rel=1e-6)
    f = 0.01
    pushed = solve_equilibrium(g, force=[f, 0, 0])
    assert pushed.displacement[0] - eq.displacement[0] == pytest.approx(f * hw / 30.0, rel=1e-3)
    assert single_wire_pendulum_stiffness(g) == pytest.approx(30.0 / (6 * hw))


# --- tangent stiffness against finite differences --------------------------------------------------------------

def random_loaded_case(seed: int):
    """A random crane with offsets under a random side load, moment and vertical load, and its equilibrium."""
    rng = np.random.default_rng(100 + seed)
    g = random_geometry(rng, com_offset=tuple(rng.uniform(-0.03, 0.03, 3)),
                        load_point=tuple(rng.uniform(-0.03, 0.03, 3)),
                        length_offsets=tuple(rng.uniform(-2e-4, 2e-4, 6)))
    side = rng.uniform(0.05, 0.6) * g.weight
    load = np.concatenate([rng.normal(size=2) / math.sqrt(2) * side, [rng.uniform(-0.3, 0.3) * g.weight],
                           rng.normal(size=3) * 0.05 * g.weight * g.a])
    return g, solve_equilibrium(g, load=load)


@pytest.mark.parametrize('seed', range(10))
def test_tangent_matches_finite_differences_at_random_loaded_rotated_partly_slack_poses(seed):
    g, eq = random_loaded_case(seed)
    assert np.abs(eq.residual[:3]).max() < 1e-8 * g.weight
    margin = np.abs(eq.wire_lengths - g.unstretched_lengths).min()
    assert margin > 1e-6, 'a wire sits on the slack threshold; finite differences would straddle the kink'
    kt = tangent_stiffness(g, eq)
    kf = fd_stiffness(g, eq)
    assert np.abs(kt - kf).max() <= 1e-6 * np.abs(kt).max()


def test_random_poses_cover_slack_and_rotation():
    """The finite-difference cases above are not all easy: some rotate by degrees and some have slack wires."""
    slack = rotated = 0
    for seed in range(10):
        _, eq = random_loaded_case(seed)
        slack += bool(eq.slack.any())
        rotated += bool(np.abs(eq.euler_zxy).max() > math.radians(2))
    assert slack >= 3 and rotated >= 3


def test_tangent_symmetry_and_fixed_couple_asymmetry():
    g = lab_model(height=0.7, weight=60.0)
    eq = solve_equilibrium(g, force=[2.0, -3.0, 5.0])
    k = tangent_stiffness(g, eq)
    assert np.abs(k - k.T).max() <= 1e-9 * np.abs(k).max()
    eqm = solve_equilibrium(g, moment=[0.0, 0.0, 0.2])
    km = tangent_stiffness(g, eqm)
    asym = np.abs(km - km.T).max() / np.abs(km).max()
    assert 1e-8 < asym < 1e-2  # a couple held fixed in space leaves a small asymmetric part


# --- slack behaviour (Fig. 9) ----------------------------------------------------------------------------------

def test_fig9_low_weight_long_wires_bends_away_from_linear_when_wires_go_slack():
    from crane_stiffness.analysis.sweep import force_displacement
    g = lab_model(height=1.5, weight=5.0)
    curves = force_displacement(g, 'fy', max_load=2.0, points=21)
    assert curves.slack_wires[1] == 0
    # Small loads: linear, within 1 % of eq. (18).
    assert curves.nonlinear[1] == pytest.approx(curves.linear[1], rel=1e-2)
    # Larger loads: wires reach zero tension and the displacement runs far beyond the linear prediction.
    assert curves.slack_wires[-1] >= 2
    assert curves.nonlinear[-1] > 1.5 * curves.linear[-1]
    # Stiffer short wires under a heavy load stay linear over the same range.
    stiff = force_displacement(lab_model(height=0.5, weight=90.0), 'fy', max_load=2.0, points=5)
    assert stiff.slack_wires.max() == 0
    assert stiff.nonlinear[-1] == pytest.approx(stiff.linear[-1], rel=2e-2)


# --- solver behaviour ------------------------------------------------------------------------------------------

def test_batch_warm_start_and_cold_solves_agree():
    g = lab_model(height=0.9, weight=40.0)
    rng = np.random.default_rng(7)
    loads = np.column_stack([rng.uniform(-15, 15, (50, 2)), rng.uniform(-10, 30, 50), rng.uniform(-0.3, 0.3, (50, 3))])
    batch = solve_batch(g, loads)
    for i in range(0, 50, 7):
        single = solve_equilibrium(g, load=loads[i])
        assert np.allclose(batch.displacement[i], single.displacement, atol=1e-11)
        assert np.allclose(batch.rotation[i], single.rotation, atol=1e-11)
        assert np.array_equal(batch.slack[i], single.slack)
    path = solve_path(g, loads[:10])
    for i, eq in enumerate(path):
        assert np.allclose(eq.displacement, batch.displacement[i], atol=1e-11)
    assert np.abs(batch.residual[:, :3]).max() < 1e-7


def test_large_swing_needs_continuation_and_lands_on_the_loaded_branch():
    g = lab_model(height=0.5, weight=50.0)
    eq = solve_equilibrium(g, force=[0.0, 40.0, 0.0])
    # Pendulum intuition: the suspension leans towards the force; the platform moves +y and rises (−z).
    assert eq.displacement[1] > 0.1
    assert eq.slack.sum() >= 2
    # It is in balance and the same pose as stepping the load up slowly.
    assert np.abs(net_wrench(g, eq.displacement, eq.rotation, eq.load)).max() < 1e-8
    slow = solve_path(g, np.outer(np.linspace(0, 40, 21), [0, 1, 0, 0, 0, 0]))[-1]
    assert np.allclose(eq.displacement, slow.displacement, atol=1e-10)


def test_bad_inputs_raise_errors_naming_the_value():
    with pytest.raises(GeometryError, match=r'^a = -1.0: must be > 0'):
        CraneGeometry(a=-1.0, b=0.1, height=0.5, weight=1.0, wire_stiffness=1e4)
    with pytest.raises(GeometryError, match='weight = nan: must be finite'):
        CraneGeometry(a=0.1, b=0.1, height=0.5, weight=float('nan'), wire_stiffness=1e4)
    with pytest.raises(GeometryError, match='not both'):
        CraneGeometry(a=0.1, b=0.1, height=0.5, weight=1.0, wire_stiffness=1e4, wire_diameter=1e-3,
                      youngs_modulus=2e11)
    with pytest.raises(GeometryError, match='wire_diameter and youngs_modulus'):
        CraneGeometry(a=0.1, b=0.1, height=0.5, weight=1.0, wire_diameter=1e-3)
    with pytest.raises(GeometryError, match='com_offset .* 3 components'):
        CraneGeometry(a=0.1, b=0.1, height=0.5, weight=1.0, wire_stiffness=1e4, com_offset=(0, 0))
    with pytest.raises(GeometryError, match='wire_3 offset'):
        CraneGeometry(a=0.1, b=0.1, height=0.5, weight=1.0, wire_stiffness=1e4,
                      length_offsets=(0, 0, -0.4, 0, 0, 0))
    with pytest.raises(GeometryError, match='l0 = 0.01: must exceed'):
        CraneGeometry.from_dict({'a': 0.1, 'b': 0.1, 'l0': 0.01, 'weight': 1.0, 'wire_stiffness': 1e4})
    with pytest.raises(GeometryError, match='colour'):
        CraneGeometry.from_dict({'a': 0.1, 'b': 0.1, 'height': 1, 'weight': 1.0, 'colour': 'red'})
    g = lab_model(height=0.5, weight=10.0)
    with pytest.raises(NoEquilibriumError, match='W \\+ fz = 10 \\+ -10.5'):
        solve_equilibrium(g, force=[0, 0, -10.5])
    with pytest.raises(ValueError, match='finite'):
        solve_equilibrium(g, force=[0, float('inf'), 0])
    with pytest.raises(ValueError, match='3 components'):
        solve_equilibrium(g, force=[0, 1])
    with pytest.raises(NoEquilibriumError):
        solve_batch(g, [[0, 0, 0, 0, 0, 0], [0, 0, -20, 0, 0, 0]])
    with pytest.raises(ValueError, match=r'loads\[1\]'):
        solve_batch(g, [[0, 0, 0, 0, 0, 0], [0, np.nan, 0, 0, 0, 0]])
    with pytest.raises(ValueError, match="axis = 'fq'"):
        axis_stiffness(paper_stiffness(g), 'fq')


def test_limit_point_raises_instead_of_returning_a_far_pose():
    """Past a limit point the loaded branch ends (the platform would tip over): an error, not some other pose."""
    g = lab_model(height=0.9, weight=40.0)
    load = np.array([8.27, -8.24, 16.31, 0.434, 0.259, 0.943])
    eq = solve_equilibrium(g, load=0.76 * load)
    k = tangent_stiffness(g, eq)
    assert np.linalg.eigvalsh(0.5 * (k + k.T)).min() < 0.2  # nearly unstable, down from ~1e3 at rest
    assert abs(eq.euler_zxy[0]) > math.radians(50)  # twisted about z: the torsional limit of a hung platform
    with pytest.raises(NoEquilibriumError, match='limit point'):
        solve_equilibrium(g, load=load)
    with pytest.raises(NoEquilibriumError, match='limit point'):
        solve_batch(g, [0.5 * load, load])


def test_solver_gives_up_with_an_error_instead_of_hanging():
    g = lab_model(height=0.5, weight=50.0)
    with pytest.raises((ConvergenceError, NoEquilibriumError)):
        solve_equilibrium(g, force=[0.0, 40.0, 0.0], max_iter=1, max_steps=5)


# --- rotations -------------------------------------------------------------------------------------------------

def test_euler_convention_small_angle_form_and_round_trips():
    rng = np.random.default_rng(3)
    for _ in range(20):
        phi, theta, psi = rng.uniform(-1.2, 1.2, 3)
        q = euler_zxy_to_matrix(phi, theta, psi)
        assert np.allclose(q @ q.T, np.eye(3), atol=1e-15)
        assert np.allclose(matrix_to_euler_zxy(q), [phi, theta, psi], atol=1e-12)
        assert np.allclose(quaternion_to_matrix(matrix_to_quaternion(q)), q, atol=1e-14)
    # Eq. (22): Q ≈ I + [ω]× with ω = (θ, ψ, φ).
    d = 1e-6
    q = euler_zxy_to_matrix(3 * d, 1 * d, 2 * d)
    assert np.allclose(q, np.eye(3) + skew(np.array([1 * d, 2 * d, 3 * d])), atol=1e-11)
    # φ alone is a rotation about z, θ about x, ψ about y.
    assert np.allclose(euler_zxy_to_matrix(0.3, 0, 0) @ [1, 0, 0], [math.cos(0.3), math.sin(0.3), 0])
    assert np.allclose(euler_zxy_to_matrix(0, 0.3, 0) @ [0, 1, 0], [0, math.cos(0.3), math.sin(0.3)])
    assert np.allclose(euler_zxy_to_matrix(0, 0, 0.3) @ [0, 0, 1], [math.sin(0.3), 0, math.cos(0.3)])
