"""A lab's own recording analysed offline as the live estimator takes it (crane_stiffness.analysis.mapping): the
session's streams copied by an independent writer (the `rosbags` package, MCAP storage) into a bag without session
metadata, as ``ros2 bag record /netft_data /daq/ch0 ...`` leaves one: the F/T sensor's WrenchStamped on
/netft_data, the LVDT as a DAQ channel in volts (std_msgs/Float64) on /daq/ch0, with the README's gain and offset.
``analyze`` and ``compare`` with the flags (or a parameter file) and ``--config`` find the original's stiffness and
say which mapping they used; bad values are refused by name.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from helpers import REPO
from crane_stiffness.analysis.analyze import analyze_session
from crane_stiffness.analysis.errors import MappingError, SessionAnalysisError
from crane_stiffness.analysis.mapping import SensorMapping
from crane_stiffness.bag import BagReader, TopicNotFoundError
from crane_stiffness.cli.main import main as cli_main
from crane_stiffness.contract import topics
from crane_stiffness.errors import ParameterError
from crane_stiffness.estimation.live import LiveStiffness
from crane_stiffness.estimation.settings import LiveSettings
from crane_stiffness.model import lab_model
from crane_stiffness.serde import decode_stamped
from crane_stiffness.sim.program import LoadProgram, Segment
from crane_stiffness.testing.synthetic import write_synthetic_session

K_TRUE = 53_793.5  # N/m, the synthetic session's linear truth: the lab model's tangent along fy, so they agree
GAIN, OFFSET = 0.002, -0.001  # m/V, m: the README's example (reading_m = GAIN * volts + OFFSET)
WRENCH, DAQ = '/netft_data', '/daq/ch0'
CRANE = REPO / 'config' / 'crane_lab.yaml'  # the geometry the synthetic session recorded: lab_model(0.5, 50.0)
FLAGS = ['--wrench-topic', WRENCH, '--displacement-topic', DAQ, '--displacement-type', 'float64',
         '--displacement-gain', str(GAIN), '--displacement-offset', str(OFFSET)]


def _program() -> LoadProgram:
    """0 → 1 → 2 → 3 N and back in ramps and 0.6 s holds on fy, twice."""
    segs = [Segment('hold', 'fy', 0.0, 0.6)]
    for level in (1.0, 2.0, 3.0, 2.0, 1.0, 0.0):
        segs += [Segment('ramp', 'fy', level, 0.4), Segment('hold', 'fy', level, 0.6)]
    return LoadProgram(segs, repeats=2, name='short_steps', rate_hz=100.0)


def write_lab_bag(original: Path, path: Path, commands: bool = True) -> dict[str, np.ndarray]:
    """The original session's load cell, LVDT and commands written with rosbags' rosbag2 Writer (MCAP storage), no
    session metadata: the wrenches as they are on /netft_data; each LVDT reading x as a Float64 of volts
    (x - OFFSET) / GAIN on /daq/ch0, logged at the reading's stamp (a Float64 has no stamp: its log time is its
    instant); the commands on /crane/wrench_command (unless ``commands`` is False: a lab whose program publishes
    none). Returns the volts written and their log times."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore
    store = get_typestore(Stores.ROS2_JAZZY)
    Float64 = store.types['std_msgs/msg/Float64']
    out: list[tuple[int, str, bytes]] = []
    volts, logs = [], []
    with BagReader(original) as reader:
        for msg in reader.messages([topics.LOAD_CELL_WRENCH, topics.LVDT_DISPLACEMENT] +
                                   ([topics.WRENCH_COMMAND] if commands else [])):
            if msg.topic == topics.LVDT_DISPLACEMENT:
                sec, nanosec, (x, _, _) = decode_stamped(msg.data, 3)
                v = (x - OFFSET) / GAIN
                t = sec * 1_000_000_000 + nanosec
                volts.append(v)
                logs.append(t)
                out.append((t, DAQ, bytes(store.serialize_cdr(Float64(data=v), 'std_msgs/msg/Float64'))))
            else:
                out.append((msg.log_time_ns, WRENCH if msg.topic == topics.LOAD_CELL_WRENCH else msg.topic,
                            bytes(msg.data)))
    out.sort(key=lambda m: m[0])
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conns = {topic: writer.add_connection(topic, msg_type, typestore=store)
                 for topic, msg_type in ((WRENCH, 'geometry_msgs/msg/WrenchStamped'), (DAQ, 'std_msgs/msg/Float64'),
                                         (topics.WRENCH_COMMAND, 'geometry_msgs/msg/WrenchStamped'))
                 if commands or topic != topics.WRENCH_COMMAND}
        for t, topic, data in out:
            writer.write(conns[topic], t, data)
    return {'volts': np.array(volts), 'log_time_ns': np.array(logs, dtype=np.int64)}


@pytest.fixture(scope='module')
def sessions(tmp_path_factory):
    """(original session, its analysis, the lab bag, the volts written)."""
    root = tmp_path_factory.mktemp('lab')
    original = write_synthetic_session(root / 'original', _program(), geometry=lab_model(0.5, 50.0),
                                       stiffness=K_TRUE, seed=11)
    analysed = analyze_session(original.path, write_files=False)
    written = write_lab_bag(original.path, root / 'lab')
    return original, analysed, root / 'lab', written


def test_the_lab_bag_is_what_ros2_bag_record_leaves(sessions):
    _, _, lab, written = sessions
    with BagReader(lab) as reader:
        assert {t: i.msg_type for t, i in reader.topics.items()} == {
            WRENCH: 'geometry_msgs/msg/WrenchStamped', DAQ: 'std_msgs/msg/Float64',
            topics.WRENCH_COMMAND: 'geometry_msgs/msg/WrenchStamped'}
        assert not reader.metadata_records()  # no session record: no geometry, no estimator parameters
        daq = reader.decode_topics([DAQ], columns=True)[DAQ]
    assert daq['data'].tolist() == written['volts'].tolist()
    assert daq['log_time_ns'].tolist() == written['log_time_ns'].tolist()


def test_cli_analyze_with_the_flags_finds_the_original_stiffness(sessions, tmp_path, capsys):
    original, analysed, lab, _ = sessions
    out = tmp_path / 'out'
    assert cli_main(['analyze', str(lab), *FLAGS, '--config', str(CRANE), '--json', '--quiet',
                     '--out', str(out)]) == 0
    result = json.loads(capsys.readouterr().out)
    reference = analysed.branch_fits['loading']
    assert reference is not None and reference.ci95_low < K_TRUE < reference.ci95_high
    loading = result['branch_fits']['loading']
    assert reference.ci95_low <= loading['stiffness'] <= reference.ci95_high
    # The same pairs as the original: a Float64 logged at the reading's stamp is taken at that instant.
    assert loading['n'] == reference.n
    assert math.isclose(loading['stiffness'], reference.stiffness, rel_tol=1e-9)
    assert result['pairing']['pairs'] == analysed.pairing['pairs']
    assert result['mapping'] == {
        'wrench_topic': WRENCH, 'wrench_msg_type': 'geometry_msgs/msg/WrenchStamped',
        'displacement_topic': DAQ, 'displacement_msg_type': 'std_msgs/msg/Float64', 'displacement_type': 'float64',
        'displacement_gain': GAIN, 'displacement_offset': OFFSET,
        'conversion': 'reading = 0.002 m/V × volts - 0.001 m (displacement_gain, displacement_offset)',
        'sample_instant': result['mapping']['sample_instant'], 'geometry_source': f'--config {CRANE}',
        'sources': {'displacement_type': 'flag', 'displacement_gain': 'flag', 'displacement_offset': 'flag'}}
    assert 'log time' in result['mapping']['sample_instant']
    # The geometry from --config is the one the original recorded: the same model.
    assert result['geometry'] == analysed.to_dict()['geometry']
    assert result['model']['tangent_at_rest'] == analysed.model.tangent_at_rest
    report = (out / 'report.md').read_text()
    for text in (f'{WRENCH} [geometry_msgs/msg/WrenchStamped]', f'{DAQ} [std_msgs/msg/Float64], displacement_type '
                 'float64 (flag)', '0.002 m/V (flag), -0.001 m (flag)', f'| geometry from | --config {CRANE} |'):
        assert text in report
    assert json.loads((out / 'analysis.json').read_text())['mapping'] == result['mapping']


def test_without_commands_the_branches_follow_the_force(sessions, tmp_path):
    """A lab whose program publishes no /crane/wrench_command: no test steps, the branches from the measured force
    (as the live estimator without commands), the loading stiffness still within the original's interval."""
    original, analysed, _, _ = sessions
    write_lab_bag(original.path, tmp_path / 'lab', commands=False)
    result = analyze_session(tmp_path / 'lab', write_files=False, mapping=SensorMapping(
        wrench_topic=WRENCH, displacement_topic=DAQ, displacement_gain=GAIN, displacement_offset=OFFSET))
    reference, loading = analysed.branch_fits['loading'], result.branch_fits['loading']
    assert reference is not None and loading is not None
    assert reference.ci95_low <= loading.stiffness <= reference.ci95_high
    assert result.steps == [] and result.pairing['pairs'] == analysed.pairing['pairs']
    assert result.mapping['sources']['displacement_type'] == "the bag's message type"
    assert any('/crane/wrench_command is not in the bag: no test steps' in p for p in result.problems)


def test_a_parameter_file_sets_the_mapping_as_the_flags_do(sessions, tmp_path, capsys):
    _, _, lab, _ = sessions
    params = tmp_path / 'lab_estimator.yaml'
    params.write_text('stiffness_estimator:\n  ros__parameters:\n    displacement_type: float64\n'
                      f'    displacement_gain: {GAIN}\n    displacement_offset: {OFFSET}\n')
    by_flags = analyze_session(lab, write_files=False, mapping=SensorMapping(
        wrench_topic=WRENCH, displacement_topic=DAQ, displacement_type='float64', displacement_gain=GAIN,
        displacement_offset=OFFSET))
    out = tmp_path / 'out'
    assert cli_main(['analyze', str(lab), '--wrench-topic', WRENCH, '--displacement-topic', DAQ,
                     '--params-file', str(params), '--quiet', '--json', '--out', str(out)]) == 0
    result = json.loads((out / 'analysis.json').read_text())
    assert result['branch_fits']['loading']['stiffness'] == by_flags.branch_fits['loading'].stiffness
    assert result['mapping']['sources'] == {name: f'--params-file {params}' for name in
                                            ('displacement_type', 'displacement_gain', 'displacement_offset')}
    # Without --config a bag without session metadata has no geometry: said, no model.
    assert result['mapping']['geometry_source'] == 'none' and result['model'] is None
    assert any('no rig geometry recorded' in p for p in result['problems'])
    # A bad value in the file is named, with the file.
    params.write_text('stiffness_estimator:\n  ros__parameters:\n    displacement_gain: 0.0\n')
    assert cli_main(['analyze', str(lab), '--wrench-topic', WRENCH, '--displacement-topic', DAQ,
                     '--params-file', str(params), '--quiet', '--out', str(out)]) == 2
    assert f'displacement_gain = 0.0: must be non-zero (m/V) (from --params-file {params})' in \
        capsys.readouterr().err


def test_cli_compare_names_each_sessions_mapping(sessions, tmp_path, capsys):
    _, analysed, lab, _ = sessions
    out = tmp_path / 'cmp'
    assert cli_main(['compare', str(lab), *FLAGS, '--config', str(CRANE), '--quiet', '--json', '--out', str(out)]) == 0
    capsys.readouterr()
    row = json.loads((out / 'compare.json').read_text())['rows'][0]
    assert math.isclose(row['loading_k'], analysed.branch_fits['loading'].stiffness, rel_tol=1e-9)
    assert row['mapping']['displacement_topic'] == DAQ and row['mapping']['displacement_gain'] == GAIN
    assert f'{WRENCH}, {DAQ} (float64, 0.002 m/V, -0.001 m); geometry --config {CRANE}' in \
        (out / 'compare.md').read_text()


def test_offline_and_live_convert_volts_with_the_one_function(sessions, monkeypatch):
    """analyze and the live core (LiveStiffness.add_volts) both call LiveSettings.volts_to_displacement: the same
    numbers from the same volts."""
    _, _, lab, written = sessions
    calls: list[tuple[object, object]] = []
    convert = LiveSettings.volts_to_displacement

    def spy(self, volts):
        value = convert(self, volts)
        calls.append((volts, value))
        return value

    monkeypatch.setattr(LiveSettings, 'volts_to_displacement', spy)
    analyze_session(lab, write_files=False, mapping=SensorMapping(
        wrench_topic=WRENCH, displacement_topic=DAQ, displacement_gain=GAIN, displacement_offset=OFFSET))
    assert len(calls) == 1
    offline_in, offline_out = calls.pop()
    assert np.array_equal(offline_in, written['volts'])
    core = LiveStiffness(LiveSettings.from_params({'displacement_gain': GAIN, 'displacement_offset': OFFSET}))
    for i in (0, 1, len(written['volts']) // 2, len(written['volts']) - 1):
        core.add_volts(written['log_time_ns'][i] * 1e-9, float(written['volts'][i]))
        live_in, live_out = calls.pop()
        assert live_in == written['volts'][i] and live_out == offline_out[i]
    assert not calls


def test_a_topic_not_in_the_bag_or_of_another_type_is_named(sessions, capsys):
    _, _, lab, _ = sessions
    assert cli_main(['analyze', str(lab), *FLAGS[2:], '--wrench-topic', '/ft_sensor/data', '--quiet']) == 2
    err = capsys.readouterr().err
    assert '/ft_sensor/data is not in the bag (wrench_topic' in err
    assert (f'topics present: /crane/wrench_command [geometry_msgs/msg/WrenchStamped], {DAQ} [std_msgs/msg/Float64], '
            f'{WRENCH} [geometry_msgs/msg/WrenchStamped]') in err
    with pytest.raises(TopicNotFoundError, match='/lvdt/displacement is not in the bag'):
        analyze_session(lab, write_files=False, mapping=SensorMapping(wrench_topic=WRENCH))
    with pytest.raises(SessionAnalysisError, match=f'wrench_topic {DAQ} has type std_msgs/msg/Float64, expected '
                       'geometry_msgs/msg/WrenchStamped'):
        analyze_session(lab, write_files=False, mapping=SensorMapping(wrench_topic=DAQ, displacement_topic=WRENCH))
    assert cli_main(['analyze', str(lab), '--wrench-topic', WRENCH, '--displacement-topic', DAQ,
                     '--displacement-type', 'point_stamped', '--quiet']) == 2
    assert (f'displacement_topic {DAQ} has type std_msgs/msg/Float64, but displacement_type point_stamped expects '
            'geometry_msgs/msg/PointStamped') in capsys.readouterr().err


@pytest.mark.parametrize('flag, value, message', [
    ('--displacement-gain', '0', 'displacement_gain = 0.0: must be non-zero (m/V)'),
    ('--displacement-gain', 'nan', 'displacement_gain = nan: must be a finite number'),
    ('--displacement-offset', 'inf', 'displacement_offset = inf: must be a finite number'),
    ('--wrench-topic', 'netft_data', "wrench_topic = 'netft_data': must be a topic name as the bag records it"),
])
def test_a_bad_value_is_named(sessions, capsys, flag, value, message):
    _, _, lab, _ = sessions
    args = ['analyze', str(lab), *FLAGS, '--quiet']
    args[args.index(flag) + 1] = value
    assert cli_main(args) == 2
    assert message in capsys.readouterr().err


def test_bad_mappings_raise_errors_naming_the_value(tmp_path):
    with pytest.raises(ParameterError, match='displacement_gain = 0.0: must be non-zero'):
        SensorMapping(displacement_gain=0.0)
    with pytest.raises(MappingError, match="displacement_type = 'volts': must be one of point_stamped, float64"):
        SensorMapping(displacement_type='volts')
    with pytest.raises(MappingError, match="displacement_topic = '/a': must differ from wrench_topic = '/a'"):
        SensorMapping(wrench_topic='/a', displacement_topic='/a')
    with pytest.raises(MappingError, match=r"displacement_type = 'volts': must be one of .*\(from f.yaml\)"):
        SensorMapping(estimator_params={'displacement_type': 'volts'},
                      estimator_params_source='f.yaml').asked_displacement_type()


def test_the_documented_recipe_runs(sessions, tmp_path, capsys):
    """docs/recording.md's `crane-stiffness analyze` command, on the lab bag: the original's stiffness."""
    import shlex
    _, analysed, lab, _ = sessions
    text = (REPO / 'docs' / 'recording.md').read_text()
    start = text.index('crane-stiffness analyze bags/lab_run')
    command = text[start:text.index('\n```', start)].replace('\\\n', ' ')
    args = shlex.split(command)[1:]
    args[args.index('bags/lab_run')] = str(lab)
    args[args.index('config/crane_lab.yaml')] = str(CRANE)
    assert cli_main([*args, '--quiet', '--json', '--out', str(tmp_path)]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result['branch_fits']['loading']['stiffness'] == pytest.approx(
        analysed.branch_fits['loading'].stiffness, rel=1e-9)
    assert result['mapping']['displacement_topic'] == DAQ and result['mapping']['displacement_gain'] == GAIN


@pytest.mark.parametrize('command', ['analyze', 'compare'])
def test_help_shows_the_flags_with_their_units(command, capsys):
    with pytest.raises(SystemExit):
        cli_main([command, '--help'])
    text = ' '.join(capsys.readouterr().out.split())
    for flag in ('--wrench-topic TOPIC', '--displacement-topic TOPIC', '--displacement-type {point_stamped,float64}',
                 '--displacement-gain M_PER_V', '--displacement-offset M', '--params-file FILE',
                 '--config CRANE.yaml'):
        assert flag in text
    for unit in ('metres per volt [m/V]', 'metres at 0 V [m]', 'wrench in N and N·m', 'point.x in m', 'geometry.* '
                 'parameters [m, N, Pa]'):
        assert unit in text
