"""The pose deflection from an array of LVDTs (crane_stiffness.full6.lvdt_array): readings made by the simulated
LVDT (crane_stiffness.sim.sensors.LvdtModel, an independent forward model) solved back exactly, the first-order
solution within its stated bound, the propagated covariance against Monte Carlo scatter, and arrangements that cannot
determine the pose refused with the reason."""
from __future__ import annotations

import math

import numpy as np
import pytest

from crane_stiffness.full6.deflection import pose_deflection
from crane_stiffness.full6.errors import ArrangementError, Full6Error, Full6InputError
from crane_stiffness.full6.lvdt_array import MAX_CONDITION, LvdtArray, lab_arrangement, rotation_matrices
from crane_stiffness.model.geometry import LAB_A, platform_vertices
from crane_stiffness.model.rotation import euler_zxy_to_matrix, rotvec_to_matrix
from crane_stiffness.sim import LvdtModel

REST_U = np.array([0.0, 0.0, 2.4e-5])  # the loaded rest pose: the platform sags under the weight
REST_R = euler_zxy_to_matrix(0.004, -0.002, 0.003)  # and, with an offset load, turns a little


def _random_deflections(rng: np.random.Generator, m: int) -> np.ndarray:
    """Small deflections: up to ~1 mm and ~5 mrad, of random sizes over three decades."""
    size = 10.0 ** rng.uniform(-3.0, 0.0, (m, 1))
    return np.hstack([rng.uniform(-1e-3, 1e-3, (m, 3)), rng.uniform(-5e-3, 5e-3, (m, 3))]) * size


def _lvdt_readings(arrangement: LvdtArray, deflection: np.ndarray) -> np.ndarray:
    """What the simulated LVDTs read, zeroed at the rest pose, with the platform at the deflected pose (the pose of
    full6.deflection: u = u0 + δu, Q = exp([δθ]×)·Q0)."""
    u = REST_U + deflection[:3]
    q = rotvec_to_matrix(deflection[3:]) @ REST_R
    readings = []
    for p, n in zip(arrangement.contact_points, arrangement.directions):
        lvdt = LvdtModel(axis=n, contact_point=p)
        lvdt.zero(REST_U, REST_R)
        readings.append(lvdt.true_displacement(u, q))
    return np.array(readings)


def test_the_lab_arrangement():
    lab = lab_arrangement()
    assert lab.n == 6 and lab.rank == 6
    assert lab.condition_number == pytest.approx(math.sqrt(2.0), rel=1e-12)
    vertices = platform_vertices(LAB_A)
    r = np.linalg.norm(vertices[0])  # 2a/√3
    assert lab.radius == pytest.approx(r, rel=1e-12)
    j0 = lab.first_order_jacobian
    # tangential at the vertices: a translation across the radius and a turn about z (lever arm r)
    np.testing.assert_allclose(j0[:3, 2:5], 0.0, atol=1e-15)
    np.testing.assert_allclose(j0[:3, 5], r, rtol=1e-12)
    np.testing.assert_allclose(np.sum(j0[:3, :2] * vertices[:, :2], axis=1), 0.0, atol=1e-16)  # across the radius
    # vertical: u_z and the tilts about x and y (a × z = (a_y, −a_x, 0))
    np.testing.assert_allclose(j0[3:], np.column_stack([np.zeros((3, 2)), np.ones(3), vertices[:, 1],
                                                        -vertices[:, 0], np.zeros(3)]), atol=1e-15)
    print('lab arrangement: standard errors [m, rad] at 2e-7 m per LVDT',
          np.sqrt(np.diag(lab.solve(np.zeros(6)).covariance)).tolist())


def test_the_exact_derivative_is_the_readings_derivative():
    lab = lab_arrangement(rest_rotation=REST_R)
    d = np.array([3e-4, -1e-4, 2e-4, 0.02, -0.03, 0.05])  # larger than any deflection: the derivative shows
    h = 1e-7
    numeric = np.column_stack([(lab.readings(d + h * e) - lab.readings(d - h * e)) / (2 * h) for e in np.eye(6)])
    np.testing.assert_allclose(lab.jacobian(d), numeric, rtol=0.0, atol=1e-8)
    np.testing.assert_allclose(lab.jacobian(np.zeros(6)), lab.first_order_jacobian, atol=1e-17)
    for theta in (np.zeros(3), np.array([1e-9, 0.0, 2e-9]), np.array([3e-3, -4e-3, 1e-3]), np.array([0.3, 1.0, -0.2])):
        np.testing.assert_allclose(rotation_matrices(theta), rotvec_to_matrix(theta), atol=3e-16)


def test_exact_recovery_without_noise():
    lab = lab_arrangement(rest_rotation=REST_R)
    rng = np.random.default_rng(7)
    truth = _random_deflections(rng, 200)
    readings = np.array([_lvdt_readings(lab, d) for d in truth])
    # The arrangement's forward model is the simulated LVDT's, to rounding (of the contact points' coordinates,
    # ~0.13 m: a few 1e-17 m).
    np.testing.assert_allclose(lab.readings(truth), readings, rtol=0.0, atol=4 * np.finfo(float).eps * lab.radius)
    solved = lab.solve(readings)
    assert solved.converged and solved.iterations <= 5
    u_error = np.abs(solved.deflection[:, :3] - truth[:, :3]).max(axis=1)
    theta_error = np.abs(solved.deflection[:, 3:] - truth[:, 3:]).max(axis=1)
    assert np.all(u_error <= 1e-9 * np.abs(truth[:, :3]).max(axis=1))
    assert np.all(theta_error <= 1e-9 * np.abs(truth[:, 3:]).max(axis=1))
    worst = max((u_error / np.abs(truth[:, :3]).max(axis=1)).max(),
                (theta_error / np.abs(truth[:, 3:]).max(axis=1)).max())
    print(f'exact: worst relative error {worst:.2e} after {solved.iterations} steps')
    np.testing.assert_allclose(solved.residuals, 0.0, atol=4 * np.finfo(float).eps * lab.radius)
    # One at a time gives the same; and the deflection of the pose the readings came from (full6.deflection) too.
    one = lab.solve(readings[17])
    np.testing.assert_allclose(one.deflection, solved.deflection[17], rtol=1e-14, atol=1e-19)
    pose = pose_deflection(REST_U + truth[17, :3], rotvec_to_matrix(truth[17, 3:]) @ REST_R, REST_U, REST_R)
    np.testing.assert_allclose(one.deflection, pose, rtol=1e-9, atol=1e-18)


def test_first_order_error_within_its_bound():
    lab = lab_arrangement(rest_rotation=REST_R)
    truth = _random_deflections(np.random.default_rng(8), 200)
    first = lab.solve(lab.readings(truth), exact=False)
    assert first.iterations == 0
    error = np.abs(first.deflection - truth)
    bound = lab.second_order_bound(truth)
    assert np.all(error <= bound)
    print(f'first order: error / bound at most {np.max(error / bound):.3f}; worst angle error '
          f'{error[:, 3:].max():.2e} rad at up to {np.abs(truth[:, 3:]).max():.1e} rad')
    assert error[:, 3:].max() > 1e-8  # the second order is there: the exact iteration is not for show
    np.testing.assert_allclose(first.deflection, lab.readings(truth) @ lab.first_order_projection.T, atol=0.0)


@pytest.mark.parametrize('exact', [True, False])
def test_covariance_matches_monte_carlo_scatter(exact):
    noise = np.array([2e-7, 2e-7, 4e-7, 2e-7, 3e-7, 1e-7])  # unequal LVDTs: the weighting matters
    lab = lab_arrangement(noise_std=noise, rest_rotation=REST_R)
    truth = np.array([4e-4, -2e-4, 3e-4, 2e-3, -1e-3, 3e-3])
    m = 20_000
    readings = lab.readings(truth) + np.random.default_rng(9).standard_normal((m, 6)) * noise
    solved = lab.solve(readings, exact=exact)
    assert solved.converged
    # The scatter about the solution of the noise-free readings: the truth (exact), or the truth plus the first
    # order's own second-order error (first order: d = P·r, the noise enters as P·noise exactly).
    centre = lab.solve(lab.readings(truth), exact=exact).deflection
    predicted = solved.covariance.mean(axis=0)
    # Whitened by the predicted covariance, the scatter is the identity; 5 standard errors of a sample covariance
    # (diagonal sqrt(2 / m), off-diagonal sqrt(1 / m)) and of a mean (sqrt(1 / m)).
    whiten = np.linalg.inv(np.linalg.cholesky(predicted))
    z = (solved.deflection - centre) @ whiten.T
    sample = np.cov(z, rowvar=False)
    print(f'exact={exact}: whitened scatter diagonal {np.round(np.diag(sample), 3).tolist()}, mean '
          f'{np.round(z.mean(axis=0), 3).tolist()}')
    assert np.all(np.abs(np.diag(sample) - 1.0) < 5 * math.sqrt(2.0 / m))
    assert np.all(np.abs(sample - np.diag(np.diag(sample))) < 5 * math.sqrt(1.0 / m))
    assert np.all(np.abs(z.mean(axis=0)) < 5 * math.sqrt(1.0 / m))
    # The covariance hardly moves over the scatter of the solutions (first order: not at all).
    np.testing.assert_allclose(whiten @ solved.covariance @ whiten.T, np.broadcast_to(np.eye(6), (m, 6, 6)),
                               rtol=0.0, atol=1e-4)


def _lab_points_and_directions():
    vertices = platform_vertices(LAB_A)
    radial = vertices / np.linalg.norm(vertices, axis=1)[:, None]
    return vertices, radial, np.cross([0.0, 0.0, 1.0], radial)


def test_an_arrangement_that_cannot_determine_the_pose_is_refused_naming_why():
    vertices, radial, tangential = _lab_points_and_directions()
    down = np.tile([0.0, 0.0, 1.0], (3, 1))
    with pytest.raises(ArrangementError, match="'five': 5 LVDTs cannot determine") as info:
        LvdtArray(np.vstack([vertices, vertices[:2]]), np.vstack([tangential, down[:2]]), name='five')
    assert info.value.rank == 5
    # All vertical: only u_z and the two tilts are seen.
    with pytest.raises(ArrangementError, match="'all vertical': sees only 3 of the 6 independent motions; no LVDT "
                       r"reads the motions ux; uy; thz·L \(L = ") as info:
        LvdtArray(np.vstack([vertices, 0.5 * vertices]), np.vstack([down, down]), name='all vertical')
    assert info.value.rank == 3 and info.value.condition == math.inf
    # Horizontal ones pointing at the centre: no LVDT sees the turn about z, and the error says so.
    with pytest.raises(ArrangementError, match=r"'radial': sees only 5 of the 6 .* reads the motion thz·L \(") as info:
        LvdtArray(np.vstack([vertices, vertices]), np.vstack([radial, down]), name='radial')
    assert info.value.rank == 5 and np.abs(info.value.unseen).argmax() == 5
    # Nearly radial (2 mrad off): the turn about z is seen through a 2e-3 share of three LVDTs, u_z through three
    # whole ones: 1 / 2e-3 = 500 times less well.
    skew = radial + 2e-3 * tangential
    with pytest.raises(ArrangementError, match=rf"'nearly radial': condition number .* exceeds {MAX_CONDITION:g}"
                       r": the motion thz·L \(L = 0.132 m, the RMS lever arm\) is seen") as info:
        LvdtArray(np.vstack([vertices, vertices]), np.vstack([skew, down]), name='nearly radial')
    assert info.value.rank == 6 and info.value.condition == pytest.approx(500.0, rel=1e-3)  # 1 / 2e-3
    # ... which a looser, stated limit accepts: then it solves, with the large error it predicts for θ_z.
    loose = LvdtArray(np.vstack([vertices, vertices]), np.vstack([skew, down]), max_condition=1e4)
    assert loose.solve(np.zeros(6)).stderr[5] > 100 * lab_arrangement().solve(np.zeros(6)).stderr[5]
    assert issubclass(ArrangementError, Full6Error)


@pytest.mark.parametrize('field, kwargs, rule', [
    ('directions', {'directions': np.vstack([np.zeros(3), np.eye(3), np.eye(3)[:2]])}, 'row 0 is zero'),
    ('directions', {'directions': np.eye(3)}, 'must be 6 rows'),
    ('noise_std', {'noise_std': 0.0}, '> 0'),
    ('contact_points', {'contact_points': np.full((6, 3), np.nan)}, 'finite'),
    ('rest_rotation', {'rest_rotation': 2 * np.eye(3)}, 'rotation matrix'),
])
def test_bad_inputs_are_refused_naming_the_field(field, kwargs, rule):
    vertices, _, tangential = _lab_points_and_directions()
    args = {'contact_points': np.vstack([vertices, vertices]),
            'directions': np.vstack([tangential, np.tile([0.0, 0.0, 1.0], (3, 1))])} | kwargs
    with pytest.raises(Full6InputError, match=rule) as info:
        LvdtArray(**args)
    assert info.value.field == field
    with pytest.raises(Full6InputError, match='6 finite numbers'):
        lab_arrangement().solve(np.zeros(5))
