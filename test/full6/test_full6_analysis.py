"""The offline 6×6 analysis of a six-axis session bag (crane_stiffness.analysis.full6, ``crane-stiffness analyze``):
the tangent recovered from a synthetic MCAP session, its numbers those of identify() on full6_pairs of the bag's
arrays, the JSON, the figures, the printed table, and the settings read from the recorded parameters.

The session (crane_stiffness.testing.synthetic_full6_bag) plays config/program_full6.yaml on the lab model: the pose
at the rest pose plus C·w (C the exact tangent compliance) with 2 µm / 20 µrad of noise at 250 Hz, the load cell at
1 kHz mounted rotated, off-centre and measuring the reaction (recorded as the stiffness_estimator's mounting), and
settle_s = 0.6 s recorded as the stiffness6_estimator's parameter (the default is 0.5 s).
"""
from __future__ import annotations

import json

import numpy as np
import pytest
from matplotlib import image as mpimg

from helpers import REPO
from crane_stiffness.contract import topics
from crane_stiffness.analysis.full6 import analyze_full6
from crane_stiffness.analysis.full6_load import DEFAULT_SETTLE_S, is_full6_bag, read_settings
from crane_stiffness.contract.axes import AXES
from crane_stiffness.bag import BagReader
from crane_stiffness.cli.main import main as cli_main
from crane_stiffness.estimation.frames import SensorMount
from crane_stiffness.full6.identify import identify
from crane_stiffness.full6.pairs import DEFAULT_MAX_AGE_S, DEFAULT_MAX_GAP_S, full6_pairs
from crane_stiffness.model import lab_model
from crane_stiffness.model.rotation import euler_zxy_to_matrix
from crane_stiffness.bag.session_metadata import read_session
from crane_stiffness.sim.program import LoadProgram, Segment, load_program_file
from crane_stiffness.testing.synthetic_full6_bag import write_full6_session

SETTLE_S = 0.6
MOUNT = SensorMount(euler_zxy_to_matrix(0.7, 0.2, -0.1), np.array([0.01, -0.02, -0.05]), True)


@pytest.fixture(scope='module')
def session(tmp_path_factory):
    path = tmp_path_factory.mktemp('full6') / 'six_axis'
    return write_full6_session(path, load_program_file(REPO / 'config' / 'program_full6.yaml'),
                               lab_model(0.5, 50.0), seed=11, mount=MOUNT,
                               estimator6={'settle_s': SETTLE_S, 'max_gap_s': 0.005, 'max_age_s': 0.5})


@pytest.fixture(scope='module')
def analysed(session, tmp_path_factory):
    out = tmp_path_factory.mktemp('full6_out')
    result = analyze_full6(session.path, out)
    return result, json.loads((out / 'full6.json').read_text()), out


def test_the_bag_holds_the_streams_at_their_rates(session):
    with BagReader(session.path) as reader:
        counts = {t: i.count for t, i in reader.topics.items()}
        stamps = reader.decode_topics([topics.POSE_SENSOR_POSE, topics.LOAD_CELL_WRENCH], columns=True)
    assert counts == {topics.WRENCH_COMMAND: 10001, topics.LOAD_CELL_WRENCH: 101001, topics.POSE_SENSOR_POSE: 25251}
    assert np.allclose(np.diff(stamps[topics.POSE_SENSOR_POSE]['stamp_s']), 0.004, atol=1e-6)
    assert np.allclose(np.diff(stamps[topics.LOAD_CELL_WRENCH]['stamp_s']), 0.001, atol=1e-6)
    assert is_full6_bag(session.path)


def test_recovers_the_tangent(session, analysed):
    _, js, _ = analysed
    assert js['status']['level'] == 'OK', js['status']['message']
    assert js['pairs']['steps'] == 26 and js['pairs']['n'] > 20_000  # 24 steps and the two baselines
    k = np.array(js['stiffness']['value'])
    low, high = np.array(js['stiffness']['low']), np.array(js['stiffness']['high'])
    assert np.all(np.isfinite(low)) and np.all(low < k) and np.all(k < high)
    err = np.diag(k) / np.diag(session.tangent) - 1.0
    assert np.all(np.abs(err) < 0.01), err
    assert [d['relative_error'] for d in js['diagonal']] == pytest.approx(err.tolist(), rel=1e-9)
    k2 = js['k2']
    assert k2['sign'] == '+' and k2['sign_as_tangent']
    assert abs(k2['value'] / k2['tangent'] - 1.0) < 0.03
    assert k2['low'] < k2['value'] < k2['high']
    assert k2['tangent'] == pytest.approx(17898.6, rel=1e-5) and k2['paper'] == pytest.approx(k2['tangent'], rel=1e-6)
    # The four signed entries agree with K2.
    assert [e['sign'] * e['measured'] for e in k2['entries'].values()] == pytest.approx([k2['value']] * 4, rel=0.03)
    assert js['comparison']['covered']['stiffness'] >= 32  # 36 × 95 % = 34.2 expected
    assert js['condition'] == pytest.approx(2.67, abs=0.01)


def test_numbers_are_identify_on_full6_pairs_of_the_bag(session, analysed):
    """The bag's arrays decoded here, the recorded mount applied, paired with the recorded settle_s: the same fit."""
    result, js, _ = analysed
    with BagReader(session.path) as reader:
        a = reader.decode_topics([topics.WRENCH_COMMAND, topics.LOAD_CELL_WRENCH, topics.POSE_SENSOR_POSE],
                                 columns=True)
        mount = SensorMount.from_params(read_session(reader)['sensors']['stiffness_estimator'])  # as recorded
    np.testing.assert_allclose(mount.matrix(), MOUNT.matrix(), rtol=0, atol=1e-15)
    c, w, p = a[topics.WRENCH_COMMAND], a[topics.LOAD_CELL_WRENCH], a[topics.POSE_SENSOR_POSE]
    pairs = full6_pairs(c['stamp_s'], np.column_stack([c[k] for k in AXES]), w['stamp_s'], w['log_time_ns'] * 1e-9,
                        mount.apply(np.column_stack([w[k] for k in AXES])), p['stamp_s'], p['log_time_ns'] * 1e-9,
                        np.column_stack([p['x'], p['y'], p['z']]),
                        np.column_stack([p['qx'], p['qy'], p['qz'], p['qw']]), settle_s=SETTLE_S)
    fit = identify(pairs.wrench, pairs.deflection, pairs.step)
    assert js['pairs']['n'] == len(pairs) == fit.n
    for key, ours in (('value', fit.stiffness), ('low', fit.stiffness_low), ('high', fit.stiffness_high),
                      ('stderr', fit.stiffness_stderr)):
        np.testing.assert_allclose(js['stiffness'][key], ours, rtol=1e-12, atol=0)
    for key, ours in (('value', fit.compliance), ('low', fit.compliance_low), ('high', fit.compliance_high)):
        np.testing.assert_allclose(js['compliance'][key], ours, rtol=1e-12, atol=0)
    assert [js['k2'][k] for k in ('value', 'low', 'high')] == pytest.approx([fit.k2, fit.k2_low, fit.k2_high],
                                                                            rel=1e-12, abs=0)
    assert js['condition'] == pytest.approx(fit.condition, rel=1e-12)
    assert js['status']['message'] == fit.message == result.fit.message
    # Paired with the default settle_s instead, the pairs differ: the recorded 0.6 s was used.
    assert len(full6_pairs(c['stamp_s'], np.column_stack([c[k] for k in AXES]), w['stamp_s'],
                           w['log_time_ns'] * 1e-9, np.column_stack([w[k] for k in AXES]), p['stamp_s'],
                           p['log_time_ns'] * 1e-9, np.column_stack([p['x'], p['y'], p['z']]),
                           np.column_stack([p['qx'], p['qy'], p['qz'], p['qw']]),
                           settle_s=DEFAULT_SETTLE_S)) > len(pairs)


def test_json_names_the_settings_and_the_comparison(analysed):
    _, js, _ = analysed
    s = js['settings']
    assert (s['settle_s'], s['max_gap_s'], s['max_age_s']) == (SETTLE_S, 0.005, 0.5)
    assert s['source'] == 'stiffness6_estimator parameters' and s['sensor_reaction'] is True
    assert 'stiffness_estimator' in s['mount_source']
    np.testing.assert_allclose(s['sensor_rotation'], MOUNT.rotation, atol=1e-12)
    zero = np.array(js['comparison']['tangent_zero'])
    assert zero.sum() == 36 - 6 - 4  # only the diagonal and the four K2 entries are not zeros of the model
    rel = js['comparison']['stiffness_relative_error']
    assert all((rel[i][j] is None) == bool(zero[i, j]) for i in range(6) for j in range(6))


def test_figures_exist_and_show_something(analysed):
    result, _, out = analysed
    names = sorted(p.split('/')[-1] for p in result.files)
    assert names == ['full6.json', 'full6_ellipsoids.png', 'full6_report.md', 'full6_stiffness.png']
    for name, shape in (('full6_stiffness.png', (640, 1900)), ('full6_ellipsoids.png', (900, 1400))):
        pixels = mpimg.imread(out / name)
        assert pixels.shape[:2] == shape
        rgb = pixels[..., :3]
        inked = np.any(rgb < 0.9, axis=-1).mean()  # share of pixels that are not (near) white
        assert 0.02 < inked < 0.9, (name, inked)
        colours = np.unique((rgb * 255).astype(np.uint8).reshape(-1, 3), axis=0)
        assert len(colours) > 100, (name, len(colours))
    report = (out / 'full6_report.md').read_text()
    assert '![full6 stiffness](full6_stiffness.png)' in report and 'K2 = +' in report


def test_analyze_command_prints_the_table(session, tmp_path, capsys):
    assert cli_main(['analyze', str(session.path), '--out', str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert out.startswith('six-axis session six_axis')
    assert 'status OK: 26 steps' in out
    for axis in ('K[fx, u_x]', 'K[fy, u_y]', 'K[fz, u_z]', 'K[mx, θ_x]', 'K[my, θ_y]', 'K[mz, θ_z]'):
        assert axis in out
    assert 'K2 = +1' in out and "(as the tangent's)" in out and '95 % CI' in out
    assert 'no /lvdt/displacement in the bag: no 1-D analysis' in out
    assert (tmp_path / 'full6.json').exists() and not (tmp_path / 'analysis.json').exists()


def test_settings_from_the_recorded_parameters():
    problems: list[str] = []
    s = read_settings({}, problems)
    assert (s.settle_s, s.max_gap_s, s.max_age_s, s.wrench_noise) == (0.5, DEFAULT_MAX_GAP_S, DEFAULT_MAX_AGE_S, None)
    assert s.mount.is_identity and s.source.startswith('defaults') and not problems
    own = {'settle_s': -1.0, 'max_gap_s': 0.01, 'wrench_noise': [0.01] * 6, 'sensor_position': [0.0, 0.0, 0.1]}
    s = read_settings({'stiffness6_estimator': own, 'stiffness_estimator': {'sensor_reaction': True}}, problems)
    assert (s.settle_s, s.max_gap_s, s.wrench_noise) == (0.5, 0.01, (0.01,) * 6)
    assert problems == ['stiffness6_estimator parameter settle_s = -1.0 is invalid (a number >= 0 (s)): using 0.5']
    assert s.mount.position.tolist() == [0.0, 0.0, 0.1] and not s.mount.reaction  # its own mount first
    s = read_settings({'stiffness_estimator': {'sensor_reaction': True}}, problems)
    assert s.mount.reaction and 'stiffness_estimator' in s.mount_source


def test_a_session_the_fit_cannot_determine_is_reported_not_drawn(tmp_path, capsys):
    """Four side-force steps and a baseline: five steps, eight needed. Status ERROR with the reason, no figures,
    the JSON's numbers null."""
    segments = [Segment('hold', 'fx', 0.0, 1.0)] + [Segment('step', 'fy', v, 1.5) for v in (1.0, -1.0, 2.0, -2.0)]
    bag = write_full6_session(tmp_path / 'short', LoadProgram(segments, name='short', rate_hz=100.0),
                              lab_model(0.5, 50.0)).path
    assert cli_main(['analyze', str(bag), '--out', str(tmp_path / 'out')]) == 0
    out = capsys.readouterr().out
    assert 'status ERROR undetermined: 5 distinct steps, at least 8 needed' in out
    assert 'K2: – (no numbers from the fit)' in out and 'no figures' in out
    js = json.loads((tmp_path / 'out' / 'full6.json').read_text())
    assert js['status']['level'] == 'ERROR' and js['k2']['value'] is None
    assert js['stiffness']['value'][0][0] is None and js['diagonal'][0]['covers'] is None
    assert js['settings']['source'].startswith('defaults') and js['settings']['settle_s'] == DEFAULT_SETTLE_S
    assert sorted(p.name for p in (tmp_path / 'out').iterdir()) == ['full6.json', 'full6_report.md']
