"""The live view's pure parts: the display decimation of the fitted pairs, the fit lines and their band, the scene
of the crane, and the ROS 2 message definitions offered to Foxglove clients. No ROS."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from crane_stiffness.estimation.estimator import StiffnessEstimator
from crane_stiffness.estimation.fit import fit_line, t_quantile
from helpers import PATIENCE_S
from crane_stiffness.estimation.fit_lines import FIT_LINE_FIELDS, band, fit_line_rows
from crane_stiffness.model.geometry import lab_model
from crane_stiffness.view import plot
from crane_stiffness.view.errors import ViewError
from crane_stiffness.view.msgdefs import definition
from crane_stiffness.view.scene import CraneState, scene_update


def _pairs(n: int, segment: int = 1, start: int = 0) -> list[float]:
    out: list[float] = []
    for i in range(start, start + n):
        out += [float(i), i * 1e-6, i * 0.05, 0.0, float(segment)]
    return out


def test_points_are_every_stride_th_pair_of_the_segment_and_never_more_than_capacity():
    buf = plot.PointBuffer(100)
    for start in range(0, 1000, 37):  # messages of 37 pairs
        buf.add(_pairs(min(37, 1000 - start), start=start))
    msg = buf.message()
    shown = [p['t'] for p in msg['loading']]
    assert len(shown) <= 100 and msg['pairs'] == 1000
    assert shown == [float(i) for i in range(0, 1000, msg['stride'])]
    assert msg['stride'] == 16
    buf.add(_pairs(5, segment=2, start=2000))  # a new segment starts afresh
    msg = buf.message()
    assert msg['segment'] == 2 and msg['pairs'] == 5 and [p['t'] for p in msg['loading']] == [2000.0 + i
                                                                                              for i in range(5)]
    with pytest.raises(ViewError, match='max_points = 1'):
        plot.PointBuffer(1)


def test_fit_line_rows_and_band_match_an_independent_least_squares_fit():
    rng = np.random.default_rng(3)
    est = StiffnessEstimator(hysteresis=0.1, window=200)
    x = np.linspace(0, 80e-6, 150)
    y = 53_800.0 * x + 0.02 + rng.normal(0, 0.01, x.size)
    for i, (xi, yi) in enumerate(zip(x, y)):
        est.add(float(i), float(yi), float(xi), load=float(i))  # a rising load: all loading
    rows = fit_line_rows(est)
    loading = dict(zip(FIT_LINE_FIELDS, rows[:len(FIT_LINE_FIELDS)]))
    assert all(math.isnan(v) for v in rows[len(FIT_LINE_FIELDS):])  # no unloading pairs
    ref = fit_line(x, y)
    assert loading['stiffness'] == pytest.approx(ref.stiffness, rel=1e-9)
    assert loading['x_mean'] == pytest.approx(x.mean()) and loading['n'] == x.size
    assert (loading['x_min'], loading['x_max']) == (x.min(), x.max())
    # the band's half width at the mean is t·s/sqrt(n), and at any x t·se(fit) from the classical formula
    s = math.sqrt(np.sum((y - ref.stiffness * x - ref.intercept) ** 2) / (x.size - 2))
    line, lower, upper = band(loading, np.array([x.mean(), x.max()]))
    assert upper[0] - line[0] == pytest.approx(t_quantile(x.size - 2) * s / math.sqrt(x.size), rel=1e-6)
    sxx = np.sum((x - x.mean()) ** 2)
    assert upper[1] - line[1] == pytest.approx(t_quantile(x.size - 2) * s * math.sqrt(
        1 / x.size + (x.max() - x.mean()) ** 2 / sxx), rel=1e-6)
    msg = plot.fit_lines_message(rows)
    assert len(msg['loading']['line']) == plot.LINE_POINTS and msg['unloading']['line'] == []
    json.dumps(msg, allow_nan=False)  # NaN never reaches JSON


def test_scene_carries_the_tensions_as_published_and_draws_slack_wires_dashed():
    geometry = lab_model(0.5, 50.0)
    tensions = [8.6, 0.0, 13.7, 3.5, 3.5, 13.7]
    state = CraneState(position=(0.0, 1e-4, 2e-5), orientation=(0.0, 0.0, 0.0, 1.0), tensions=tensions,
                       force=(0.0, 3.2, 0.0), stamp_s=12.5)
    scene = scene_update(geometry, state, 200.0)
    entity = scene['entities'][0]
    meta = {kv['key']: kv['value'] for kv in entity['metadata']}
    assert [float(meta[f'tension.wire_{i}']) for i in range(1, 7)] == tensions
    wires = entity['lines'][1:]
    assert len(wires[1]['points']) > 2 and len(wires[0]['points']) == 2  # wire_2 slack: dashes
    # the platform's centre drawn at 200 × its displacement, in crane_view (y and z turned over)
    corners = np.array([[p['x'], p['y'], p['z']] for p in entity['triangles'][0]['points']])
    assert corners.mean(axis=0) == pytest.approx([0.0, -0.02, -0.004], abs=1e-12)
    top = np.array([[p['x'], p['y'], p['z']] for p in entity['lines'][0]['points']])
    assert top[:, 2] == pytest.approx([geometry.height] * 3)  # the overhead triangle above, z up
    arrow = entity['arrows'][0]
    assert arrow['shaft_length'] == pytest.approx(0.02 * 3.2)
    assert entity['timestamp'] == {'sec': 12, 'nsec': 500000000}
    json.dumps(scene, allow_nan=False)


def test_message_definitions_are_the_msg_files_and_those_they_use(tmp_path):
    share = tmp_path / 'share'
    (share / 'pkg_a' / 'msg').mkdir(parents=True)
    (share / 'pkg_b' / 'msg').mkdir(parents=True)
    (share / 'pkg_a' / 'msg' / 'Outer.msg').write_text('# comment\nInner[] items\npkg_b/Leaf leaf\nint32 X=3\n')
    (share / 'pkg_a' / 'msg' / 'Inner.msg').write_text('pkg_b/Leaf leaf\nstring<=5 name\n')
    (share / 'pkg_b' / 'msg' / 'Leaf.msg').write_text('float64 value\n')
    text = definition('pkg_a/msg/Outer', [str(tmp_path)])
    sep = '=' * 80
    assert text == ('# comment\nInner[] items\npkg_b/Leaf leaf\nint32 X=3\n'
                    f'{sep}\nMSG: pkg_a/Inner\npkg_b/Leaf leaf\nstring<=5 name\n'
                    f'{sep}\nMSG: pkg_b/Leaf\nfloat64 value\n')
    with pytest.raises(ViewError, match='pkg_a/msg/Missing.msg'):
        definition('pkg_a/msg/Missing', [str(tmp_path)])


def _conforms(value, schema, path='') -> list[str]:
    """Where ``value`` (a decoded JSON message) leaves ``schema``: a field the schema does not name or of another
    type (null stands for a missing number: NaN)."""
    kind = schema['type']
    if kind == 'object':
        if not isinstance(value, dict):
            return [f'{path}: {value!r} is not an object']
        props = schema.get('properties', {})
        out = [f'{path}.{k}: not in the schema' for k in value if k not in props]
        return out + [p for k, v in value.items() if k in props for p in _conforms(v, props[k], f'{path}.{k}')]
    if kind == 'array':
        if not isinstance(value, list):
            return [f'{path}: {value!r} is not an array']
        return [p for i, v in enumerate(value) for p in _conforms(v, schema['items'], f'{path}[{i}]')]
    ok = {'number': lambda v: v is None or (isinstance(v, (int, float)) and not isinstance(v, bool)),
          'integer': lambda v: isinstance(v, int) and not isinstance(v, bool),
          'string': lambda v: isinstance(v, str), 'boolean': lambda v: isinstance(v, bool)}[kind]
    return [] if ok(value) else [f'{path}: {value!r} is not {kind}']


def test_every_derived_channel_has_a_schema_foxglove_apps_parse_and_its_messages_follow_it():
    from crane_stiffness.estimation.live_status import VALUE_FIELDS
    from crane_stiffness.view.jsonschema import foxglove_parsable
    from crane_stiffness.view import stiffness6
    from crane_stiffness.view.scene import SCENE_SCHEMA
    # The rule that refused three channels in Lichtblick ("Player alert schema"): an array without items.
    assert foxglove_parsable({'type': 'object', 'properties': {'wires': {'type': 'array'}}}) == [
        'wires: an array needs "items"']
    schemas = {**plot.SCHEMAS, 'scene': SCENE_SCHEMA, 'stiffness6': stiffness6.SCHEMA}
    for name, schema in schemas.items():
        assert foxglove_parsable(schema) == [], name
    est = StiffnessEstimator(hysteresis=0.1, window=200)
    rng = np.random.default_rng(3)
    x = np.linspace(0.0, 1e-4, 200)
    y = 50_000.0 * x + rng.normal(0.0, 0.01, x.size)
    for i, (xi, yi) in enumerate(zip(x, y)):
        est.add(float(i), float(yi), float(xi), load=float(i))
    rows = fit_line_rows(est)
    buf = plot.PointBuffer(100)
    buf.add([v for i in range(0, 200, 7) for v in (float(i), x[i], y[i], 0.0, 1.0)])
    values = [float(i) for i in range(len(VALUE_FIELDS))] + [math.nan] * len(VALUE_FIELDS)
    geometry = lab_model(0.5, 50.0)
    state = CraneState(position=(0.0, 1e-4, 0.0), orientation=(0.0, 0.0, 0.0, 1.0),
                       tensions=[8.6, 0.0, 13.7, 3.5, 3.5, 13.7], force=(0.0, 3.2, 0.0), stamp_s=1.0)
    messages = {'xy': buf.message(rows, 52_000.0), 'fit_lines': plot.fit_lines_message(rows),
                'prediction': plot.prediction_message(52_000.0, rows, (0.0, 1e-4)),
                'estimate': plot.estimate_message(values, {'loading': {
                    'U': '798.8', 'coverage_factor': '1.96', 'En': '-0.01', 'prediction_U': '3284',
                    'statistical_only': 'false'}}),
                'status': plot.status_message([('loading', 0, 'OK k = 50000'), ('input', 1, 'late')]),
                'wires': plot.wires_message(['wire_1', 'wire_2'], [0.5, 0.5], [8.6, 0.0], 1e-6),
                'scene': scene_update(geometry, state, 200.0, np.diag([1.9e-5, 1.9e-5, 4.9e-7])),
                'stiffness6': stiffness6.stiffness6_message(
                    np.r_[np.eye(6).ravel() * 2.0, np.eye(6).ravel(), np.eye(6).ravel() * 3.0], np.eye(6),
                    (1, 'condition 1e4', {'k2_ci95': '-1 .. 1'}), np.full((6, 6), 0.5))}
    assert set(messages) == set(schemas)
    for name, message in messages.items():
        decoded = json.loads(json.dumps(message, allow_nan=False))
        assert _conforms(decoded, schemas[name]) == [], name


def test_the_page_is_told_the_kind_of_run_in_its_config_and_a_status_names_the_fitted_axis():
    import urllib.request

    from crane_stiffness.view.server import PageServer
    for run in ('one_axis', 'six_axis'):
        page = PageServer('127.0.0.1', 0, 4321, run)
        try:
            with urllib.request.urlopen(f'http://127.0.0.1:{page.port}/config.json', timeout=PATIENCE_S) as reply:
                config = json.loads(reply.read())
        finally:
            page.stop()
        assert config['run'] == run and config['ws_port'] == 4321
    with pytest.raises(ViewError, match="run 'three_axis'"):
        PageServer('127.0.0.1', 0, 4321, 'three_axis')
    status = plot.status_message([('/stiffness_estimator: loading', 0, 'not applicable: six-axis program')],
                                 ('mz', 'N·m/rad'))
    assert (status['axis'], status['unit'], status['level_name']) == ('mz', 'N·m/rad', 'OK')
    assert plot.status_message([])['axis'] == ''


def test_the_estimate_channel_carries_each_branch_U_and_E_n_from_its_status():
    """U, k ∓ U and E_n come from the branch's status (its key/values), beside the values' repeatability; a
    branch whose status states none has them null, and statistical_only says whether U counts no calibration."""
    from crane_stiffness.estimation.live_status import VALUE_FIELDS
    from crane_stiffness.view import stiffness6
    row = dict.fromkeys(VALUE_FIELDS, math.nan)
    row.update(stiffness=53792.9, ci95_low=53782.1, ci95_high=53803.7, prediction=53793.5)
    values = [row[f] for f in VALUE_FIELDS] * 2
    statuses = [('/stiffness_estimator: loading', {'U': '798.8', 'coverage_factor': '1.96', 'En': '-0.000183',
                                                  'prediction_U': '3283.8', 'statistical_only': 'false'}),
                ('/stiffness_estimator: unloading', {'U': '12.1', 'statistical_only': 'true', 'En': 'nan'}),
                ('/stiffness_estimator: input', {'pairs': '10'})]
    message = plot.estimate_message(values, plot.branch_uncertainty(statuses))
    loading, unloading = message['loading'], message['unloading']
    assert loading['U'] == 798.8 and loading['U_low'] == pytest.approx(53792.9 - 798.8)
    assert loading['U_high'] == pytest.approx(53792.9 + 798.8) and loading['coverage_factor'] == 1.96
    assert loading['En'] == -0.000183 and loading['prediction_U'] == 3283.8 and loading['statistical_only'] is False
    assert loading['ci95_low'] == 53782.1  # the repeatability, unchanged beside U
    assert unloading['U'] == 12.1 and unloading['En'] is None and unloading['statistical_only'] is True
    bare = plot.estimate_message(values)  # no status yet
    assert bare['loading']['U'] is None and bare['loading']['U_low'] is None and not bare['loading']['statistical_only']
    # the 6x6 cells: U when one is given (none on the wire yet), null otherwise
    k6 = np.r_[np.eye(6).ravel() * 2.0, np.eye(6).ravel(), np.eye(6).ravel() * 3.0]
    cell = stiffness6.stiffness6_message(k6, np.eye(6), None, np.full((6, 6), 0.25))['rows'][0]['cells'][0]
    assert (cell['U'], cell['U_low'], cell['U_high']) == (0.25, 1.75, 2.25)
    assert stiffness6.stiffness6_message(k6, np.eye(6), None)['rows'][0]['cells'][0]['U'] is None
