"""Driver and emulator nodes on real DDS (loopback): ``rdt_emulator`` → ``netft`` and ``modbus_emulator`` →
``modbus_lvdt`` as the installed console scripts in their own processes, and the nodes in-process against the
emulator classes for the faults (lost records, status word, a device that goes away), the services and the clear
start-up errors.

Every test remaps the rig's topics under its own prefix and gets its own DDS domain (conftest).
"""
from __future__ import annotations

import itertools
import math
import os
import socket
import threading
import time

import numpy as np
import pytest
from geometry_msgs.msg import PointStamped, PoseStamped, WrenchStamped
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter

from helpers import PATIENCE_S, call_trigger, isolated, publish_wrench_now, spin_until, stamp_ns, wrench_vector
from helpers.probe import ProbeNode
from helpers.processes import final_counters, start_node_process, stop_node_process
from crane_stiffness.contract import topics
from crane_stiffness.devices.modbus_device import ModbusDevice
from crane_stiffness.devices.rdt_device import RdtDevice
from crane_stiffness.drivers import rdt
from crane_stiffness.drivers.modbus import Channel
from crane_stiffness.nodes import modbus_emulator, modbus_lvdt, netft, rdt_emulator
from crane_stiffness.rosnode.qos import LATCHED_QOS, RELIABLE_QOS, SENSOR_QOS
from crane_stiffness.launcher.ports import free_port
from std_msgs.msg import Float64

pytestmark = pytest.mark.ros  # every test here starts ROS (conftest)

_ids = itertools.count()
BIAS = np.array([0.05, -0.03, 0.08, 0.001, -0.001, 0.0005])


class Probe(ProbeNode):
    """Publishes the rig's inputs and records the sensor topics and /diagnostics under a prefix."""

    def __init__(self, ctx, prefix: str):
        super().__init__(ctx, prefix, name=f'probe_{next(_ids)}_{os.getpid()}', diagnostics_depth=100)
        # What crane_model publishes after each command: the load in force, which the simulated sensors apply.
        self.cmd = self.publisher(topics.APPLIED_WRENCH, WrenchStamped, RELIABLE_QOS)
        self.pose = self.publisher(topics.PLATFORM_POSE, PoseStamped, RELIABLE_QOS)
        self.wrenches: list[tuple[int, str, np.ndarray]] = self.record(
            topics.LOAD_CELL_WRENCH, WrenchStamped, SENSOR_QOS,
            lambda m: (stamp_ns(m.header.stamp), m.header.frame_id, wrench_vector(m)))
        self.points: list[tuple[int, str, float]] = self.record(
            topics.LVDT_DISPLACEMENT, PointStamped, SENSOR_QOS,
            lambda m: (stamp_ns(m.header.stamp), m.header.frame_id, m.point.x))
        self.epochs: dict[str, list[float]] = {  # zero epochs
            topic: self.record(topic, Float64, LATCHED_QOS, lambda m: m.data)
            for topic in (topics.LVDT_ZERO, topics.LOAD_CELL_TARE)}

    def command(self, wrench) -> None:
        publish_wrench_now(self.node, self.cmd, wrench, topics.FRAME_BASE)

    def publish_pose(self, u) -> None:
        msg = PoseStamped()
        msg.header.stamp = self.node.get_clock().now().to_msg()
        msg.header.frame_id = topics.FRAME_BASE
        msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = (float(v) for v in u)
        msg.pose.orientation.w = 1.0
        self.pose.publish(msg)

    def wrench_after(self, t_ns: int) -> np.ndarray:
        return np.array([w for s, _, w in self.wrenches if s > t_ns]).reshape(-1, 6)

    def points_after(self, t_ns: int) -> np.ndarray:
        return np.array([x for s, _, x in self.points if s > t_ns])


def test_netft_reads_the_rdt_emulator_across_processes(rclpy_context, tmp_path):
    """applied wrench → rdt_emulator (load-cell physics, RDT on 127.0.0.1) → netft → /load_cell/wrench: the
    commanded wrench plus the sensor's bias, 7 kHz averaged to 1 kHz, stamped on the host clock; ~/tare; counters."""
    port = free_port(kind=socket.SOCK_DGRAM)
    emu_name, prefix, emu_args = isolated('rdt_emulator')
    ft_name = f'netft_{os.getpid()}_{next(_ids)}'
    ft_args = [a if not a.startswith('__node:=') else f'__node:={ft_name}' for a in emu_args]
    emu = start_node_process('rdt_emulator', emu_args + [
        '-p', f'port:={port}', '-p', 'noise_std:=[0.0, 0.0, 0.0, 0.0, 0.0, 0.0]', '-p',
        f'bias:={BIAS.tolist()}', '-p', 'resolution:=[0.0, 0.0, 0.0, 0.0, 0.0, 0.0]', '-p', 'seed:=1'],
        tmp_path / 'emu.log')
    probe = Probe(rclpy_context, prefix)
    ex = SingleThreadedExecutor(context=rclpy_context)
    ex.add_node(probe.node)
    t_start = time.time_ns()
    ft = None
    try:
        assert spin_until(ex, lambda: probe.cmd.get_subscription_count() >= 1, PATIENCE_S), \
            (tmp_path / 'emu.log').read_text()
        probe.command(np.zeros(6))  # the load in force at rest (crane_model sends it to a reader that joins)
        # netft starts once the emulator holds it (its diagnostics count it used): records streamed before that are
        # rightly marked not ready, and the status checked below must be that of a device that never was.
        assert spin_until(ex, lambda: (probe.status(emu_name) or (None, {}))[1].get('used') == '1', PATIENCE_S), \
            (tmp_path / 'emu.log').read_text()
        ft = start_node_process('netft', ft_args + [
            '-p', 'host:=127.0.0.1', '-p', f'port:={port}', '-p', 'counts_per_force:=1000000.0', '-p',
            'counts_per_torque:=1000000.0', '-p', 'publish_rate_hz:=1000.0', '-p', 'frame_id:=ft_test',
            '-p', 'tare_samples:=200'], tmp_path / 'netft.log')
        assert spin_until(ex, lambda: len(probe.wrenches) > 500, PATIENCE_S), (tmp_path / 'netft.log').read_text()
        # No command yet: the sensor reads its bias.
        np.testing.assert_allclose(probe.wrench_after(0)[-100:], np.tile(BIAS, (100, 1)), atol=1e-6)
        applied = np.array([0.5, 2.0, 50.0, 0.01, -0.02, 0.1])
        probe.command(applied)
        assert spin_until(ex, lambda: np.abs(probe.wrench_after(0)[-1] - (applied + BIAS)).max() < 1e-6, PATIENCE_S)
        t_cmd = probe.wrenches[-1][0]
        spin_until(ex, lambda: len(probe.wrench_after(t_cmd)) >= 300, PATIENCE_S)
        np.testing.assert_allclose(probe.wrench_after(t_cmd), np.tile(applied + BIAS, (len(probe.wrench_after(t_cmd)),
                                                                                      1)), atol=1e-6)
        stamps = np.array([s for s, _, _ in probe.wrenches])
        assert {f for _, f, _ in probe.wrenches} == {'ft_test'}
        assert np.all(np.diff(stamps) > 0)
        assert np.median(np.diff(stamps)) == pytest.approx(1e6, abs=5e4)   # 1 kHz out of 7 kHz
        assert t_start < stamps[0] and stamps[-1] < time.time_ns()         # on the host clock
        # Software tare at the load: the reading becomes zero.
        assert spin_until(ex, lambda: probe.epochs[topics.LOAD_CELL_TARE] == [0.0], PATIENCE_S)  # latched at start
        reply = call_trigger(ex, probe.node, f'/{ft_name}/tare')
        assert reply.success and 'tared on 200 samples' in reply.message
        # the estimator segments on it
        assert spin_until(ex, lambda: probe.epochs[topics.LOAD_CELL_TARE] == [0.0, 1.0], PATIENCE_S)
        # Samples stamped after the reply were sampled, so received and processed, after the tare.
        t_tare = time.time_ns() + 5_000_000
        assert spin_until(ex, lambda: len(probe.wrench_after(t_tare)) >= 100, PATIENCE_S)
        assert np.abs(probe.wrench_after(t_tare)).max() < 1e-6
        # Diagnostics: records counted, nothing lost on loopback.
        assert spin_until(ex, lambda: probe.status(ft_name) is not None, PATIENCE_S)
        status, values = probe.status(ft_name)
        assert int(values['received']) > 1000 and values['streaming'] == 'true'
        assert values['last_status'] == '0x00000000'
    finally:
        ft_code, ft_log = stop_node_process(ft, tmp_path / 'netft.log') if ft is not None else (None, '')
        emu_code, emu_log = stop_node_process(emu, tmp_path / 'emu.log')
    assert ft_code == 0, ft_log[-3000:]
    assert emu_code == 0, emu_log[-3000:]
    counters = final_counters(ft_log, ft_name)
    sent = final_counters(emu_log, emu_name)
    print('netft', counters, 'emulator', sent)
    assert counters['published'] > 1000 and counters['received'] >= 6 * counters['published']
    assert counters['malformed_datagrams'] == 0 and counters['status_records'] == 0
    assert sent['received'] == 2 and sent['stream_requests'] >= 1 and sent['published'] >= counters['received']


def test_modbus_lvdt_reads_the_modbus_emulator_across_processes(rclpy_context, tmp_path):
    """platform pose → modbus_emulator (LVDT physics, float32 volts little-endian words on 127.0.0.1) → modbus_lvdt
    → /lvdt/displacement: the displacement from the first pose in metres; ~/zero; jitter on /diagnostics."""
    port = free_port(kind=socket.SOCK_STREAM)
    emu_name, prefix, emu_args = isolated('modbus_emulator')
    lv_name = f'modbus_lvdt_{os.getpid()}_{next(_ids)}'
    lv_args = [a if not a.startswith('__node:=') else f'__node:={lv_name}' for a in emu_args]
    channel = ['-p', 'register:=4', '-p', 'data_type:=float32', '-p', 'word_order:=little', '-p', 'gain:=0.002',
               '-p', 'offset:=-0.001', '-p', 'unit_id:=2']
    emu = start_node_process('modbus_emulator', emu_args + channel + [
        '-p', f'port:={port}', '-p', 'noise_std:=0.0', '-p', 'resolution:=0.0'], tmp_path / 'emu.log')
    probe = Probe(rclpy_context, prefix)
    ex = SingleThreadedExecutor(context=rclpy_context)
    ex.add_node(probe.node)
    lv = None
    try:
        assert spin_until(ex, lambda: probe.pose.get_subscription_count() >= 1, PATIENCE_S), \
            (tmp_path / 'emu.log').read_text()
        lv = start_node_process('modbus_lvdt', lv_args + channel + [
            '-p', 'host:=127.0.0.1', '-p', f'port:={port}', '-p', 'poll_rate_hz:=200.0', '-p', 'frame_id:=lvdt_mb'],
            tmp_path / 'lvdt.log')
        # No pose yet: the emulator answers "server device busy" and the driver publishes nothing (a reading of a
        # pose nobody measured would let a load program start before the chain is live).
        lv_log = tmp_path / 'lvdt.log'
        assert spin_until(ex, lambda: 'server device busy' in lv_log.read_text(), PATIENCE_S), lv_log.read_text()
        assert probe.points == []
        rest = np.array([0.0, 0.0, 2.4e-5])
        probe.publish_pose(rest)  # the first pose: the emulator's LVDT zeroes on it
        assert spin_until(ex, lambda: len(probe.points) > 50, PATIENCE_S), (tmp_path / 'lvdt.log').read_text()
        # Every reading, the first included, is of the zeroed rest pose: none was made up before the first pose (a
        # register read while busy would read the channel's offset, -1 mm), however late it would have arrived.
        assert np.abs(probe.points_after(0)).max() < 1e-9
        probe.publish_pose(rest + [0.0, 5e-5, 0.0])  # 50 µm along the LVDT's axis (y)
        assert spin_until(ex, lambda: abs(probe.points[-1][2] - 5e-5) < 1e-9, PATIENCE_S)
        t_move = probe.points[-1][0]
        spin_until(ex, lambda: len(probe.points_after(t_move)) >= 20, PATIENCE_S)
        np.testing.assert_allclose(probe.points_after(t_move), 5e-5, atol=1e-9)  # float32 volts: ~1e-10 m
        stamps = np.array([s for s, _, _ in probe.points])
        assert np.all(np.diff(stamps) > 0) and {f for _, f, _ in probe.points} == {'lvdt_mb'}
        assert spin_until(ex, lambda: probe.epochs[topics.LVDT_ZERO] == [0.0], PATIENCE_S)  # latched at start
        reply = call_trigger(ex, probe.node, f'/{lv_name}/zero')
        assert reply.success and 'zeroed on 10 readings' in reply.message
        # the estimator segments on it
        assert spin_until(ex, lambda: probe.epochs[topics.LVDT_ZERO] == [0.0, 1.0], PATIENCE_S)
        t_zero = time.time_ns() + 5_000_000  # polled after the reply
        assert spin_until(ex, lambda: len(probe.points_after(t_zero)) >= 10, PATIENCE_S)
        assert np.abs(probe.points_after(t_zero)).max() < 1e-9
        assert spin_until(ex, lambda: probe.status(lv_name) is not None, PATIENCE_S)
        status, values = probe.status(lv_name)
        assert status.level == b'\x00' and values['failures'] == '0'
        assert math.isfinite(float(values['poll_jitter_p99_us']))
    finally:
        lv_code, lv_log = stop_node_process(lv, tmp_path / 'lvdt.log') if lv is not None else (None, '')
        emu_code, emu_log = stop_node_process(emu, tmp_path / 'emu.log')
    assert lv_code == 0, lv_log[-3000:]
    assert emu_code == 0, emu_log[-3000:]
    counters = final_counters(lv_log, lv_name)
    assert counters['published'] > 50 and counters['failures'] == 0
    assert final_counters(emu_log, emu_name)['published'] >= counters['published']


# --- in-process: faults, services, parameters ---------------------------------------------------------------------

def spin_node(ctx, node, prefix):
    probe = Probe(ctx, prefix)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    ex.add_node(probe.node)
    return probe, ex


def test_netft_reports_lost_records_status_word_and_a_device_that_goes_away(rclpy_context):
    wrench = np.array([1.0, 2.0, 3.0, 0.1, 0.2, 0.3])
    dev = RdtDevice(lambda: wrench, sample_rate_hz=2000.0, http_port=0,
                    calibration=rdt.Calibration(2e5, 5e6)).start()
    name, prefix, args = isolated('netft')
    node = netft.NetFt(context=rclpy_context, cli_args=args, parameter_overrides=[
        Parameter('host', value='127.0.0.1'), Parameter('port', value=dev.port),
        Parameter('http_port', value=dev.http_port), Parameter('sample_rate_hz', value=2000.0),
        Parameter('tare_mode', value='hardware'), Parameter('timeout_s', value=0.3),
        Parameter('reconnect_interval_s', value=0.3)])
    probe, ex = spin_node(rclpy_context, node, prefix)
    try:
        # Calibration from the box's netftapi2.xml (2e5 counts/N, 5e6 counts/N·m).
        assert spin_until(ex, lambda: len(probe.wrenches) > 200, PATIENCE_S)
        np.testing.assert_allclose(probe.wrenches[-1][2], wrench, atol=1e-5)
        # Lost records → WARN with the count.
        dev.drop = lambda seq: seq % 100 == 0
        assert spin_until(ex, lambda: (s := probe.status(name, b'\x01')) is not None and 'records lost' in
                          s[0].message, PATIENCE_S)
        assert node.counters.records_lost > 0
        dev.drop = None
        # A status word → ERROR naming it; those records are not published.
        dev.status = 0x80000000
        assert spin_until(ex, lambda: (s := probe.status(name, b'\x02')) is not None and '0x80000000' in
                          s[0].message, PATIENCE_S)
        assert node.counters.status_dropped > 0
        dev.status = 0
        # Hardware tare: the bias command reaches the device, readings become zero.
        reply = call_trigger(ex, probe.node, f'/{name}/tare')
        assert reply.success and '0x0042' in reply.message
        # a bias is a tare too
        assert spin_until(ex, lambda: probe.epochs[topics.LOAD_CELL_TARE] == [0.0, 1.0], PATIENCE_S)
        assert spin_until(ex, lambda: np.abs(probe.wrenches[-1][2]).max() < 1e-5, PATIENCE_S)
        assert (rdt.CMD_BIAS, 0) in dev.requests
        # The device goes away: ERROR while silent, then it comes back and the stream is requested again.
        dev.stop()
        assert spin_until(ex, lambda: (s := probe.status(name, b'\x02')) is not None and 'no record' in
                          s[0].message, PATIENCE_S)
        dev.start()
        # The bias went with the power: the readings are the wrench again (the probe may still be working through
        # zeros published before the device went away: wait for the newest).
        assert spin_until(ex, lambda: np.abs(probe.wrenches[-1][2] - wrench).max() < 1e-5, PATIENCE_S)
        assert node.counters.reconnects >= 1 and node.receiver.streaming
    finally:
        ex.shutdown()
        node.close()
        dev.stop()


def test_netft_after_a_power_cycle_publishes_nothing_from_before_it(rclpy_context):
    """The F/T device stops for 2 s and restarts as after a power cycle (counters from 1 again, 2 datagrams in
    flight across the outage): no wrench published after the restart carries a record from before it (the device
    serves another wrench after it), and the counters and /diagnostics name the restart."""
    before, after = np.array([1.0, 2.0, 3.0, 0.1, 0.2, 0.3]), np.array([-4.0, 5.0, 6.0, -0.4, 0.5, 0.6])
    dev = RdtDevice(lambda: after if dev.power_cycles else before, sample_rate_hz=7000.0).start()
    name, prefix, args = isolated('netft')
    node = netft.NetFt(context=rclpy_context, cli_args=args, parameter_overrides=[
        Parameter('host', value='127.0.0.1'), Parameter('port', value=dev.port),
        Parameter('counts_per_force', value=1e6), Parameter('counts_per_torque', value=1e6),
        Parameter('sample_rate_hz', value=7000.0), Parameter('publish_rate_hz', value=1000.0),
        Parameter('timeout_s', value=0.5), Parameter('reconnect_interval_s', value=0.25)])
    published: list[tuple[int, int, np.ndarray]] = []   # (wall time of publish, stamp, wrench) as netft publishes
    publish = node.pub.publish
    node.pub.publish = lambda m: (published.append((time.time_ns(), stamp_ns(m.header.stamp), wrench_vector(m))),
                                  publish(m))[-1]
    probe, ex = spin_node(rclpy_context, node, prefix)
    done: dict[str, int] = {}

    def cycle() -> None:
        done['held'] = dev.power_cycle(2.0, in_flight=2)
        done['up_ns'] = time.time_ns()
    try:
        assert spin_until(ex, lambda: len(probe.wrenches) > 200, PATIENCE_S)
        thread = threading.Thread(target=cycle)
        thread.start()
        assert spin_until(ex, lambda: (s := probe.status(name, b'\x02')) is not None and 'no record' in
                          s[0].message, PATIENCE_S)
        assert spin_until(ex, lambda: not thread.is_alive(), PATIENCE_S) and done['held'] == 2
        assert spin_until(ex, lambda: sum(t > done['up_ns'] for t, _, _ in published) >= 500, PATIENCE_S)
        assert spin_until(ex, lambda: (s := probe.status(name, b'\x01')) is not None and 'device restarted' in
                          s[0].message, PATIENCE_S)
        late = [(s, w) for t, s, w in published if t > done['up_ns']]
        np.testing.assert_allclose([w for _, w in late], np.tile(after, (len(late), 1)), atol=1e-9)
        last_before = max(s for t, s, _ in published if t <= done['up_ns'])
        assert min(s for s, _ in late) > last_before
        c = node.counters
        # one clock reset (one power cycle); a restart at least (a starved receiver may ask once more: test_driver_
        # outage)
        assert (c.stream_restarts >= 1, c.clock_resets, c.records_lost, c.records_duplicate) == (True, 1, 0, 0)
        assert c.records_stale_dropped >= 2
        status, values = probe.status(name, b'\x01')
        assert int(values['stream_restarts']) >= 1 and values['clock_resets'] == '1'
        assert 'counter started again' in status.message and 'before the outage not published' in status.message
    finally:
        ex.shutdown()
        node.close()
        dev.stop()


def test_netft_parameters_checked_at_start_and_on_change(rclpy_context):
    with RdtDevice(lambda: np.zeros(6), sample_rate_hz=1000.0) as dev:
        name, prefix, args = isolated('netft')
        node = netft.NetFt(context=rclpy_context, cli_args=args, parameter_overrides=[
            Parameter('host', value='127.0.0.1'), Parameter('port', value=dev.port), Parameter('device',
                                                                                               value='onrobot'),
            Parameter('sample_rate_hz', value=1000.0)])
        try:
            assert node.pipeline.calibration == rdt.ONROBOT
            bad = node.set_parameters([Parameter('host', value='10.0.0.5')])[0]
            assert not bad.successful and 'host' in bad.reason and 'restart the node' in bad.reason
            bad = node.set_parameters([Parameter('tare_mode', value='magic')])[0]
            assert not bad.successful and 'tare_mode' in bad.reason
            bad = node.set_parameters([Parameter('publish_rate_hz', value=5000.0)])[0]
            assert not bad.successful and 'up to sample_rate_hz' in bad.reason
            assert node.set_parameters([Parameter('publish_rate_hz', value=100.0)])[0].successful
            assert node.pipeline.publish_period_ns == 10_000_000
        finally:
            node.close()
            node.destroy_node()


def test_driver_mains_exit_2_with_a_clear_reason(capsys):
    udp = free_port(kind=socket.SOCK_DGRAM)
    assert netft.main(['--ros-args', '-p', 'host:=127.0.0.1', '-p', f'port:={udp}', '-p', 'counts_per_force:=1e6',
                       '-p', 'counts_per_torque:=1e6', '-p', 'wait_for_device_s:=1.0']) == 2
    assert 'port unreachable' in capsys.readouterr().err
    with RdtDevice(lambda: np.zeros(6)) as dev:
        dev.silent = True
        assert netft.main(['--ros-args', '-p', 'host:=127.0.0.1', '-p', f'port:={dev.port}', '-p',
                           'device:=onrobot', '-p', 'wait_for_device_s:=1.0']) == 2
    assert 'sent no record within 1.0 s' in capsys.readouterr().err
    assert netft.main(['--ros-args', '-p', 'counts_per_force:=1e6']) == 2
    assert 'set counts_per_force and counts_per_torque together' in capsys.readouterr().err
    tcp = free_port(kind=socket.SOCK_STREAM)
    assert modbus_lvdt.main(['--ros-args', '-p', 'host:=127.0.0.1', '-p', f'port:={tcp}']) == 2
    assert f'no Modbus TCP device at 127.0.0.1:{tcp}' in capsys.readouterr().err
    assert modbus_lvdt.main(['--ros-args', '-p', 'data_type:=float64']) == 2
    assert 'data_type' in capsys.readouterr().err
    assert rdt_emulator.main(['--ros-args', '-p', 'full_scale:=[1.0]']) == 2
    assert 'full_scale' in capsys.readouterr().err
    assert modbus_emulator.main(['--ros-args', '-p', 'range_m:=[0.001, -0.001]']) == 2
    assert 'range_m' in capsys.readouterr().err


def test_modbus_lvdt_reports_failures_and_recovers(rclpy_context):
    ch = Channel(register=0, data_type='int16', gain=1e-6)
    reading = {'m': 0.00123}
    with ModbusDevice(lambda: reading['m'], channel=ch) as dev:
        name, prefix, args = isolated('modbus_lvdt')
        node = modbus_lvdt.ModbusLvdt(context=rclpy_context, cli_args=args, parameter_overrides=[
            Parameter('host', value='127.0.0.1'), Parameter('port', value=dev.port),
            Parameter('data_type', value='int16'), Parameter('gain', value=1e-6), Parameter('offset', value=0.0),
            Parameter('poll_rate_hz', value=100.0)])
        probe, ex = spin_node(rclpy_context, node, prefix)
        try:
            assert spin_until(ex, lambda: len(probe.points) > 10, PATIENCE_S)
            assert probe.points[-1][2] == pytest.approx(0.00123, abs=1e-12)
            dev.fail_with = 4
            assert spin_until(ex, lambda: (s := probe.status(name, b'\x02')) is not None and
                              'exception 4 (server device failure)' in s[0].message, PATIENCE_S)
            assert node.counters.exception_responses > 0
            dev.fail_with = 0
            reading['m'] = -0.0005
            assert spin_until(ex, lambda: probe.points[-1][2] == pytest.approx(-0.0005, abs=1e-12), PATIENCE_S)
            assert spin_until(ex, lambda: (s := probe.status(name)) is not None and s[0].level == b'\x00', PATIENCE_S)
            # Runtime change of the scaling: accepted (the device still sends -500 counts, now read as 2 µm each);
            # of the address: refused with the reason.
            assert node.set_parameters([Parameter('gain', value=2e-6)])[0].successful
            assert spin_until(ex, lambda: probe.points[-1][2] == pytest.approx(-0.001, abs=1e-12), PATIENCE_S)
            bad = node.set_parameters([Parameter('port', value=1)])[0]
            assert not bad.successful and 'restart the node' in bad.reason
        finally:
            ex.shutdown()
            node.close()
            node.destroy_node()
