"""Offline analysis of recorded sessions (crane_stiffness.analysis.analyze, .compare): known truth recovered, the
recorded live estimate reproduced, outputs written, damaged input. (The vectorized pairing, branch labels and input
checks it uses are pinned to the live estimator's beside them: test_sync, test_branch, test_inputs.)

Sessions are synthetic bags written like session_recorder writes them (crane_stiffness.testing.synthetic); the
live estimate in them comes from the estimator's own core (LiveStiffness) run over the messages in arrival order.
"""
from __future__ import annotations

import json
import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest

from helpers import REPO, run_without_ros
from crane_stiffness.contract import topics
from crane_stiffness.analysis.analyze import analyze_session
from crane_stiffness.analysis.compare import compare_sessions
from crane_stiffness.analysis.errors import SessionAnalysisError
from crane_stiffness.testing.synthetic import write_synthetic_session
from crane_stiffness.bag import (BagDamageWarning, BagFormatError, BagReader, BagWriter, McapFile,
                                 TopicNotFoundError)
from crane_stiffness.cli.main import main as cli_main
from crane_stiffness.estimation.live import VALUE_FIELDS
from crane_stiffness.model import lab_model, paper_coefficients
from crane_stiffness.serde import (decode_diagnostic_array, decode_float64_multiarray, decode_string,
                                   encode_float64_multiarray, encode_stamped, encode_string)
from crane_stiffness.sim.program import LoadProgram, Segment, load_program_file

K_TRUE = 53_793.5  # N/m, the linear truth of the synthetic sessions: the lab model's tangent along fy, so they agree


def short_program(repeats: int = 2) -> LoadProgram:
    """0 → 1 → 2 → 3 N and back in ramps and 0.6 s holds, on fy: 6.6 s per repeat."""
    segs = [Segment('hold', 'fy', 0.0, 0.6)]
    for level in (1.0, 2.0, 3.0, 2.0, 1.0, 0.0):
        segs += [Segment('ramp', 'fy', level, 0.4), Segment('hold', 'fy', level, 0.6)]
    return LoadProgram(segs, repeats=repeats, name='short_steps', rate_hz=100.0)


@pytest.fixture(scope='module')
def linear_session(tmp_path_factory):
    """Two repeats, linear truth K_TRUE, the live estimator's output recorded."""
    path = tmp_path_factory.mktemp('sessions') / 'linear'
    return write_synthetic_session(path, short_program(2), geometry=lab_model(0.5, 50.0), stiffness=K_TRUE,
                                   live=True, seed=3, chunk_size=256 * 1024)


@pytest.fixture(scope='module')
def analysis(linear_session, tmp_path_factory):
    out = tmp_path_factory.mktemp('out')
    return analyze_session(linear_session.path, out, formats=('png', 'svg'), reports=('md', 'html'))


def test_cdr_helpers_match_rclpy_serialization():
    serialization = pytest.importorskip('rclpy.serialization')
    from std_msgs.msg import Float64MultiArray, MultiArrayDimension, String
    msg = Float64MultiArray(data=[1.5, -2.0, float('nan')])
    msg.layout.dim = [MultiArrayDimension(label='branch', size=2, stride=30),
                      MultiArrayDimension(label='field', size=15, stride=15)]
    raw = serialization.serialize_message(msg)
    dims, data = decode_float64_multiarray(raw)
    assert dims == [('branch', 2, 30), ('field', 15, 15)]
    assert data[:2].tolist() == [1.5, -2.0] and np.isnan(data[2])
    back = serialization.deserialize_message(encode_float64_multiarray([1.5, -2.0, 3.0], dims), Float64MultiArray)
    assert [(d.label, d.size, d.stride) for d in back.layout.dim] == dims and list(back.data) == [1.5, -2.0, 3.0]
    assert decode_string(serialization.serialize_message(String(data='{"state": "done"}'))) == '{"state": "done"}'
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
    diag = DiagnosticArray(status=[
        DiagnosticStatus(level=b'\x01', name='/stiffness_estimator: loading', message='k = 5', hardware_id='est'),
        DiagnosticStatus(level=b'\x00', name='/stiffness_estimator: input', message='ok', hardware_id='est',
                         values=[KeyValue(key='pairs', value='12'), KeyValue(key='force_received', value='13')])])
    diag.header.frame_id = 'x'
    assert decode_diagnostic_array(serialization.serialize_message(diag)) == [
        (1, '/stiffness_estimator: loading', 'k = 5', 'est', {}),
        (0, '/stiffness_estimator: input', 'ok', 'est', {'pairs': '12', 'force_received': '13'})]
    assert serialization.deserialize_message(encode_string('héllo'), String).data == 'héllo'


# ------------------------------------------------------------------------------------- results and truth --
def test_fits_recover_the_known_stiffness(analysis, linear_session):
    for branch in ('loading', 'unloading'):
        fit = analysis.branch_fits[branch]
        assert fit.ci95_low < K_TRUE < fit.ci95_high, (branch, fit)
        assert fit.stiffness == pytest.approx(K_TRUE, rel=2e-3)
        assert fit.r2 > 0.999 and abs(fit.nonlinearity) < 0.01
        holds = analysis.hold_fits[branch]
        assert holds.stiffness == pytest.approx(K_TRUE, rel=2e-3) and holds.n == (7 if branch == 'loading' else 6)
    assert analysis.pairing['pairs'] == linear_session.counts[topics.LOAD_CELL_WRENCH]
    assert analysis.pairing['force_unmatched'] == 0 and analysis.pairing['replayed_stretches'] == 0
    # 7 holds per repeat (0, 1, 2, 3, 2, 1, 0) merge to 13 over two repeats (the final 0 joins the next start).
    steps = analysis.steps
    assert [s.level for s in steps] == [0.0, 1.0, 2.0, 3.0, 2.0, 1.0, 0.0, 1.0, 2.0, 3.0, 2.0, 1.0, 0.0]
    assert [s.approach for s in steps] == ['loading'] * 4 + ['unloading'] * 3 + ['loading'] * 3 + ['unloading'] * 3
    assert [s.repeat for s in steps] == [0] * 7 + [1] * 6
    for s in steps:
        assert s.force_mean == pytest.approx(s.level, abs=3e-3)
        assert s.displacement_mean == pytest.approx(s.level / K_TRUE, abs=1e-7)
        assert s.n > 300
    assert [c.repeat for c in analysis.cycle_fits] == [0, 1]
    for c in analysis.cycle_fits:
        assert c.loading.stiffness == pytest.approx(K_TRUE, rel=5e-3)
    g = lab_model(0.5, 50.0)
    assert analysis.model.tangent_at_rest == pytest.approx(paper_coefficients(g).side, rel=1e-9)
    assert analysis.model.eq18 == pytest.approx(paper_coefficients(g).side, rel=1e-9)
    assert analysis.model.lvdt_scale == 1.0
    assert analysis.problems == [] and analysis.missing_topics == []


def test_the_recorded_live_estimate_is_reproduced(analysis, linear_session):
    live = analysis.live
    assert live is not None
    rows = linear_session.live_values
    index = {f: i for i, f in enumerate(VALUE_FIELDS)}
    assert live.sample_stamp_s == rows[0, index['sample_stamp']]
    for b, branch in enumerate(('loading', 'unloading')):
        if branch == 'unloading' and np.isnan(rows[b, index['stiffness']]):
            # its window lies in the last hold: no spread beyond the noise, no estimate live nor offline
            assert np.isnan(live.offline[branch]['stiffness']) and live.max_rel_diff[branch] == 0.0
            assert live.offline[branch]['x_noise'] == live.live[branch]['x_noise'] > 0.0
            continue
        assert live.live[branch]['stiffness'] == rows[b, index['stiffness']]
        for field in ('stiffness', 'intercept', 'stderr', 'ci95_low', 'ci95_high', 'r2', 'residual_rms',
                      'rls_stiffness', 'x_noise'):
            assert live.offline[branch][field] == pytest.approx(live.live[branch][field], rel=1e-9, abs=1e-12), \
                (branch, field)
        assert live.offline[branch]['n'] == live.live[branch]['n'] == 500
        assert live.max_rel_diff[branch] < 1e-9


def test_the_nonlinear_model_is_matched_and_slack_softening_seen(tmp_path):
    program = load_program_file(REPO / 'config' / 'program_side_force_slack.yaml')
    g = lab_model(0.5, 50.0)
    write_synthetic_session(tmp_path / 'slack', program, geometry=g, displacement_noise=1e-7, seed=5)
    a = analyze_session(tmp_path / 'slack', write_files=False)
    assert a.live is None and topics.STIFFNESS_VALUES in a.missing_topics
    assert any('no live estimate' in p for p in a.problems)
    for s in a.steps:
        assert s.displacement_mean == pytest.approx(s.model_displacement, abs=3e-8 + 5e-3 * abs(s.model_displacement))
    curves = a.model.curves
    assert max(curves['slack_wires']) > 0  # the 9 N side force slackens wires (paper Fig. 9)
    assert a.hold_fits['loading'].nonlinearity > 0.05  # softening: the curve bends away from the linear model
    assert a.branch_fits['loading'].stiffness < 0.9 * a.model.tangent_at_rest


def test_outputs_written(analysis):
    out = Path(analysis.files[0]).parent
    names = sorted(Path(f).name for f in analysis.files)
    assert names == ['analysis.json', 'budget.png', 'budget.svg', 'force_displacement.png', 'force_displacement.svg',
                     'report.html', 'report.md', 'timeseries.png', 'timeseries.svg']
    for name in ('force_displacement.png', 'timeseries.png'):
        assert (out / name).read_bytes()[:8] == b'\x89PNG\r\n\x1a\n' and (out / name).stat().st_size > 20_000
    assert '<svg' in (out / 'force_displacement.svg').read_text()[:2000]
    md = (out / 'report.md').read_text()
    assert '## Live estimate reproduced' in md and '![force displacement](force_displacement.png)' in md
    assert f'| all pairs of the branch | loading | {analysis.branch_fits["loading"].stiffness:.6g} |' in md
    html = (out / 'report.html').read_text()
    assert html.startswith('<!DOCTYPE html>') and html.count('<table>') >= 5 and 'timeseries.svg' in html
    data = json.loads((out / 'analysis.json').read_text())
    assert data['branch_fits']['loading']['stiffness'] == analysis.branch_fits['loading'].stiffness
    assert len(data['steps']) == 13 and data['live']['max_rel_diff']['loading'] < 1e-9
    assert data['program']['name'] == 'short_steps' and data['geometry']['weight'] == 50.0


def test_compare_sessions_table_and_overlay(linear_session, tmp_path):
    other = write_synthetic_session(tmp_path / 'stiffer', short_program(1), geometry=lab_model(0.5, 50.0),
                                    stiffness=2 * K_TRUE, seed=4)
    c = compare_sessions([linear_session.path, other.path], tmp_path / 'cmp', reports=('md', 'html'))
    assert [r['session'] for r in c.rows] == ['linear', 'stiffer']
    assert c.rows[0]['loading_k'] == pytest.approx(K_TRUE, rel=2e-3)
    assert c.rows[1]['loading_k'] == pytest.approx(2 * K_TRUE, rel=2e-3)
    assert c.rows[0]['live_loading_k'] == pytest.approx(linear_session.live_values[0, 0], rel=1e-12)
    assert sorted(Path(f).name for f in c.files) == ['compare.html', 'compare.json', 'compare.md',
                                                       'compare_force_displacement.png']
    assert '| stiffer |' in (tmp_path / 'cmp' / 'compare.md').read_text()


# -------------------------------------------------------------------------------------- damaged input --
def test_truncated_bag_is_analysed_from_its_readable_part(linear_session, tmp_path):
    damaged = tmp_path / 'cut'
    shutil.copytree(linear_session.path, damaged)
    (damaged / 'metadata.yaml').unlink()  # as after a crash
    mcap = damaged / 'linear_0.mcap'
    data = mcap.read_bytes()
    mcap.write_bytes(data[:int(len(data) * 0.6)])
    with pytest.warns(BagDamageWarning, match='truncated'):
        a = analyze_session(damaged, write_files=False)
    assert any('truncated' in p for p in a.problems)
    assert 0.4 * linear_session.counts[topics.LOAD_CELL_WRENCH] < a.pairing['pairs'] \
        < 0.7 * linear_session.counts[topics.LOAD_CELL_WRENCH]
    assert a.branch_fits['loading'].stiffness == pytest.approx(K_TRUE, rel=5e-3)
    # and recover makes it whole again (readable by the CLI without warnings)
    assert cli_main(['recover', str(damaged)]) == 0
    assert (damaged / 'metadata.yaml').is_file()
    with warnings.catch_warnings():
        warnings.simplefilter('error', BagDamageWarning)
        b = analyze_session(damaged, write_files=False)
    assert b.pairing['pairs'] >= a.pairing['pairs']


def test_corrupt_chunk_is_skipped_with_a_warning(linear_session, tmp_path, capsys):
    damaged = tmp_path / 'corrupt'
    shutil.copytree(linear_session.path, damaged)
    mcap = damaged / 'linear_0.mcap'
    data = bytearray(mcap.read_bytes())
    with McapFile(mcap) as f:
        assert len(f.chunks) >= 3
        victim = f.chunks[len(f.chunks) // 2]
    middle = victim.records_offset + victim.compressed_size // 2
    data[middle:middle + 64] = bytes(64)  # zeros inside a compressed chunk
    mcap.write_bytes(bytes(data))
    with pytest.warns(BagDamageWarning, match=f'chunk at offset {victim.offset}'):
        a = analyze_session(damaged, write_files=False)
    assert a.problems and a.pairing['pairs'] < linear_session.counts[topics.LOAD_CELL_WRENCH]
    assert a.branch_fits['loading'].stiffness == pytest.approx(K_TRUE, rel=5e-3)
    assert cli_main(['analyze', str(damaged), '--out', str(tmp_path / 'o'), '--quiet']) == 0
    err = capsys.readouterr().err
    assert 'crane-stiffness: warning:' in err


def test_not_a_bag_and_missing_topics(tmp_path, capsys):
    (tmp_path / 'junk').mkdir()
    (tmp_path / 'junk' / 'junk_0.mcap').write_bytes(b'not an mcap file at all')
    with pytest.raises(BagFormatError):
        analyze_session(tmp_path / 'junk', write_files=False)
    assert cli_main(['analyze', str(tmp_path / 'junk'), '--quiet']) == 2
    assert 'not an MCAP file' in capsys.readouterr().err
    assert cli_main(['analyze', str(tmp_path / 'nothing_here'), '--quiet']) == 2
    assert 'does not exist' in capsys.readouterr().err
    # A bag with the load cell only: the LVDT topic is named, with the topics present.
    stamps = 1_700_000_000_000_000_000 + np.arange(50, dtype=np.int64) * 1_000_000
    raw, size = encode_stamped(stamps, 'load_cell', np.zeros((50, 6)))
    with BagWriter(tmp_path / 'no_lvdt') as w:
        w.add_topic(topics.LOAD_CELL_WRENCH, 'geometry_msgs/msg/WrenchStamped')
        for i, t in enumerate(stamps.tolist()):
            w.write(topics.LOAD_CELL_WRENCH, raw[i * size:(i + 1) * size], t)
    with pytest.raises(TopicNotFoundError, match='/lvdt/displacement.*topics present: /load_cell/wrench'):
        analyze_session(tmp_path / 'no_lvdt', write_files=False)
    assert cli_main(['analyze', str(tmp_path / 'no_lvdt'), '--quiet']) == 2
    assert 'required topic /lvdt/displacement is not in the bag' in capsys.readouterr().err
    # Both sensors but no pair within slop: a clear error.
    raw_d, dsize = encode_stamped(stamps + 300_000_000, 'lvdt', np.zeros((50, 3)))
    with BagWriter(tmp_path / 'no_pairs') as w:
        w.add_topic(topics.LOAD_CELL_WRENCH, 'geometry_msgs/msg/WrenchStamped')
        w.add_topic(topics.LVDT_DISPLACEMENT, 'geometry_msgs/msg/PointStamped')
        for i, t in enumerate(stamps.tolist()):
            w.write(topics.LOAD_CELL_WRENCH, raw[i * size:(i + 1) * size], t)
            w.write(topics.LVDT_DISPLACEMENT, raw_d[i * dsize:(i + 1) * dsize], t + 1)
    with pytest.raises(SessionAnalysisError, match='only 0 load-cell/LVDT pair'):
        analyze_session(tmp_path / 'no_pairs', write_files=False)


def test_session_without_commands_names_the_missing_topics(tmp_path):
    """Only the two sensor streams: fits from the measured-force branches, missing topics named."""
    syn = tmp_path / 'full'
    write_synthetic_session(syn, short_program(1), stiffness=K_TRUE, seed=9)
    with BagReader(syn) as reader:
        msgs = list(reader.messages([topics.LOAD_CELL_WRENCH, topics.LVDT_DISPLACEMENT]))
    with BagWriter(tmp_path / 'sensors_only') as w:
        w.add_topic(topics.LOAD_CELL_WRENCH, 'geometry_msgs/msg/WrenchStamped')
        w.add_topic(topics.LVDT_DISPLACEMENT, 'geometry_msgs/msg/PointStamped')
        for m in msgs:
            w.write(m.topic, m.data, m.log_time_ns)
    a = analyze_session(tmp_path / 'sensors_only', write_files=False)
    assert set(a.missing_topics) >= {topics.WRENCH_COMMAND, topics.PROGRAM_STATE, topics.STIFFNESS_VALUES}
    assert any(p.startswith(f'topic {topics.WRENCH_COMMAND} is not in the bag') for p in a.problems)
    assert a.steps == [] and a.model is None and a.program is None
    assert a.branch_fits['loading'].stiffness == pytest.approx(K_TRUE, rel=5e-3)


def test_cli_analyze_json_and_compare(linear_session, tmp_path, capsys):
    assert cli_main(['analyze', str(linear_session.path), '--out', str(tmp_path / 'a'), '--json']) == 0
    data = json.loads(capsys.readouterr().out)
    assert data['branch_fits']['loading']['stiffness'] == pytest.approx(K_TRUE, rel=2e-3)
    assert (tmp_path / 'a' / 'analysis.json').is_file() and (tmp_path / 'a' / 'report.md').is_file()
    assert cli_main(['analyze', str(linear_session.path), '--out', str(tmp_path / 'b'), '--format', 'svg',
                     '--report', 'html', '--quiet']) == 0
    out = capsys.readouterr().out
    assert 'loading    k = ' in out and 'last live estimate reproduced' in out
    assert sorted(p.name for p in (tmp_path / 'b').iterdir()) == ['budget.svg', 'force_displacement.svg',
                                                                  'report.html', 'timeseries.svg']
    assert cli_main(['compare', str(linear_session.path), str(linear_session.path), '--out',
                     str(tmp_path / 'c'), '--quiet']) == 0
    assert (tmp_path / 'c' / 'compare.md').is_file()


def test_analysis_needs_no_ros(linear_session, tmp_path):
    run_without_ros(f'''
        from crane_stiffness.cli.main import main
        assert main(["analyze", {str(linear_session.path)!r}, "--out", {str(tmp_path / "noros")!r}, "--quiet"]) == 0
    ''')
    assert (tmp_path / 'noros' / 'report.md').is_file()


def test_commands_covering_part_of_the_program_are_matched_to_its_holds(linear_session, tmp_path):
    """The first commands were not recorded (as when the load program starts before DDS connected it): the holds
    seen are matched to the program's by level, keeping their approach and segment."""
    cut = linear_session.program_start_ns + 800_000_000  # inside the ramp to 1 N, after the first hold at 0
    with BagReader(linear_session.path) as reader:
        records = reader.metadata_records()
        infos = reader.topics
        msgs = [m for m in reader.messages() if not (m.topic == topics.WRENCH_COMMAND and m.log_time_ns < cut)]
    with BagWriter(tmp_path / 'late', metadata=records) as w:
        for topic, info in infos.items():
            w.add_topic(topic, info.msg_type, info.offered_qos_profiles)
        for m in msgs:
            w.write(m.topic, m.data, m.log_time_ns)
    a = analyze_session(tmp_path / 'late', write_files=False)
    assert [s.level for s in a.steps][:3] == [1.0, 2.0, 3.0] and len(a.steps) == 12
    assert [s.segment for s in a.steps][:3] == [2, 4, 6] and a.steps[3].approach == 'unloading'
    assert any("the commands show 12 of the program's 13 holds on fy (from hold 2)" in p for p in a.problems)
