"""Design questions: the inverse problem, the split stiffness against finite differences of the nonlinear model,
slack margins against a direct bisection on the nonlinear solver, the threefold symmetry of maps, the parallel
batch solver against the serial one."""
from __future__ import annotations

import math

import numpy as np
import pytest

from crane_stiffness.analysis.sweep import slack_threshold
from crane_stiffness.design.maps import VARIABLES, GridAxis, MapSpec, compute_points
from crane_stiffness.design.margins import circle_directions, load_directions, slack_margins, sphere_directions
from crane_stiffness.design.pose import at_pose, centre_height, split_stiffness, split_stiffness_batch
from crane_stiffness.model import (CraneGeometry, GeometryError, ModelError, lab_model, net_wrench, solve_batch,
                                   solve_equilibrium, tangent_stiffness)
from crane_stiffness.model import _pose_kernels as pk
from crane_stiffness.model.batch import solve_batch_parallel
from crane_stiffness.model.geometry import LAB_A, LAB_B, height_from_length
from crane_stiffness.model.inverse import UnreachablePoseError, inverse_pose
from crane_stiffness.model.rotation import rotvec_to_matrix


def fd_stiffness(g: CraneGeometry, eq, h: float = 1e-7) -> np.ndarray:
    """−∂w/∂x of the nonlinear net wrench by central differences, rotations perturbed in the fixed frame."""
    out = np.zeros((6, 6))
    for j in range(6):
        d = np.zeros(6)
        d[j] = h
        wp = net_wrench(g, eq.displacement + d[:3], rotvec_to_matrix(d[3:]) @ eq.rotation, eq.load)
        wm = net_wrench(g, eq.displacement - d[:3], rotvec_to_matrix(-d[3:]) @ eq.rotation, eq.load)
        out[:, j] = -(wp - wm) / (2 * h)
    return out


def random_crane(rng: np.random.Generator, material: bool) -> CraneGeometry:
    a, b = rng.uniform(0.06, 0.3), rng.uniform(0.06, 0.3)
    wire = ({'wire_diameter': rng.uniform(0.5e-3, 2e-3), 'youngs_modulus': 2e11} if material
            else {'wire_stiffness': rng.uniform(5e3, 2e5)})
    return CraneGeometry(a=a, b=b, height=rng.uniform(0.4, 2.0), weight=rng.uniform(5.0, 150.0),
                         com_offset=(rng.uniform(-0.2, 0.2) * a, rng.uniform(-0.2, 0.2) * a, 0.0), **wire)


def random_pose(rng: np.random.Generator, g: CraneGeometry):
    """A reachable off-centre, rotated pose of g: (position, angles) and the PoseReport there."""
    for _ in range(200):
        s = min(g.a, g.b)
        pos = (rng.uniform(-0.25, 0.25) * s, rng.uniform(-0.25, 0.25) * s,
               centre_height(g) + rng.uniform(-0.02, 0.02) * g.height)
        ang = rng.uniform(-0.06, 0.06, 3)
        try:
            return pos, ang, at_pose(g, pos, ang)
        except (UnreachablePoseError, ModelError):
            continue
    raise AssertionError('no reachable pose found')


def rel(a, b) -> float:
    return abs(a - b) / abs(b)


# --- the inverse problem ---------------------------------------------------------------------------------------

@pytest.mark.parametrize('seed', range(6))
def test_inverse_problem_holds_the_platform_exactly_at_the_pose(seed):
    rng = np.random.default_rng(seed)
    g = random_crane(rng, material=bool(seed % 2))
    pos, ang, report = random_pose(rng, g)
    held, eq = report.solution.geometry, report.equilibrium
    assert np.abs(eq.residual[:3]).max() <= 1e-10 * g.weight
    assert np.abs(eq.residual[3:]).max() <= 1e-10 * g.weight * g.a
    assert np.all(eq.wire_tensions > 0)
    # The nonlinear solver, from its own start (the symmetric crane's sag, then the offsets), finds that pose.
    rest = solve_equilibrium(held, load=np.zeros(6), xtol=1e-13)
    assert np.abs(rest.displacement - np.asarray(pos)).max() <= 1e-10
    assert np.abs(rest.rotation - eq.rotation).max() <= 1e-9
    assert np.allclose(rest.wire_tensions, eq.wire_tensions, rtol=1e-7)


def test_centre_pose_of_the_lab_model_needs_no_offsets_and_has_the_papers_side_stiffness():
    g = lab_model(0.5, 50.0)
    report = at_pose(g)
    assert np.abs(report.solution.offsets).max() < 1e-12
    assert np.allclose(report.equilibrium.wire_tensions, report.equilibrium.wire_tensions[0], rtol=1e-12)
    from crane_stiffness.model import paper_coefficients
    c = paper_coefficients(g)
    assert rel(report.split.force_min, c.side) < 1e-9   # horizontal, tilt free: K_j of eq. (19)
    assert rel(report.split.moment_min, min(c.k5, c.k4 - c.k2 ** 2 / c.k1)) < 1e-9


def test_unreachable_poses_name_the_wire_and_the_rule():
    g = lab_model(0.5, 50.0)
    with pytest.raises(UnreachablePoseError, match=r'wire_\d would need tension .* can only pull'):
        inverse_pose(g, (0.3, 0.0, 0.0))
    with pytest.raises(GeometryError, match='weight = 0.0: must be > 0'):
        inverse_pose(g.replace(weight=0.0), (0.0, 0.0, 0.0))


# --- split stiffness against finite differences -----------------------------------------------------------------

def _check_split_against_fd(g: CraneGeometry, eq, reported) -> None:
    kf = fd_stiffness(g, eq)
    fd = split_stiffness(kf)
    for name in ('force_min', 'moment_min'):
        assert rel(getattr(reported, name), getattr(fd, name)) <= 1e-6, name
    for name in ('force_matrix', 'moment_matrix'):
        a, b = getattr(reported, name), getattr(fd, name)
        assert np.abs(a - b).max() <= 1e-6 * np.abs(b).max(), name
    # The reported directions are where the nonlinear model is softest: its stiffness there is the minimum.
    c = np.linalg.inv(kf)
    assert rel(1.0 / (reported.force_direction @ c[:3, :3] @ reported.force_direction), fd.force_min) <= 1e-6
    assert rel(1.0 / (reported.moment_axis @ c[3:, 3:] @ reported.moment_axis), fd.moment_min) <= 1e-6


@pytest.mark.parametrize('seed', range(6))
def test_split_stiffness_matches_finite_differences_at_random_off_centre_rotated_poses(seed):
    rng = np.random.default_rng(100 + seed)
    g = random_crane(rng, material=bool(seed % 2))
    _, _, report = random_pose(rng, g)
    _check_split_against_fd(report.solution.geometry, report.equilibrium, report.split)


@pytest.mark.parametrize('seed', range(4))
def test_split_stiffness_matches_finite_differences_at_slack_poses(seed):
    rng = np.random.default_rng(200 + seed)
    g = random_crane(rng, material=bool(seed % 2))
    _, _, report = random_pose(rng, g)
    held = report.solution.geometry
    d = np.array([math.cos(seed), math.sin(seed), 0.0])
    margin = slack_margins(held, report.equilibrium, d[None], 'force').margin[0]
    eq = solve_equilibrium(held, load=np.concatenate([1.3 * margin * d, np.zeros(3)]))
    assert eq.slack.any(), 'the pose must have a slack wire'
    assert np.abs(eq.wire_lengths - held.unstretched_lengths).min() > 1e-7  # no wire on the kink
    _check_split_against_fd(held, eq, split_stiffness(tangent_stiffness(held, eq)))


def test_the_map_reports_what_the_pose_reports():
    g = lab_model(0.5, 50.0)
    pos, ang = (0.012, -0.007, centre_height(g)), (0.0, 0.0, 0.0)
    report = at_pose(g, pos, ang)
    spec = MapSpec(GridAxis('x', -0.02, 0.02, 2), GridAxis('y', -0.02, 0.02, 2), g, z=pos[2], directions=7)
    vals = {name: np.array([spec.fixed(name)]) for name in VARIABLES}
    vals['x'], vals['y'] = np.array([pos[0]]), np.array([pos[1]])
    cols = compute_points(spec, vals)
    assert rel(cols['force_stiffness_min_N_per_m'][0], report.split.force_min) < 1e-9
    assert rel(cols['moment_stiffness_min_Nm_per_rad'][0], report.split.moment_min) < 1e-9
    assert rel(cols['tension_min_N'][0], report.tension_min[0]) < 1e-9
    offsets = [cols[f'offset_{i}_m'][0] for i in range(1, 7)]
    assert np.abs(np.array(offsets) - report.solution.offsets).max() < 1e-12
    margins = slack_margins(report.solution.geometry, report.equilibrium, sphere_directions(7), 'force')
    assert rel(cols['margin_min_N'][0], margins.smallest[0]) < 1e-9


def test_split_batch_equals_the_single_split():
    rng = np.random.default_rng(5)
    ks = []
    for _ in range(4):
        _, _, report = random_pose(rng, random_crane(rng, material=False))
        ks.append(report.stiffness)
    batch = split_stiffness_batch(np.array(ks + [np.full((6, 6), np.nan)]))
    for i, k in enumerate(ks):
        one = split_stiffness(k)
        assert rel(batch['force_min'][i], one.force_min) < 1e-12
        assert rel(batch['moment_min'][i], one.moment_min) < 1e-12
        assert np.allclose(batch['force_dir'][i], one.force_direction, atol=1e-9)
    assert np.isnan(batch['force_min'][-1])


# --- slack margins against bisection ----------------------------------------------------------------------------

def bisect_margin(g: CraneGeometry, d6: np.ndarray, rtol: float = 1e-9) -> float:
    """Smallest s at which solve_equilibrium(g, s·d6) (from rest, with its own continuation) has a slack wire."""
    def slack(s: float) -> bool:
        try:
            return bool(solve_equilibrium(g, load=s * d6, xtol=1e-13).slack.any())
        except ModelError:
            return True
    hi = 0.01 * g.weight * (1.0 if np.any(d6[:3]) else g.a)
    while not slack(hi):
        hi *= 2.0
    lo = 0.0
    while hi - lo > rtol * hi:
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if slack(mid) else (mid, hi)
    return 0.5 * (lo + hi)


@pytest.mark.parametrize('seed', range(4))
def test_slack_margins_agree_with_bisection_on_the_nonlinear_solver(seed):
    rng = np.random.default_rng(300 + seed)
    g = lab_model(rng.uniform(0.4, 1.5), rng.uniform(10.0, 80.0)) if seed % 2 else random_crane(rng, True)
    _, _, report = random_pose(rng, g)
    held = report.solution.geometry
    for kind in ('force', 'moment'):
        dirs = rng.normal(size=(2, 3))
        dirs[:, 2] = -np.abs(dirs[:, 2])  # horizontal to upward: a downward pull may never slacken a wire
        m = slack_margins(held, report.equilibrium, dirs, kind)
        for d6, margin, status in zip(load_directions(dirs, kind), m.margin, m.status):
            assert status == pk.FOUND
            assert rel(margin, bisect_margin(held, d6)) <= 1e-6, (kind, d6)


@pytest.mark.parametrize('height, weight, l0, expected', [(0.5, 50.0, None, 6.6), (None, 5.0, 1.5, 0.22)])
def test_margins_at_the_centre_reproduce_the_sweeps_slack_onsets(height, weight, l0, expected):
    h = height if height is not None else height_from_length(LAB_A, LAB_B, l0)
    g = lab_model(h, weight)
    report = at_pose(g)
    m = slack_margins(report.solution.geometry, report.equilibrium, np.array([[0.0, 1.0, 0.0]]), 'force')
    sweep = slack_threshold(g, 'fy', rtol=1e-8)
    assert rel(m.margin[0], sweep) < 1e-7
    assert round(m.margin[0], 2 if expected < 1 else 1) == expected


def test_a_downward_pull_never_slackens_and_lifting_w_slackens_all():
    g = lab_model(0.5, 50.0)
    report = at_pose(g)
    m = slack_margins(report.solution.geometry, report.equilibrium, np.array([[0, 0, 1.0], [0, 0, -1.0]]))
    assert m.margin[0] == math.inf and m.status[0] == pk.NONE
    assert rel(m.margin[1], g.weight) < 1e-9


# --- symmetry ---------------------------------------------------------------------------------------------------

def test_direction_sets_are_unit_and_threefold_symmetric():
    rot = np.array([[-0.5, -math.sqrt(3) / 2, 0], [math.sqrt(3) / 2, -0.5, 0], [0, 0, 1.0]])
    for n in (1, 2, 3, 64, 65, 256):
        d = sphere_directions(n)
        assert d.shape == (n, 3) and np.allclose(np.linalg.norm(d, axis=1), 1.0)
        turned = d @ rot.T
        assert max(np.abs(d - t).sum(axis=1).min() for t in turned) < 1e-12
    assert np.allclose(np.linalg.norm(circle_directions(12), axis=1), 1.0)


@pytest.mark.parametrize('material', [False, True])
def test_maps_of_the_symmetric_crane_repeat_under_a_120_degree_turn(material):
    rng = np.random.default_rng(7 + material)
    g = random_crane(rng, material).replace(com_offset=(0.0, 0.0, 0.0))
    spec = MapSpec(GridAxis('x', -0.1, 0.1, 2), GridAxis('y', -0.1, 0.1, 2), g, directions=64)
    n = 12
    r = rng.uniform(0.0, 0.3, n) * min(g.a, g.b)
    phi = rng.uniform(0, 2 * math.pi, n)
    vals = {name: np.full(3 * n, spec.fixed(name)) for name in VARIABLES}
    turns = np.concatenate([phi, phi + 2 * math.pi / 3, phi + 4 * math.pi / 3])
    vals['x'], vals['y'] = np.tile(r, 3) * np.cos(turns), np.tile(r, 3) * np.sin(turns)
    cols = compute_points(spec, vals)
    ok = cols['status'] == 0
    assert ok[:n].sum() >= n // 2, 'most points must be reachable'
    assert np.array_equal(ok[:n], ok[n:2 * n]) and np.array_equal(ok[:n], ok[2 * n:])
    for col in ('force_stiffness_min_N_per_m', 'moment_stiffness_min_Nm_per_rad', 'tension_min_N', 'margin_min_N'):
        v = cols[col].reshape(3, n)[:, ok[:n]]
        assert np.abs(v[1] - v[0]).max() <= 1e-9 * np.abs(v[0]).max(), col
        assert np.abs(v[2] - v[0]).max() <= 1e-9 * np.abs(v[0]).max(), col


# --- the parallel batch solver ----------------------------------------------------------------------------------

def _pose_error(g, a, b) -> float:
    pts = np.vstack([np.zeros(3), g.platform_points])
    pa = a.displacement[:, None, :] + pts[None] @ np.swapaxes(a.rotation, 1, 2)
    pb = b.displacement[:, None, :] + pts[None] @ np.swapaxes(b.rotation, 1, 2)
    return float(np.abs(pa - pb).max())


@pytest.mark.parametrize('scale', [1.0, 4.0])
def test_parallel_batch_equals_the_serial_batch(scale):
    g = lab_model(0.8, 60.0)
    rng = np.random.default_rng(int(scale))
    n = 3000
    loads = scale * np.column_stack([rng.uniform(-0.05, 0.05, (n, 2)) * g.weight,
                                     rng.uniform(-0.1, 0.1, n) * g.weight, rng.uniform(-0.02, 0.02, (n, 3))])
    fast = solve_batch_parallel(g, loads, xtol=1e-12)
    slow = solve_batch(g, loads, xtol=1e-12)
    assert _pose_error(g, fast, slow) <= 1e-10
    assert np.array_equal(fast.slack, slow.slack)
    assert np.abs(fast.residual[:, :3]).max() <= 1e-6
    if scale > 1:
        assert fast.slack.any(axis=1).mean() > 0.5  # the hard set is mostly slack cases


def test_parallel_batch_rejects_what_the_serial_batch_rejects():
    g = lab_model(0.5, 50.0)
    with pytest.raises(ModelError, match='W \\+ fz'):
        solve_batch_parallel(g, [[0, 0, 0, 0, 0, 0], [0, 0, -60, 0, 0, 0]])
    with pytest.raises(ValueError, match='finite'):
        solve_batch_parallel(g, [[0, np.nan, 0, 0, 0, 0]])
    assert len(solve_batch_parallel(g, np.zeros((0, 6)))) == 0
