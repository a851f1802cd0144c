"""The sensors' declared calibration and true errors on real nodes (real rclpy, DDS on loopback): a load cell with a
given +1 % sensitivity error on fy publishes readings 1 % high; an LVDT with a given sensitivity error and a mains
line reads both; a bad declaration is refused at start and on change
(through the node's set_parameters service, as ``ros2 param set`` sends it) with the old value kept; the declaration
reaches the session's bag (the node's parameters and its parameter-file section).

Every node under test gets its own node name and topic names (remapped), so tests cannot hear each other.
"""
from __future__ import annotations

import json

import numpy as np
import pytest
import yaml
from geometry_msgs.msg import PointStamped, PoseStamped, WrenchStamped
from rcl_interfaces.srv import SetParameters
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter

from helpers import isolated, publish_wrench_now, spin_until, stamp_ns, wrench_vector
from helpers.probe import ProbeNode
from crane_stiffness.bag import BagReader
from crane_stiffness.bag.session_metadata import read_node_parameters, read_session
from crane_stiffness.contract import topics
from crane_stiffness.nodes import load_cell, lvdt, modbus_emulator, rdt_emulator
from crane_stiffness.nodes.session_recorder import SessionRecorder
from crane_stiffness.rosnode.qos import RELIABLE_QOS, SENSOR_QOS

pytestmark = pytest.mark.ros  # every test here starts ROS (conftest)

PATIENCE_S = 180.0  # waits for events, however loaded the machine: the assertions follow, not a time bound
QUIET = [Parameter('noise_std', value=[0.0] * 6), Parameter('bias', value=[0.0] * 6),
         Parameter('resolution', value=[0.0] * 6), Parameter('seed', value=3)]


class Probe(ProbeNode):
    """Applies a wrench on the load cell's (remapped) /crane/applied_wrench and keeps its readings."""

    def __init__(self, ctx, prefix: str):
        super().__init__(ctx, prefix)
        self.samples: list[tuple[int, np.ndarray]] = []
        self.cmd = self.publisher(topics.APPLIED_WRENCH, WrenchStamped, RELIABLE_QOS)
        self.node.create_subscription(WrenchStamped, prefix + topics.LOAD_CELL_WRENCH,
                                      lambda m: self.samples.append((stamp_ns(m.header.stamp), wrench_vector(m))),
                                      SENSOR_QOS)

    def readings_after(self, t_ns: int) -> np.ndarray:
        return np.array([w for s, w in self.samples if s > t_ns + 1_000_000]).reshape(-1, 6)


def set_parameter(ex, client_node, node_name: str, parameter: Parameter):
    """Set one parameter through ``/<node>/set_parameters`` (what ``ros2 param set`` calls); returns the result."""
    client = client_node.create_client(SetParameters, f'/{node_name}/set_parameters')
    assert client.wait_for_service(timeout_sec=PATIENCE_S)
    future = client.call_async(SetParameters.Request(parameters=[parameter.to_parameter_msg()]))
    assert spin_until(ex, future.done, PATIENCE_S)
    return future.result().results[0]


def test_a_given_sensitivity_error_of_one_percent_on_fy_reads_one_percent_high(rclpy_context):
    name, prefix, args = isolated('load_cell')
    node = load_cell.LoadCell(context=rclpy_context, cli_args=args, parameter_overrides=[
        *QUIET, Parameter('truth.mode', value='given'),
        Parameter('truth.sensitivity', value=[0.0, 1.0, 0.0, 0.0, 0.0, 0.0]), Parameter('state_wait_s', value=0.25)])
    probe = Probe(rclpy_context, prefix)
    ex = SingleThreadedExecutor(context=rclpy_context)
    ex.add_node(node)
    ex.add_node(probe.node)
    assert spin_until(ex, lambda: probe.cmd.get_subscription_count() >= 1, PATIENCE_S)
    applied = np.array([0.5, 3.0, 0.0, 0.0, 0.0, 0.1])
    t_cmd = publish_wrench_now(probe.node, probe.cmd, applied, topics.FRAME_BASE)
    assert spin_until(ex, lambda: len(probe.readings_after(t_cmd)) >= 200, PATIENCE_S)
    readings = probe.readings_after(t_cmd)
    # Noise-free: every reading is the load with fy 1 % high, the other axes as applied.
    np.testing.assert_allclose(readings, np.tile([0.5, 3.03, 0.0, 0.0, 0.0, 0.1], (len(readings), 1)),
                               rtol=1e-12, atol=1e-15)
    # Back to a perfect sensor at runtime: the readings are the load again.
    assert node.set_parameters([Parameter('truth.mode', value='perfect')])[0].successful
    t_perfect = node.get_clock().now().nanoseconds + 50_000_000
    assert spin_until(ex, lambda: len(probe.readings_after(t_perfect)) >= 100, PATIENCE_S)
    np.testing.assert_allclose(probe.readings_after(t_perfect)[:, 1], 3.0, rtol=1e-12)
    ex.shutdown()


def test_an_lvdt_with_a_given_sensitivity_error_and_mains_hum_reads_both(rclpy_context):
    name, prefix, args = isolated('lvdt')
    node = lvdt.Lvdt(context=rclpy_context, cli_args=args, parameter_overrides=[
        Parameter('noise_std', value=0.0), Parameter('resolution', value=0.0), Parameter('seed', value=4),
        Parameter('zero_on_first_pose', value=False), Parameter('truth.mode', value='given'),
        Parameter('truth.sensitivity', value=0.5), Parameter('noise.mains_amplitude', value=2.0e-7),
        Parameter('noise.mains_hz', value=60.0)])
    probe = ProbeNode(rclpy_context, prefix)
    pose = probe.publisher(topics.PLATFORM_POSE, PoseStamped, RELIABLE_QOS)
    samples = probe.record(topics.LVDT_DISPLACEMENT, PointStamped, SENSOR_QOS,
                           lambda m: (stamp_ns(m.header.stamp), m.point.x))
    ex = SingleThreadedExecutor(context=rclpy_context)
    ex.add_node(node)
    ex.add_node(probe.node)
    assert spin_until(ex, lambda: pose.get_subscription_count() >= 1, PATIENCE_S)
    msg = PoseStamped()
    msg.header.stamp = probe.node.get_clock().now().to_msg()
    msg.header.frame_id = topics.FRAME_BASE
    msg.pose.position.y = 1.0e-3  # 1 mm along the LVDT's axis (y)
    msg.pose.orientation.w = 1.0
    pose.publish(msg)
    t_pose = stamp_ns(msg.header.stamp)
    assert spin_until(ex, lambda: sum(s > t_pose + 1_000_000 for s, _ in samples) >= 500, PATIENCE_S)
    t, x = np.array([(s, v) for s, v in samples if s > t_pose + 1_000_000]).T
    # reading = 1.005 · 1 mm + 0.2 µm · sin(2π·60 Hz·t + φ): a least-squares fit of the line at 60 Hz on the stamps
    # (samples a best-effort probe missed do not matter) gives back both, to rounding.
    phase = 2 * np.pi * 60.0 * (t - t[0]) * 1e-9
    coefficients = np.linalg.lstsq(np.column_stack([np.ones_like(t), np.sin(phase), np.cos(phase)]), x, rcond=None)[0]
    assert coefficients[0] == pytest.approx(1.005e-3, rel=1e-9)
    assert np.hypot(coefficients[1], coefficients[2]) == pytest.approx(2.0e-7, rel=1e-6)
    ex.shutdown()


def test_the_driver_emulators_carry_given_errors_too(rclpy_context):
    """rdt_emulator and modbus_emulator read the load and the pose with the truth they are given, as load_cell and
    lvdt do (what they serve to the drivers netft and modbus_lvdt)."""
    _, prefix, args = isolated('rdt_emulator')
    rdt = rdt_emulator.RdtEmulator(context=rclpy_context, cli_args=args, parameter_overrides=[
        *QUIET, Parameter('port', value=0), Parameter('http_port', value=-1), Parameter('truth.mode', value='given'),
        Parameter('truth.sensitivity', value=[0.0, 1.0, 0.0, 0.0, 0.0, 0.0])])
    _, mb_prefix, mb_args = isolated('modbus_emulator')
    modbus = modbus_emulator.ModbusEmulator(context=rclpy_context, cli_args=mb_args, parameter_overrides=[
        Parameter('port', value=0), Parameter('noise_std', value=0.0), Parameter('resolution', value=0.0),
        Parameter('truth.mode', value='given'), Parameter('truth.sensitivity', value=-2.0)])
    probe, mb_probe = Probe(rclpy_context, prefix), ProbeNode(rclpy_context, mb_prefix)
    pose = mb_probe.publisher(topics.PLATFORM_POSE, PoseStamped, RELIABLE_QOS)
    ex = SingleThreadedExecutor(context=rclpy_context)
    for node in (rdt, modbus, probe.node, mb_probe.node):
        ex.add_node(node)
    try:
        assert spin_until(ex, lambda: probe.cmd.get_subscription_count() >= 1 and pose.get_subscription_count() >= 1,
                          PATIENCE_S)
        publish_wrench_now(probe.node, probe.cmd, [0.0, 2.0, 0.0, 0.0, 0.0, 0.0], topics.FRAME_BASE)
        for y in (0.0, 4.0e-5):  # the first pose zeroes the LVDT; the second is 40 µm along its axis (y)
            msg = PoseStamped()
            msg.header.stamp = mb_probe.node.get_clock().now().to_msg()
            msg.pose.position.y = y
            msg.pose.orientation.w = 1.0
            pose.publish(msg)
            assert spin_until(ex, lambda: modbus.counters.used == (2 if y else 1), PATIENCE_S)
        assert spin_until(ex, lambda: rdt.applied is not None, PATIENCE_S)
        np.testing.assert_allclose(rdt._samples(7), np.tile([0.0, 2.02, 0.0, 0.0, 0.0, 0.0], (7, 1)), rtol=1e-12)
        assert modbus._reading() == pytest.approx(0.98 * 4.0e-5, rel=1e-12)
    finally:
        ex.shutdown()
        rdt.close()
        modbus.close()


@pytest.mark.parametrize('parameter, field, rule', [
    (Parameter('calibration.sensitivity_k', value=0.0), 'calibration.sensitivity_k', 'must be > 0'),
    (Parameter('calibration.crosstalk_distribution', value='gaussian'), 'calibration.crosstalk_distribution',
     'must be one of normal, rectangular, triangular, u_shaped, not_stated'),
    (Parameter('calibration.nonlinearity', value=[0.2, 0.2, -0.2, 0.2, 0.2, 0.2]), 'calibration.nonlinearity',
     'must be >= 0'),
])
def test_a_bad_declaration_is_refused_at_start(rclpy_context, parameter, field, rule):
    name, _, args = isolated('load_cell')
    with pytest.raises(ValueError) as err:
        load_cell.LoadCell(context=rclpy_context, cli_args=args, parameter_overrides=[parameter])
    assert str(err.value).startswith(f'{field} = ') and rule in str(err.value)


def test_a_bad_declaration_is_refused_on_change_and_the_old_value_kept(rclpy_context):
    name, prefix, args = isolated('load_cell')
    node = load_cell.LoadCell(context=rclpy_context, cli_args=args, parameter_overrides=QUIET)
    probe = Probe(rclpy_context, prefix)
    ex = SingleThreadedExecutor(context=rclpy_context)
    ex.add_node(node)
    ex.add_node(probe.node)
    before = list(node.get_parameter('calibration.sensitivity').value)
    for parameter, rule in [
            (Parameter('calibration.sensitivity', value=[1.0, 1.0, float('nan'), 1.0, 1.0, 1.0]), 'finite'),
            (Parameter('calibration.sensitivity', value=[-1.0]), '>= 0'),
            (Parameter('calibration.sensitivity_distribution', value='lognormal'), 'must be one of'),
            (Parameter('calibration.sensitivity_k', value=-2.0), '> 0'),
            (Parameter('truth.mode', value='approximate'), 'must be one of perfect, given, drawn')]:
        result = set_parameter(ex, probe.node, name, parameter)
        assert not result.successful and result.reason.startswith(f'{parameter.name} = ') and rule in result.reason
    assert list(node.get_parameter('calibration.sensitivity').value) == before == [1.0] * 6
    assert node.get_parameter('calibration.sensitivity_distribution').value == 'normal'
    assert node.get_parameter('calibration.sensitivity_k').value == 2.0
    assert node.get_parameter('truth.mode').value == 'perfect'
    # A good certificate is taken.
    result = set_parameter(ex, probe.node, name, Parameter('calibration.sensitivity', value=[0.8, 0.8, 0.8, 1.2,
                                                                                            1.2, 1.2]))
    assert result.successful
    assert list(node.get_parameter('calibration.sensitivity').value) == [0.8, 0.8, 0.8, 1.2, 1.2, 1.2]
    ex.shutdown()


def test_the_declared_calibration_and_the_truth_reach_the_bag(rclpy_context, tmp_path):
    """The recorder stores the load cell's parameters as it ran (calibration.*, truth.*) and the section of its
    parameter file: the drawn truth follows from them (crane_stiffness.sim.truth), for a study to read."""
    from crane_stiffness.sim.truth import load_cell_truth
    name, prefix, args = isolated('load_cell')
    certificate = {'calibration.sensitivity': [0.6, 0.6, 0.9, 1.1, 1.1, 1.5],
                   'calibration.sensitivity_distribution': 'normal', 'calibration.sensitivity_k': 2.0,
                   'calibration.hysteresis_distribution': 'not_stated',
                   'calibration.misalignment': [0.0175], 'calibration.misalignment_distribution': 'u_shaped',
                   'truth.mode': 'drawn', 'truth.seed': 17}
    sensors = tmp_path / 'sensors.yaml'
    sensors.write_text(yaml.safe_dump({name: {'ros__parameters': certificate}}))
    node = load_cell.LoadCell(context=rclpy_context, cli_args=[*args, '--params-file', str(sensors)],
                              parameter_overrides=QUIET)
    recorder = SessionRecorder(params_files=[str(sensors)], context=rclpy_context, parameter_overrides=[
        Parameter('output_dir', value=str(tmp_path / 'bags')), Parameter('session', value='calibration'),
        Parameter('record_node_parameters', value=[f'/{name}']), Parameter('flush_interval_s', value=0.2),
        Parameter('stop_on_program_done', value=False)])
    ex = SingleThreadedExecutor(context=rclpy_context)
    ex.add_node(node)
    ex.add_node(recorder)
    assert spin_until(ex, lambda: name in recorder.node_parameters, PATIENCE_S), recorder.parameter_reader.pending
    bag, _ = recorder.stop('test')
    ex.shutdown()
    with BagReader(bag) as reader:
        ran = read_node_parameters(reader)[name]
        session = read_session(reader)
    for key, value in certificate.items():
        assert ran[key] == value, key
        assert session['sensors'][name][key] == value, key
    assert ran['calibration.crosstalk'] == [0.5] * 6 and ran['calibration.crosstalk_distribution'] == 'rectangular'
    # The drawn truth of the session, from what was recorded, is the node's own.
    recorded = load_cell_truth(ran)
    assert node.model is not None and node.model.truth is not None
    assert recorded.as_dict() == node.model.truth.as_dict()
    assert json.dumps(recorded.as_dict())  # plain numbers, for a study's table
    assert 0 < np.abs(recorded.sensitivity).max() < 0.05 and np.abs(recorded.misalignment).max() <= 0.0175
