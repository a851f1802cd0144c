"""Parameters as the genuine tools see them.

At start: nodes started the way ``ros2 run`` does (crane_stiffness.launcher.rosrun, from the colcon install tree)
with ``--ros-args -p`` / ``--params-file``; exit status and stderr. At runtime: the parameter services
(SetParameters, DescribeParameters, GetParameters) called from a client node, as ``ros2 param`` does.
"""
from __future__ import annotations

import math
import subprocess
from pathlib import Path

import pytest
from rcl_interfaces.msg import Parameter as ParameterMsg
from rcl_interfaces.msg import ParameterType, ParameterValue
from rcl_interfaces.srv import DescribeParameters, GetParameters, SetParameters
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from std_srvs.srv import Trigger

from helpers import PATIENCE_S, REPO, spin_until
from crane_stiffness.bag import BagWriter, dump_qos_profiles, qos_profile
from crane_stiffness.nodes.crane_model import CraneModel
from crane_stiffness.nodes.session_player import SessionPlayer
from crane_stiffness.nodes.session_recorder import SessionRecorder
from crane_stiffness.launcher import rosrun

PKG = 'crane_stiffness'


# ---------------------------------------------------------------------------------------- at start, as processes --

def run_node(env, executable: str, *args: str, timeout: float = PATIENCE_S) -> subprocess.CompletedProcess:
    """A node started like ``ros2 run crane_stiffness <executable> <args>`` that is expected to stop by itself."""
    return subprocess.run(rosrun.command(PKG, executable, list(args), env), env=env, capture_output=True, text=True,
                          timeout=timeout, stdin=subprocess.DEVNULL)


def refused(result: subprocess.CompletedProcess) -> str:
    """stderr of a node that refused to start: exit status 2, one line of reason, no traceback."""
    assert result.returncode == 2, (result.returncode, result.stdout[-2000:], result.stderr[-2000:])
    assert 'Traceback' not in result.stderr, result.stderr
    lines = [line for line in result.stderr.splitlines() if 'cannot start' in line]
    assert len(lines) == 1, result.stderr
    return lines[0]


def write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def test_bad_values_on_the_command_line_exit_2_naming_the_full_parameter(install_tree):
    _, env = install_tree
    line = refused(run_node(env, 'crane_model', '--ros-args', '-p', 'geometry.height:=abc'))
    assert "geometry.height = 'abc': must be a number" in line
    # An integer where a float is declared is a float; the model's own rule names the full parameter and shows the
    # value as written.
    line = refused(run_node(env, 'crane_model', '--ros-args', '-p', 'geometry.a:=-1'))
    assert 'geometry.a = -1: must be > 0' in line
    # A misspelt name would be ignored by rclpy (the node would run with the default weight): refused, with a hint.
    line = refused(run_node(env, 'crane_model', '--ros-args', '-p', 'geometry.wieght:=80.0'))
    assert "-p geometry.wieght:=...: unknown parameter for crane_model (did you mean 'geometry.weight'?)" in line
    line = refused(run_node(env, 'crane_model', '--ros-args', '-p', 'geometry.com_offset:=[0.0, 0.0]'))
    assert 'geometry.com_offset = [0.0, 0.0]' in line and 'array(' not in line
    line = refused(run_node(env, 'load_cell', '--ros-args', '-p', 'tare_samples:=0'))
    assert 'tare_samples = 0: must be >= 1' in line
    # Values that would crash ~/start later are refused at start (the same rule as at runtime).
    line = refused(run_node(env, 'session_recorder', '--ros-args', '-p', 'split_max_duration_s:=.inf'))
    assert 'split_max_duration_s = inf' in line


def test_bad_or_missing_params_file_or_unknown_key_exits_2_naming_file_and_key(install_tree, tmp_path):
    _, env = install_tree
    missing = tmp_path / 'missing.yaml'
    line = refused(run_node(env, 'crane_model', '--ros-args', '--params-file', str(missing)))
    assert str(missing) in line and 'no such parameter file' in line
    broken = write(tmp_path / 'broken.yaml', '/**:\n  ros__parameters:\n    geometry: {a: [1\n')
    line = refused(run_node(env, 'crane_model', '--ros-args', '--params-file', str(broken)))
    assert str(broken) in line and 'not valid YAML' in line and 'line ' in line
    misspelt = write(tmp_path / 'misspelt.yaml', '/**:\n  ros__parameters:\n    geometry: {wieght: 80.0}\n')
    line = refused(run_node(env, 'crane_model', '--ros-args', '--params-file', str(misspelt)))
    assert str(misspelt) in line and "'geometry.wieght'" in line and "did you mean 'geometry.weight'" in line
    # A key of another node of the package is fine under /**, but not in this node's own section.
    own = write(tmp_path / 'own.yaml', 'crane_model:\n  ros__parameters:\n    tare_samples: 5\n')
    line = refused(run_node(env, 'crane_model', '--ros-args', '--params-file', str(own)))
    assert str(own) in line and "'tare_samples'" in line and "'crane_model'" in line
    typed = write(tmp_path / 'typed.yaml', 'crane_model:\n  ros__parameters:\n    geometry: {height: tall}\n')
    line = refused(run_node(env, 'crane_model', '--ros-args', '--params-file', str(typed)))
    assert "geometry.height = 'tall': must be a number" in line


# ----------------------------------------------------------------------------------- through parameter services --

class ParamClient:
    """What ``ros2 param`` does: the node's parameter services, called from a client node."""

    def __init__(self, ctx, executor, target: str) -> None:
        self.node = Node('param_client', context=ctx)
        self.ex = executor
        self.ex.add_node(self.node)
        self.target = target

    def _call(self, srv_type, service: str, request):
        client = self.node.create_client(srv_type, f'{self.target}/{service}')
        assert client.wait_for_service(timeout_sec=PATIENCE_S), service
        future = client.call_async(request)
        assert spin_until(self.ex, future.done, PATIENCE_S), service
        self.node.destroy_client(client)
        return future.result()

    def set(self, name: str, value) -> tuple[bool, str]:
        p = Parameter(name, value=value).to_parameter_msg()
        result = self._call(SetParameters, 'set_parameters', SetParameters.Request(parameters=[p])).results[0]
        return result.successful, result.reason

    def set_int(self, name: str, value: int) -> tuple[bool, str]:
        """As ``ros2 param set node name 1`` sends it: an INTEGER."""
        p = ParameterMsg(name=name, value=ParameterValue(type=ParameterType.PARAMETER_INTEGER, integer_value=value))
        result = self._call(SetParameters, 'set_parameters', SetParameters.Request(parameters=[p])).results[0]
        return result.successful, result.reason

    def get(self, name: str) -> ParameterValue:
        return self._call(GetParameters, 'get_parameters', GetParameters.Request(names=[name])).values[0]

    def describe(self, name: str):
        return self._call(DescribeParameters, 'describe_parameters',
                          DescribeParameters.Request(names=[name])).descriptors[0]

    def trigger(self, service: str):
        return self._call(Trigger, service, Trigger.Request())


def test_crane_model_over_services_integers_ranges_and_full_names(rclpy_context, capfd):
    ex = SingleThreadedExecutor(context=rclpy_context)
    # An integer override where a float is declared (what `-p geometry.height:=1` sends) starts the node.
    model = CraneModel(context=rclpy_context, parameter_overrides=[Parameter('geometry.height', value=1)])
    ex.add_node(model)
    client = ParamClient(rclpy_context, ex, '/crane_model')
    value = client.get('geometry.height')
    assert value.type == ParameterType.PARAMETER_DOUBLE and value.double_value == 1.0
    ok, reason = client.set_int('geometry.weight', 80)
    assert ok, reason
    value = client.get('geometry.weight')
    assert value.type == ParameterType.PARAMETER_DOUBLE and value.double_value == 80.0
    assert model.geometry.weight == 80.0
    ok, reason = client.set('geometry.a', -0.1)
    assert not ok and 'geometry.a = -0.1: must be > 0' in reason
    ok, reason = client.set_int('geometry.a', -1)  # `ros2 param set /crane_model geometry.a -1`: shown as sent
    assert not ok and 'geometry.a = -1: must be > 0' in reason, reason
    assert model.get_parameter('geometry.a').value > 0
    ok, reason = client.set('geometry.weight', -1.0)
    assert not ok and 'geometry.weight' in reason
    # A string for a number: rclpy refuses it with a reason naming neither; the node's log names both.
    ok, reason = client.set('geometry.height', 'tall')
    assert not ok and model.get_parameter('geometry.height').value == 1.0
    assert "parameter change rejected: geometry.height = 'tall': must be a number" in capfd.readouterr().err
    ok, reason = client.set('geometry.com_offset', [0.0, 0.0])
    assert not ok and 'geometry.com_offset = [0.0, 0.0]' in reason and 'array(' not in reason
    ok, reason = client.set('geometry.com_offset', [0, 0, 1])  # integers in a float list
    assert ok, reason
    assert list(model.get_parameter('geometry.com_offset').value) == [0.0, 0.0, 1.0]
    # The rules are in the descriptors, before any value is rejected.
    weight = client.describe('geometry.weight')
    assert len(weight.floating_point_range) == 1
    r = weight.floating_point_range[0]
    assert r.from_value == 0.0 and r.to_value > 1e300 and r.step == 0.0
    assert client.describe('geometry.a').additional_constraints == '> 0'
    assert 'finite' in client.describe('geometry.com_offset').additional_constraints
    ex.shutdown()
    model.destroy_node()


def test_sensor_integer_range_in_descriptor(rclpy_context):
    from crane_stiffness.nodes.load_cell import LoadCell
    ex = SingleThreadedExecutor(context=rclpy_context)
    node = LoadCell(context=rclpy_context, cli_args=['--ros-args', '-r', '__ns:=/params_test'])
    ex.add_node(node)
    client = ParamClient(rclpy_context, ex, '/params_test/load_cell')
    d = client.describe('tare_samples')
    assert len(d.integer_range) == 1 and d.integer_range[0].from_value == 1
    ok, reason = client.set('tare_samples', 0)
    assert not ok and 'tare_samples' in reason
    assert client.describe('sample_rate_hz').additional_constraints == '> 0'
    ok, reason = client.set_int('sample_rate_hz', 250)  # integer where a float is declared
    assert ok, reason
    assert node.clock.period_ns == 4_000_000
    ex.shutdown()
    node.destroy_node()


def test_recorder_refuses_infinite_split_and_flush_so_start_cannot_crash(rclpy_context, tmp_path):
    ex = SingleThreadedExecutor(context=rclpy_context)
    rec = SessionRecorder(context=rclpy_context, parameter_overrides=[
        Parameter('output_dir', value=str(tmp_path)), Parameter('autostart', value=False),
        Parameter('record_node_parameters', value=[''])])
    ex.add_node(rec)
    client = ParamClient(rclpy_context, ex, '/session_recorder')
    for name in ('split_max_duration_s', 'flush_interval_s'):
        ok, reason = client.set(name, math.inf)
        assert not ok and name in reason, reason
        d = client.describe(name)
        assert len(d.floating_point_range) == 1 and math.isfinite(d.floating_point_range[0].to_value)
    ok, reason = client.set('topics', ['/crane/wrench_command', 'bad name!'])
    assert not ok and 'topics' in reason and 'bad name!' in reason
    ok, reason = client.set_int('split_max_duration_s', 60)
    assert ok, reason
    response = client.trigger('start')
    assert response.success, response.message
    assert client.trigger('stop').success
    ex.shutdown()
    rec.destroy_node()


@pytest.fixture
def tiny_bag(tmp_path):
    from rclpy.serialization import serialize_message
    from std_msgs.msg import String
    path = tmp_path / 'tiny'
    with BagWriter(path) as w:
        w.add_topic('/load_program/state', 'std_msgs/msg/String', dump_qos_profiles([qos_profile(depth=10)]))
        for i in range(3):
            w.write('/load_program/state', serialize_message(String(data='{}')), 1_000_000_000 + i * 1_000_000)
    return path


def test_player_refuses_a_remap_to_a_bad_topic_name_so_start_cannot_crash(rclpy_context, tiny_bag):
    ex = SingleThreadedExecutor(context=rclpy_context)
    player = SessionPlayer(context=rclpy_context, parameter_overrides=[
        Parameter('bag', value=str(tiny_bag)), Parameter('autostart', value=False),
        Parameter('exit_on_end', value=False)])
    ex.add_node(player)
    client = ParamClient(rclpy_context, ex, '/session_player')
    ok, reason = client.set('remap', ['/load_program/state:=bad name!'])
    assert not ok and 'remap' in reason and 'bad name!' in reason
    ok, reason = client.set('remap', ['/load_program/state:=/replay/state'])
    assert ok, reason
    assert client.trigger('start').success
    ex.shutdown()
    player.destroy_node()


# ----------------------------------------------------------------------------------------- the rule, in-process --

def test_the_shared_config_files_hold_only_keys_some_node_knows():
    """The unknown-key rule accepts every config file of the package for every node (geometry under /** is fine
    for nodes that do not declare it) and names the closest key for a misspelt one."""
    import importlib

    from crane_stiffness.params.files import share_dir
    from crane_stiffness.rosnode.parameters import RCLPY_PARAMS, check_params_files, node_modules
    files = sorted(str(p) for p in (share_dir() / 'config').glob('*.yaml'))
    assert files
    for module in node_modules():
        mod = importlib.import_module(f'crane_stiffness.nodes.{module}')
        own = {s.name for s in mod.PARAMS} | set(getattr(mod, 'LIST_PARAMS', {})) | set(RCLPY_PARAMS)
        check_params_files(files, f'/{module}', own)


@pytest.mark.ros  # lvdt.main() starts rclpy and a node (DDS) in this process
def test_main_exits_2_for_a_missing_params_file_without_traceback(tmp_path, capsys):
    from crane_stiffness.nodes import lvdt
    missing = tmp_path / 'nope.yaml'
    assert lvdt.main(['--ros-args', '--params-file', str(missing)]) == 2
    err = capsys.readouterr().err
    assert f'{missing}: no such parameter file' in err and 'Traceback' not in err
    bad = write(tmp_path / 'bad.yaml', 'lvdt:\n  ros__parameters:\n    nois_std: 1.0e-7\n')
    assert lvdt.main(['--ros-args', '--params-file', str(bad)]) == 2
    err = capsys.readouterr().err
    assert str(bad) in err and "'nois_std'" in err and "did you mean 'noise_std'" in err


def test_every_node_module_has_its_executable_and_every_executable_its_node():
    """nodes_bin/ (what setup.py installs for `ros2 run`) and the node modules found at run time are one list."""
    from crane_stiffness.rosnode.parameters import node_modules
    executables = sorted(p.name for p in (REPO / 'nodes_bin').iterdir())
    assert executables == sorted(node_modules())
    assert len(executables) == 16
    for name in executables:
        assert f'from crane_stiffness.rosnode.entry import {name}' in (REPO / 'nodes_bin' / name).read_text()
