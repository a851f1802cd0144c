"""What the launch file hands launch_ros survives launch_ros's own dump and our parameter reader.

launch_ros writes each parameter dict of a ``Node(parameters=[...])`` to a temporary ``--params-file`` with
``yaml.dump`` (sequences become tuples first, dumped as ``!!python/tuple``); every node reads its parameter files
with crane_stiffness.params.files. Pure Python: PyYAML and our reader, for every argument set the README shows. The
real round trip through launch_ros and the genuine ``ros2 launch`` are in test_genuine_cli.py.
"""
from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from helpers import REPO
from crane_stiffness.params.files import ParamFile, load_yaml
from crane_stiffness.launcher.rig_description import ARGUMENTS, RigError, rig_nodes

CONFIG = REPO / 'config'
#: The argument sets of the README's `ros2 launch` lines (and the launch file's docstring).
README_ARGUMENTS = [
    {}, {'program': 'side_force'}, {'program': 'moment_z'}, {'program': 'force_z'},
    {'program': 'side_force_slack'}, {'program': 'side_force', 'record': 'true'}, {'record': 'false'},
    {'session': 'run 1: µm'}, {'transport': 'drivers'},
    {'transport': 'drivers', 'sim_sensors': 'false', 'drivers': str(CONFIG / 'drivers_ati_labjack.yaml')},
    {'transport': 'drivers', 'machine': 'daq'}, {'transport': 'drivers', 'machine': 'analysis'},
]


def _as_launch_ros_hands_it(value):
    """Sequences as tuples (what launch_ros's normalize_parameters makes of them), nested too."""
    if isinstance(value, (list, tuple)):
        return tuple(_as_launch_ros_hands_it(v) for v in value)
    return value


def _as_read(value):
    if isinstance(value, (list, tuple)):
        return [_as_read(v) for v in value]
    return value


@pytest.mark.parametrize('given', README_ARGUMENTS, ids=lambda g: ' '.join(f'{k}:={v}' for k, v in g.items()) or
                         'defaults')
def test_every_launch_parameter_dict_reads_back_after_yaml_dump(given, tmp_path):
    dicts = [n for n in rig_nodes(CONFIG, given) if n.parameters]
    assert dicts, 'the rig passes parameter dicts (load_program\'s readiness at least)'
    for node in dicts:
        for form in (node.parameters, {k: _as_launch_ros_hands_it(v) for k, v in node.parameters.items()}):
            path = tmp_path / f'{node.name}.yaml'
            path.write_text(yaml.dump({'/**': {'ros__parameters': form}}, default_flow_style=False))
            read = ParamFile.read(path)
            assert read.sections['/**'] == {k: _as_read(v) for k, v in node.parameters.items()}, path.read_text()


@pytest.mark.parametrize('value', [
    ('a', 'b'), ['a', 'b'], (1, 2), (1.5, -2.0), (True, False), ((1, 2), (3, 4)), (), 'x: y', '1.0', 'true',
    '', 'µm', float('inf'), -0.0, 10 ** 12, 1e-300, ('/crane/x: crane_model load_cell', ''),
])
def test_reader_accepts_every_value_type_yaml_dump_writes(value):
    text = yaml.dump({'n': {'ros__parameters': {'p': value}}}, default_flow_style=False)
    assert load_yaml(text)['n']['ros__parameters']['p'] == _as_read(value)


def test_reader_still_refuses_python_objects():
    with pytest.raises(yaml.YAMLError):
        load_yaml('p: !!python/object/apply:os.getcwd []')
    with pytest.raises(yaml.YAMLError):
        load_yaml('p: !!python/name:os.system')


def test_launch_argument_defaults_are_plain_text():
    """`ros2 launch ... --show-args` prints each default as written: no substitution objects, file names readable."""
    for argument in ARGUMENTS:
        assert isinstance(argument.default, str), argument
    files = {a.name: a.default for a in ARGUMENTS if a.config_file}
    assert files == {'crane': 'crane_lab.yaml', 'sensors': 'sensors.yaml', 'drivers': 'drivers_emulated.yaml'}
    assert all((CONFIG / name).is_file() for name in files.values())


def test_rig_arguments_choose_the_nodes_and_their_files():
    """The nodes and files the launch file starts for its arguments (rig_description, which it evaluates)."""
    nodes = rig_nodes(CONFIG, {})
    assert [n.name for n in nodes] == ['crane_model', 'load_cell', 'lvdt', 'stiffness_estimator',
                                       'session_recorder', 'load_program']
    assert all(Path(f).is_file() for n in nodes for f in n.parameter_files)
    # The program file carries its series' measuring arrangement: the model, the LVDT and the estimator read it too.
    assert nodes[0].parameter_files == (str(CONFIG / 'crane_lab.yaml'), str(CONFIG / 'program_side_force.yaml'))
    assert {n.name for n in nodes if str(CONFIG / 'program_side_force.yaml') in n.parameter_files} == {
        'crane_model', 'lvdt', 'stiffness_estimator', 'session_recorder', 'load_program'}
    nodes = rig_nodes(CONFIG, {'program': 'moment_z', 'sim_sensors': 'false', 'record': 'False', 'session': 's1'})
    assert [n.name for n in nodes] == ['crane_model', 'stiffness_estimator', 'load_program']
    assert nodes[-1].parameter_files[0] == str(CONFIG / 'program_moment_z.yaml')
    assert set(nodes[-1].parameters) == {'wait_for_messages', 'wait_for_subscribers'}
    recorder = next(n for n in rig_nodes(CONFIG, {'session': 's1'}) if n.name == 'session_recorder')
    assert recorder.parameters == {'session': 's1'}
    # A bare file name is a file of config/; anything with a directory part is a path as given.
    assert rig_nodes(CONFIG, {'crane': 'crane_lab.yaml'})[0].parameter_files[0] == str(CONFIG / 'crane_lab.yaml')
    with pytest.raises(RigError, match=r'crane file \./nowhere\.yaml not found'):
        rig_nodes(CONFIG, {'crane': './nowhere.yaml'})


def test_a_six_axis_program_starts_the_pose_sensor_and_the_6x6_fit():
    """program:=full6: its file has a stiffness6_estimator section, so six_axis:=auto starts the pose sensor and the
    6x6 fit beside the 1-D rig; the program waits for the pose stream too."""
    names = [n.name for n in rig_nodes(CONFIG, {'program': 'full6'})]
    assert names == ['crane_model', 'load_cell', 'lvdt', 'pose_sensor', 'stiffness_estimator', 'stiffness6_estimator',
                     'session_recorder', 'load_program']
    nodes = {n.name: n for n in rig_nodes(CONFIG, {'program': 'full6', 'use_sim_time': 'true'})}
    assert str(CONFIG / 'program_full6.yaml') in nodes['stiffness6_estimator'].parameter_files
    assert {'pose_sensor', 'stiffness6_estimator'} <= set(nodes['sim_clock'].parameters['participants'])
    assert '/pose_sensor/pose' in nodes['load_program'].parameters['wait_for_messages']
    assert not {'pose_sensor', 'stiffness6_estimator'} & {n.name for n in rig_nodes(CONFIG, {})}
    assert {n.name for n in rig_nodes(CONFIG, {'six_axis': 'true'})} >= {'pose_sensor', 'stiffness6_estimator'}
    # a real tracker instead of the simulated pose sensor: the fit, no simulated sensor
    real = [n.name for n in rig_nodes(CONFIG, {'program': 'full6', 'sim_sensors': 'false'})]
    assert 'stiffness6_estimator' in real and 'pose_sensor' not in real
    with pytest.raises(RigError, match="unknown program 'nothing'.*force_z, full6, moment_z, side_force"):
        rig_nodes(CONFIG, {'program': 'nothing'})


def test_the_one_axis_estimator_and_the_live_view_are_told_whether_the_program_is_six_axis():
    """The program's file decides (rig_description.is_six_axis_program), not the six_axis argument: the one-axis
    estimator says its fit does not apply and the page leads with the 6x6 in a six-axis program only."""
    for given, six in (({'program': 'full6'}, True), ({'program': 'side_force'}, False),
                       ({'program': 'side_force', 'six_axis': 'true'}, False), ({'program': 'moment_z'}, False)):
        nodes = {n.name: n for n in rig_nodes(CONFIG, {**given, 'live_view': 'true'})}
        assert nodes['stiffness_estimator'].parameters['six_axis_program'] is six, given
        assert nodes['live_view'].parameters['six_axis_program'] is six, given
        assert 'six_axis_program' not in nodes['crane_model'].parameters


def test_live_view_argument_starts_it_with_integer_ports():
    """live_view:=true adds the view (on the analysis machine) with its ports as integers: launch_ros would hand a
    string to the node, which declares integers."""
    names = [n.name for n in rig_nodes(CONFIG, {})]
    assert 'live_view' not in names
    view = {n.name: n for n in rig_nodes(CONFIG, {'live_view': 'true', 'view_port': '9000',
                                                  'view_http_port': '9001'})}['live_view']
    assert view.parameters == {'host': '127.0.0.1', 'port': 9000, 'http_port': 9001, 'six_axis_program': False}
    assert view.machine == 'analysis' and view.parameter_files == (str(CONFIG / 'crane_lab.yaml'),)
    assert 'live_view' not in [n.name for n in rig_nodes(CONFIG, {'live_view': 'true', 'machine': 'daq'})]
    with pytest.raises(RigError, match='view_port:=80a: expected an integer'):
        rig_nodes(CONFIG, {'live_view': 'true', 'view_port': '80a'})
