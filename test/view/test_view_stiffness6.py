"""The live view's 6×6 parts, pure (no ROS): the /live_view/stiffness6 message from known matrices, and the
compliance ellipsoid in the scene (its radii along the principal axes are the compliance's principal values times
the scale)."""
from __future__ import annotations

import json

import numpy as np
import pytest

from crane_stiffness.model.geometry import lab_model
from crane_stiffness.contract.status import OK, WARN
from crane_stiffness.view import stiffness6
from crane_stiffness.view.errors import ViewError
from crane_stiffness.view.scene import COMPLIANCE_FORCE_N, CraneState, compliance_ellipsoid, scene_update

#: A tangent with the structure of the crane's at rest (K2 at its four entries, rounding noise elsewhere).
TANGENT = np.array([
    [7.0e4, 0.0, 0.0, 0.0, -1.8e4, 1e-13],
    [0.0, 7.0e4, 0.0, 1.8e4, 0.0, 0.0],
    [0.0, 0.0, 2.0e6, -7e-12, 0.0, 0.0],
    [0.0, 1.8e4, 0.0, 1.8e4, 0.0, 0.0],
    [-1.8e4, 0.0, 0.0, 0.0, 1.8e4, 0.0],
    [0.0, 0.0, 0.0, 0.0, 0.0, 1.9e3]])


def _measured() -> np.ndarray:
    rng = np.random.default_rng(6)
    return TANGENT * (1.0 + rng.uniform(-0.03, 0.03, (6, 6))) + rng.normal(0.0, 5.0, (6, 6))


def test_the_message_is_the_measured_k_against_the_tangent_entry_by_entry():
    k = _measured()
    low, high = k - 100.0, k + 250.0
    data = np.concatenate([k.ravel(), low.ravel(), high.ravel()]).tolist()
    status = (WARN, 'condition high', {'k2': '17999', 'k2_ci95': '17800.5 .. 18150.25', 'pairs': '1200'})
    msg = stiffness6.stiffness6_message(data, TANGENT, status)
    assert msg['fit'] is True and (msg['level'], msg['level_name'], msg['message']) == (WARN, 'WARN',
                                                                                          'condition high')
    assert [r['load'] for r in msg['rows']] == ['fx', 'fy', 'fz', 'mx', 'my', 'mz']
    assert [c['displacement'] for c in msg['rows'][0]['cells']] == ['u_x', 'u_y', 'u_z', 'θ_x', 'θ_y', 'θ_z']
    zeros = 0
    for i, row in enumerate(msg['rows']):
        for j, cell in enumerate(row['cells']):
            assert (cell['measured'], cell['ci95_low'], cell['ci95_high'], cell['tangent']) == (
                k[i, j], low[i, j], high[i, j], TANGENT[i, j])
            if TANGENT[i, j] and abs(TANGENT[i, j]) > 1e-6:
                assert not cell['model_zero'] and cell['relative_error'] == pytest.approx(k[i, j] / TANGENT[i, j] - 1)
            else:  # zero in the model, exactly or by rounding: no relative error
                assert cell['model_zero'] and cell['relative_error'] is None
                zeros += 1
    assert zeros == 36 - 10
    k2 = (k[1, 3] + k[3, 1] - k[0, 4] - k[4, 0]) / 4
    assert msg['k2']['measured'] == pytest.approx(k2, rel=1e-12)
    assert (msg['k2']['ci95_low'], msg['k2']['ci95_high']) == (17800.5, 18150.25)
    assert msg['k2']['tangent'] == pytest.approx(1.8e4, rel=1e-12)
    assert msg['k2']['relative_error'] == pytest.approx(k2 / 1.8e4 - 1, rel=1e-9)
    json.dumps(msg, allow_nan=False)


def test_without_a_fit_the_status_alone_and_no_numbers():
    msg = stiffness6.stiffness6_message(None, TANGENT, (OK, 'waiting: no labelled pairs yet', {}))
    assert msg['fit'] is False and msg['level_name'] == 'WAITING'
    cells = [c for r in msg['rows'] for c in r['cells']]
    assert len(cells) == 36 and all(c['measured'] is None and c['relative_error'] is None for c in cells)
    assert msg['k2']['measured'] is None and msg['k2']['ci95_low'] is None
    json.dumps(msg, allow_nan=False)
    with pytest.raises(ViewError, match='108'):
        stiffness6.stiffness6_message([1.0] * 36, TANGENT, None)


def _state() -> CraneState:
    return CraneState(position=(1e-4, 0.0, 0.0), orientation=(0.0, 0.0, 0.0, 1.0), tensions=[8.6] * 6,
                      force=(0.0, 0.0, 0.0), stamp_s=1.0)


def test_the_ellipsoid_radii_are_the_principal_compliances_times_the_scale():
    rng = np.random.default_rng(1)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    principal = np.array([1.9e-5, 1.2e-5, 5e-7])  # m/N
    c = q @ np.diag(principal) @ q.T
    flip = np.diag([1.0, -1.0, -1.0])  # crane_base -> crane_view
    centre = np.array([0.01, -0.02, 0.003])
    loops = compliance_ellipsoid(c, centre, 5000.0)
    assert len(loops) == 3 and all(loop['type'] == 1 for loop in loops)
    radii = {}
    for loop in loops:
        p = np.array([[v['x'], v['y'], v['z']] for v in loop['points']]) - centre
        # each loop lies in the plane of two principal axes; its farthest point along each is that radius
        along = p @ (flip @ q)  # coordinates along the principal axes (crane_view)
        spans = np.abs(along).max(axis=0)
        plane = np.flatnonzero(spans > 1e-12)
        assert len(plane) == 2, spans
        for axis in plane:
            radii.setdefault(int(axis), []).append(spans[axis])
        # every point is on the ellipse: sum of (coordinate / radius)^2 = 1
        r = principal[plane] * 5000.0
        assert np.sum((along[:, plane] / r) ** 2, axis=1) == pytest.approx(np.ones(len(p)), rel=1e-9)
    for axis, spans in radii.items():
        assert spans == pytest.approx([principal[axis] * 5000.0] * 2, rel=1e-12)
    assert compliance_ellipsoid(-c, centre, 5000.0) == []  # not positive definite: nothing drawn
    assert compliance_ellipsoid(np.full((3, 3), np.nan), centre, 5000.0) == []


def test_the_scene_has_the_ellipsoid_at_the_platform_only_with_a_fit_and_states_its_scale():
    geometry = lab_model(0.5, 50.0)
    plain = scene_update(geometry, _state(), 200.0)['entities'][0]
    assert len(plain['lines']) == 7 and 'compliance_scale' not in {kv['key'] for kv in plain['metadata']}
    c = np.diag([1.86e-5, 1.86e-5, 4.9e-7])
    entity = scene_update(geometry, _state(), 200.0, c)['entities'][0]
    meta = {kv['key']: kv['value'] for kv in entity['metadata']}
    assert float(meta['compliance_scale']) == COMPLIANCE_FORCE_N * 200.0
    assert float(meta['compliance_force_n']) == COMPLIANCE_FORCE_N
    assert entity['lines'][:7] == plain['lines'] and len(entity['lines']) == 10
    centre = np.array([0.02, 0.0, 0.0])  # 200 × the platform's 0.1 mm along x
    for loop in entity['lines'][7:]:
        p = np.array([[v['x'], v['y'], v['z']] for v in loop['points']])
        assert p.mean(axis=0) == pytest.approx(centre, abs=1e-12)
        assert np.linalg.norm(p - centre, axis=1).max() == pytest.approx(
            1.86e-5 * float(meta['compliance_scale']), rel=1e-12)


def test_u_is_shown_only_beside_the_fit_it_belongs_to():
    k = _measured()
    data = np.concatenate([k.ravel(), (k - 100.0).ravel(), (k + 250.0).ravel()]).tolist()
    u = 300.0 + 0.02 * np.abs(k)
    expanded = np.concatenate([k.ravel(), (k - u).ravel(), (k + u).ravel()]).tolist()
    np.testing.assert_allclose(stiffness6.expanded_uncertainty(data, expanded), u, rtol=1e-12)
    # the expanded K of another fit (it arrives before or after the K it goes with): no U rather than a wrong one
    other = np.concatenate([(k * 1.001).ravel(), (k - u).ravel(), (k + u).ravel()]).tolist()
    assert stiffness6.expanded_uncertainty(data, other) is None
    assert stiffness6.expanded_uncertainty(None, expanded) is None
    assert stiffness6.expanded_uncertainty(data, None) is None
    with pytest.raises(ViewError, match='108'):
        stiffness6.expanded_uncertainty(data, expanded[:36])
    status = (OK, 'OK', {'k2': '17999', 'k2_ci95': '17800.5 .. 18150.25', 'k2_U': '640.25',
                         'statistical_only': 'true', 'uncertainty': 'statistical only: no calibration declared'})
    msg = stiffness6.stiffness6_message(data, TANGENT, status, stiffness6.expanded_uncertainty(data, expanded))
    assert msg['rows'][2]['cells'][2]['U'] == pytest.approx(u[2, 2], rel=1e-12)
    assert msg['k2']['U'] == 640.25 and msg['statistical_only'] is True
    assert msg['uncertainty'] == 'statistical only: no calibration declared'
    # without this fit's U, neither K2's nor the statement is shown (the status may be of the next fit already)
    bare = stiffness6.stiffness6_message(data, TANGENT, status)
    assert bare['k2']['U'] is None and bare['uncertainty'] == '' and bare['statistical_only'] is False
    assert all(c['U'] is None for r in bare['rows'] for c in r['cells'])
