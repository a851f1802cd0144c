"""load_cell and lvdt nodes in-process: real rclpy, DDS on loopback, measured rates and noise, exact LVDT readings.

Every node under test gets its own node name and topic names (remapped), so tests cannot hear each other.
"""
from __future__ import annotations

import itertools
import math
import os
import time
from pathlib import Path

os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')  # normally set by conftest.py already
os.environ.setdefault('ROS_DOMAIN_ID', str(os.getpid() % 100 + 1))

import numpy as np  # noqa: E402
import pytest  # noqa: E402
from geometry_msgs.msg import PointStamped, PoseStamped, WrenchStamped  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.node import Node  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402

from helpers import PATIENCE_S, call_trigger as call, publish_wrench_now  # noqa: E402
from helpers import isolated, spin_until, stamp_ns, wrench_vector  # noqa: E402
from helpers.probe import ProbeNode  # noqa: E402
from crane_stiffness.contract import topics  # noqa: E402
from crane_stiffness.params.files import load_params  # noqa: E402
from crane_stiffness.model.rotation import euler_zxy_to_matrix, matrix_to_quaternion  # noqa: E402
from crane_stiffness.nodes import load_cell, lvdt  # noqa: E402
from crane_stiffness.rosnode.qos import LATCHED_QOS, RELIABLE_QOS, SENSOR_QOS  # noqa: E402
from std_msgs.msg import Float64  # noqa: E402

pytestmark = pytest.mark.ros  # every test here starts ROS (conftest)

_ids = itertools.count()
MS = 1_000_000  # ns


def wait_connected(ex, pub, sub_count: int = 1) -> None:
    assert spin_until(ex, lambda: pub.get_subscription_count() >= sub_count, PATIENCE_S)


class LoadCellProbe(ProbeNode):
    """Applies a wrench (publishes what crane_model publishes on /crane/applied_wrench) and records the load cell's
    samples and diagnostics."""

    def __init__(self, ctx, prefix: str):
        super().__init__(ctx, prefix, diagnostics_depth=10)
        self.samples: list[tuple[float, str, np.ndarray]] = []  # (stamp, frame, wrench)
        self.arrivals: list[float] = []
        self.cmd = self.publisher(topics.APPLIED_WRENCH, WrenchStamped, RELIABLE_QOS)
        self.node.create_subscription(WrenchStamped, prefix + topics.LOAD_CELL_WRENCH, self._on_sample, SENSOR_QOS)
        # the zero epochs received on /load_cell/tare
        self.epochs: list[float] = self.record(topics.LOAD_CELL_TARE, Float64, LATCHED_QOS, lambda m: m.data)

    def _on_sample(self, msg: WrenchStamped) -> None:
        self.arrivals.append(time.monotonic())
        self.samples.append((stamp_ns(msg.header.stamp), msg.header.frame_id, wrench_vector(msg)))

    def command(self, wrench) -> int:
        return publish_wrench_now(self.node, self.cmd, wrench, topics.FRAME_BASE)

    def readings_after(self, t_ns: int) -> np.ndarray:
        return np.array([w for s, _, w in self.samples if s > t_ns + MS])


def test_load_cell_rate_stamps_noise_and_applied_wrench(rclpy_context):
    noise = np.array([0.02, 0.05, 0.1, 0.001, 0.002, 0.003])
    name, prefix, args = isolated('load_cell')
    # On wall-clock time a command can reach the sensor after instants at its stamp have passed: with state_wait_s
    # the sensor holds a sample back until the wrench in force at its instant is known (at most that long), so every
    # reading stamped t is the load in force at t however late the command arrives (within the wait).
    node = load_cell.LoadCell(context=rclpy_context, cli_args=args, parameter_overrides=[
        Parameter('noise_std', value=noise.tolist()), Parameter('bias', value=[0.0] * 6),
        Parameter('resolution', value=[0.0] * 6), Parameter('seed', value=3), Parameter('state_wait_s', value=5.0)])
    probe = LoadCellProbe(rclpy_context, prefix)
    ex = SingleThreadedExecutor(context=rclpy_context)
    ex.add_node(node)
    ex.add_node(probe.node)
    wait_connected(ex, probe.cmd)
    # Nothing is measured before the first applied wrench, and the load cell says what it waits for: it has held
    # back 100 samples and published none (its own count: none can be on its way to the probe).
    assert spin_until(ex, lambda: node.counters.waiting_samples > 100, PATIENCE_S)
    assert node.counters.published == 0 and probe.samples == []
    assert spin_until(ex, lambda: any(s.hardware_id == name and '/crane/applied_wrench' in s.message
                                      for s in probe.diagnostics), PATIENCE_S)
    probe.command(np.zeros(6))
    assert spin_until(ex, lambda: len(probe.samples) > 50, PATIENCE_S)
    applied = np.array([0.0, 2.0, 0.0, 0.0, 0.0, 0.1])
    t_cmd = probe.command(applied)
    # Until a thousand readings of the new load arrived (1 s of samples on the wall clock: longer on a loaded machine)
    assert spin_until(ex, lambda: len(probe.readings_after(t_cmd)) > 1000, PATIENCE_S), len(probe.readings_after(t_cmd))
    stamps = np.array([s for s, _, _ in probe.samples])
    # Stamps on the 1 ms grid, one sample per grid instant, every one published. (Best-effort delivery to this probe
    # may skip some on a loaded machine: gaps are whole periods, and the node published every instant between.)
    assert np.all(stamps % MS == 0)
    gaps = np.diff(stamps)
    assert np.all(gaps > 0) and np.all(gaps % MS == 0)
    assert node.counters.published >= (stamps[-1] - stamps[0]) // MS + 1
    arrivals = np.array(probe.arrivals)
    rate_wall = (arrivals > arrivals[-1] - 1.0).sum()
    print(f'load_cell: {rate_wall} samples arrived in the last second of wall time, {np.mean(gaps == MS):.3f} of '
          f'the gaps one period (a rate target is benchmarks/bench_rig.py\'s, not a test\'s)')
    assert {f for _, f, _ in probe.samples} == {'load_cell'}
    # The command takes effect at its stamp; noise as configured, mean = applied wrench.
    # The command took effect at its stamp, or, when it came later than the node's wait for it (state_wait_s: a
    # loaded machine may delay it, and how often is benchmarks/'s question), at its arrival: the readings from then on.
    assert spin_until(ex, lambda: node.counters.received == 2, PATIENCE_S)
    t_eff = node.applied.known_through_ns
    assert t_eff >= t_cmd, (t_eff, t_cmd)
    assert spin_until(ex, lambda: len(probe.readings_after(t_eff)) > 1000, PATIENCE_S)
    w = probe.readings_after(t_eff)
    assert len(w) > 1000
    std = w.std(axis=0, ddof=1)
    print('load_cell noise std measured', std.round(5).tolist(), 'configured', noise.tolist())
    np.testing.assert_allclose(std, noise, rtol=0.1)
    assert np.all(np.abs(w.mean(axis=0) - applied) < 4 * noise / math.sqrt(len(w)))
    before = np.array([w for s, _, w in probe.samples if s < t_cmd - MS])
    assert np.all(np.abs(before.mean(axis=0)) < 4 * noise / math.sqrt(len(before)))
    assert node.counters.received == node.counters.used == 2
    # (A process stalled past its sample clock's backlog limit, 0.5 s, skips instants and counts them, as a DAQ
    # overflow would: a loaded CI machine stalled this one 0.9 s. How often is a speed question, benchmarks/'s.)
    print(f'load_cell: {node.clock.skipped} instants skipped after stalls')
    print(f'load_cell: {node.applied.late} command(s) came later than state_wait_s after their stamp')
    ex.shutdown()


def test_load_cell_tare_crosstalk_and_overload(rclpy_context):
    bias = np.array([0.5, -0.3, 1.0, 0.01, -0.02, 0.005])
    noise = np.array([0.01, 0.01, 0.01, 0.0005, 0.0005, 0.0005])
    crosstalk = np.eye(6)
    crosstalk[0, 1] = 0.02  # 2 % of fy leaks into fx
    name, prefix, args = isolated('load_cell')
    node = load_cell.LoadCell(context=rclpy_context, cli_args=args, parameter_overrides=[
        Parameter('noise_std', value=noise.tolist()), Parameter('bias', value=bias.tolist()),
        Parameter('resolution', value=[0.0] * 6), Parameter('crosstalk', value=crosstalk.ravel().tolist()),
        Parameter('full_scale', value=[40.0, 5.0, 120.0, 2.0, 2.0, 2.0]), Parameter('tare_samples', value=400),
        Parameter('sample_rate_hz', value=500.0), Parameter('seed', value=11)])
    probe = LoadCellProbe(rclpy_context, prefix)
    ex = SingleThreadedExecutor(context=rclpy_context)
    ex.add_node(node)
    ex.add_node(probe.node)
    wait_connected(ex, probe.cmd)
    reply = call(ex, probe.node, f'/{name}/tare')
    assert not reply.success and 'waiting for /crane/applied_wrench' in reply.message  # no load known yet
    assert spin_until(ex, lambda: probe.epochs, PATIENCE_S)  # latched at start (a failed tare adds none: below)
    probe.command(np.zeros(6))
    assert spin_until(ex, lambda: len(probe.samples) > 300, PATIENCE_S)
    raw = np.array([w for _, _, w in probe.samples])
    tol = 4 * noise / math.sqrt(len(raw))
    assert np.all(np.abs(raw.mean(axis=0) - bias) < tol)  # before the tare, the bias shows
    reply = call(ex, probe.node, f'/{name}/tare')
    assert reply.success and 'tared on 400 samples' in reply.message and '0.5' in reply.message
    # The estimator segments on it. One writer, in order: an epoch of the failed attempt would have come before it.
    assert spin_until(ex, lambda: 1.0 in probe.epochs, PATIENCE_S), probe.epochs
    assert probe.epochs == [0.0, 1.0], probe.epochs
    np.testing.assert_allclose(node.model.offset, bias, atol=4 * noise.max() / math.sqrt(400) + 1e-12)
    t_tare = probe.node.get_clock().now().nanoseconds
    # Enough readings for the statistics (how long they take is the machine's business, not this test's).
    assert spin_until(ex, lambda: len(probe.readings_after(t_tare)) > 300, PATIENCE_S)
    tared = probe.readings_after(t_tare)
    # After the tare the zero-load reading is zero within the tare's own averaging error and this mean's.
    assert np.all(np.abs(tared.mean(axis=0)) < 4 * noise / math.sqrt(400) + 4 * noise / math.sqrt(len(tared)))
    # Cross-talk: 3 N along y reads 0.06 N along x.
    t_cmd = probe.command([0.0, 3.0, 0.0, 0.0, 0.0, 0.0])
    # From 50 ms after the command's stamp: samples already published when it arrived keep the old load.
    assert spin_until(ex, lambda: len(probe.readings_after(t_cmd + 50 * MS)) >= 300, PATIENCE_S)
    loaded = probe.readings_after(t_cmd + 50 * MS)
    assert loaded[:, 0].mean() == pytest.approx(0.06, abs=0.005)
    assert loaded[:, 1].mean() == pytest.approx(3.0, abs=0.005)
    # Overload: 10 N on a 5 N axis saturates at full scale (minus the tare offset) and /diagnostics warns.
    probe.diagnostics.clear()
    t_cmd = probe.command([0.0, 10.0, 0.0, 0.0, 0.0, 0.0])
    assert spin_until(ex, lambda: any(s.level == b'\x01' and s.hardware_id == name for s in probe.diagnostics),
                      PATIENCE_S)
    warn = [s for s in probe.diagnostics if s.level == b'\x01'][0]
    assert 'overload' in warn.message and 'fy' in warn.message
    assert spin_until(ex, lambda: len(probe.readings_after(t_cmd + 50 * MS)) >= 50, PATIENCE_S)
    saturated = probe.readings_after(t_cmd + 50 * MS)
    np.testing.assert_allclose(saturated[:, 1], 5.0 - node.model.offset[1], atol=1e-12)
    assert node.saturated[1] >= len(saturated)
    ex.shutdown()


def test_load_cell_parameters_validated_and_bad_start_refused(rclpy_context):
    name, prefix, args = isolated('load_cell')
    node = load_cell.LoadCell(context=rclpy_context, cli_args=args)
    bad = node.set_parameters([Parameter('noise_std', value=[0.1, 0.1, 0.1])])[0]
    assert not bad.successful and 'noise_std' in bad.reason and '6 numbers' in bad.reason
    bad = node.set_parameters([Parameter('sample_rate_hz', value=-5.0)])[0]
    assert not bad.successful and 'sample_rate_hz = -5.0' in bad.reason
    bad = node.set_parameters([Parameter('full_scale', value=[40.0, 40.0, 0.0, 2.0, 2.0, 2.0])])[0]
    assert not bad.successful and 'full_scale' in bad.reason
    assert node.get_parameter('sample_rate_hz').value == 1000.0
    assert list(node.get_parameter('noise_std').value) == [0.01, 0.01, 0.01, 0.0005, 0.0005, 0.0005]
    assert node.set_parameters([Parameter('sample_rate_hz', value=250.0)])[0].successful
    assert node.clock.period_ns == 4_000_000
    with pytest.raises(ValueError, match='tare_samples = 0'):
        load_cell.LoadCell(context=rclpy_context, cli_args=isolated('load_cell')[2],
                           parameter_overrides=[Parameter('tare_samples', value=0)])
    node.destroy_node()


def test_node_mains_exit_2_on_bad_parameters(capsys):
    assert load_cell.main(['--ros-args', '-p', 'tare_samples:=0']) == 2
    assert lvdt.main(['--ros-args', '-p', 'range_m:=[0.001, -0.001]']) == 2
    err = capsys.readouterr().err
    assert 'tare_samples = 0' in err and 'range_m' in err


class LvdtProbe(ProbeNode):
    def __init__(self, ctx, prefix: str):
        super().__init__(ctx, prefix, diagnostics_depth=10)
        self.pose = self.publisher(topics.PLATFORM_POSE, PoseStamped, RELIABLE_QOS)
        self.samples: list[tuple[float, str, float]] = self.record(
            topics.LVDT_DISPLACEMENT, PointStamped, SENSOR_QOS,
            lambda m: (stamp_ns(m.header.stamp), m.header.frame_id, m.point.x))
        # the zero epochs received on /lvdt/zero
        self.epochs: list[float] = self.record(topics.LVDT_ZERO, Float64, LATCHED_QOS, lambda m: m.data)

    def publish(self, u, q: np.ndarray) -> int:
        msg = PoseStamped()
        now = self.node.get_clock().now()
        msg.header.stamp = now.to_msg()
        msg.header.frame_id = topics.FRAME_BASE
        p, o = msg.pose.position, msg.pose.orientation
        p.x, p.y, p.z = (float(v) for v in u)
        o.x, o.y, o.z, o.w = (float(v) for v in matrix_to_quaternion(q))
        self.pose.publish(msg)
        return now.nanoseconds

    def readings_after(self, t_ns: int) -> np.ndarray:
        return np.array([x for s, _, x in self.samples if s > t_ns + MS])

    def moved(self, t_ns: int, old: float, new: float) -> bool:
        """After a pose stamped ``t_ns``: every reading is ``old`` or ``new`` and the last five are ``new``. (A pose
        takes effect at its stamp, but samples already published when it arrived keep the old value.)"""
        r = self.readings_after(t_ns)
        on = lambda v: np.isclose(r, v, rtol=0.0, atol=1e-12)  # noqa: E731
        return len(r) >= 5 and bool(np.all(on(old) | on(new))) and bool(np.all(on(new)[-5:]))


def test_lvdt_reading_of_a_rotated_pose_zero_service_and_stroke(rclpy_context):
    axis = np.array([0.3, 1.0, 0.2])
    contact = np.array([0.05, -0.02, 0.01])
    name, prefix, args = isolated('lvdt')
    node = lvdt.Lvdt(context=rclpy_context, cli_args=args, parameter_overrides=[
        Parameter('axis', value=axis.tolist()), Parameter('contact_point', value=contact.tolist()),
        Parameter('noise_std', value=0.0), Parameter('resolution', value=0.0),
        Parameter('range_m', value=[-0.004, 0.004]), Parameter('zero_on_first_pose', value=False),
        Parameter('sample_rate_hz', value=500.0), Parameter('frame_id', value='lvdt_side')])
    probe = LvdtProbe(rclpy_context, prefix)
    ex = SingleThreadedExecutor(context=rclpy_context)
    ex.add_node(node)
    ex.add_node(probe.node)
    wait_connected(ex, probe.pose)
    # Nothing before the first pose: the LVDT has held back samples and published none (its own count: none can be
    # on its way to the probe).
    assert spin_until(ex, lambda: node.counters.waiting_samples > 0, PATIENCE_S)
    assert node.counters.published == 0 and probe.samples == []
    reply = call(ex, probe.node, f'/{name}/zero')
    assert not reply.success and 'no pose' in reply.message
    assert spin_until(ex, lambda: probe.epochs, PATIENCE_S)  # latched at start (a failed zero adds none: below)
    # Pose: translation plus a rotation of 10, 20 and -15 mrad (z, x, y): the contact point moves by u + (Q - I) p.
    u = np.array([0.001, 0.002, 0.003])
    q = euler_zxy_to_matrix(0.01, 0.02, -0.015)
    unit = axis / np.linalg.norm(axis)
    expected = float(unit @ (u + q @ contact - contact))
    t_pose = probe.publish(u, q)
    assert spin_until(ex, lambda: len(probe.readings_after(t_pose)) >= 20, PATIENCE_S)
    readings = probe.readings_after(t_pose)
    assert readings == pytest.approx(np.full(len(readings), expected), abs=1e-12)
    # Hand check, small angles: (Q - I) p ≈ ω × p with ω = (θ, ψ, φ) = (0.02, -0.015, 0.01) rad.
    small = float(unit @ (u + np.cross([0.02, -0.015, 0.01], contact)))
    assert small == pytest.approx(0.0030903, abs=1e-7)
    assert expected == pytest.approx(small, abs=3e-5)  # second-order terms: |ω|²·|p| ≈ 3e-5 m
    stamps = np.array([s for s, _, _ in probe.samples])
    assert np.all(stamps % (2 * MS) == 0) and np.median(np.diff(stamps)) == 2 * MS
    assert {f for _, f, _ in probe.samples} == {'lvdt_side'}
    # ~/zero at the current pose: the reading becomes 0; a further move reads the difference.
    reply = call(ex, probe.node, f'/{name}/zero')
    assert reply.success and 'zeroed' in reply.message
    # The estimator segments on it. One writer, in order: an epoch of the failed attempt would have come before it.
    assert spin_until(ex, lambda: 1.0 in probe.epochs, PATIENCE_S), probe.epochs
    assert probe.epochs == [0.0, 1.0], probe.epochs
    t_zero = probe.node.get_clock().now().nanoseconds
    assert spin_until(ex, lambda: len(probe.readings_after(t_zero)) >= 5, PATIENCE_S)
    assert probe.readings_after(t_zero) == pytest.approx(np.zeros(len(probe.readings_after(t_zero))), abs=1e-15)
    u2 = u + np.array([0.0, 0.0005, 0.0])
    t2 = probe.publish(u2, q)
    assert spin_until(ex, lambda: probe.moved(t2, 0.0, unit[1] * 0.0005), PATIENCE_S), probe.readings_after(t2)
    # Beyond the stroke: the reading saturates at the limit and /diagnostics warns.
    probe.diagnostics.clear()
    t3 = probe.publish(u + np.array([0.0, 0.01, 0.0]), q)
    assert spin_until(ex, lambda: any(s.level == b'\x01' and s.hardware_id == name for s in probe.diagnostics),
                      PATIENCE_S)
    warn = [s for s in probe.diagnostics if s.level == b'\x01'][0]
    assert 'out of range' in warn.message
    assert spin_until(ex, lambda: probe.moved(t3, unit[1] * 0.0005, 0.004), PATIENCE_S), probe.readings_after(t3)
    assert node.out_of_range > 0
    ex.shutdown()


def test_lvdt_zeroes_on_first_pose_with_noise_and_resolution(rclpy_context):
    name, prefix, args = isolated('lvdt')
    node = lvdt.Lvdt(context=rclpy_context, cli_args=args, parameter_overrides=[
        Parameter('noise_std', value=2e-7), Parameter('resolution', value=1e-8), Parameter('seed', value=5)])
    probe = LvdtProbe(rclpy_context, prefix)
    ex = SingleThreadedExecutor(context=rclpy_context)
    ex.add_node(node)
    ex.add_node(probe.node)
    wait_connected(ex, probe.pose)
    rest = np.array([0.0, 0.0, 2.4e-5])  # the loaded rest pose sags under the weight
    t0 = probe.publish(rest, np.eye(3))
    assert spin_until(ex, lambda: len(probe.readings_after(t0)) > 500, PATIENCE_S)  # enough for the statistics
    zero = probe.readings_after(t0)
    # Zeroed before its first reading: epoch 1 is the first it publishes (a 0 -> 1 could race the first readings).
    assert spin_until(ex, lambda: probe.epochs == [1.0], PATIENCE_S), probe.epochs
    assert np.allclose(zero / 1e-8, np.round(zero / 1e-8), atol=1e-6)  # on the 10 nm grid
    assert abs(zero.mean()) < 4 * 2e-7 / math.sqrt(len(zero))
    print(f'lvdt noise std measured {zero.std(ddof=1):.3e} m, configured 2e-7 m')
    assert zero.std(ddof=1) == pytest.approx(2e-7, rel=0.1)
    # 50 µm along y from the rest pose reads 50 µm.
    t1 = probe.publish(rest + [0.0, 5e-5, 0.0], np.eye(3))
    assert spin_until(ex, lambda: len(probe.readings_after(t1 + 50 * MS)) >= 300, PATIENCE_S)
    moved = probe.readings_after(t1 + 50 * MS)  # (samples published before the pose arrived read the old one)
    assert moved.mean() == pytest.approx(5e-5, abs=4 * 2e-7 / math.sqrt(len(moved)) + 1e-9)
    bad = node.set_parameters([Parameter('axis', value=[0.0, 0.0, 0.0])])[0]
    assert not bad.successful and 'axis' in bad.reason and 'non-zero' in bad.reason
    assert list(node.get_parameter('axis').value) == [0.0, 1.0, 0.0]
    ex.shutdown()


@pytest.mark.parametrize('module, cls, section', [(load_cell, load_cell.LoadCell, 'load_cell'),
                                                  (lvdt, lvdt.Lvdt, 'lvdt')])
def test_sensors_yaml_sets_every_parameter_with_its_declared_type(rclpy_context, module, cls, section):
    path = Path(__file__).resolve().parents[2] / 'config' / 'sensors.yaml'
    values = load_params(path, section)
    assert set(values) == {spec.name for spec in module.PARAMS}
    node = cls(context=rclpy_context, cli_args=['--ros-args', '--params-file', str(path)])
    for name, value in values.items():
        got = node.get_parameter(name).value
        assert (list(got) if isinstance(value, list) else got) == value, name
    node.destroy_node()


def test_grid_timer_ticks_fall_on_multiples_of_the_period(rclpy_context):
    """Sensor timers tick on the clock grid k·period, so two sensors at one rate deliver their buffers together.

    Not a timing bound: each call's *due* time (its clock's now plus the time until the next call, which rcl keeps
    on the timer's schedule whatever the dispatch delay) is checked against the grid; a free-running timer created
    half a period off would be due ~10 ms off. The median over the calls ignores a call preempted between the two
    reads.
    """
    from crane_stiffness.rosnode.sensor_timing import ALIGN_TOLERANCE_NS, create_grid_timer, grid_phase_ns
    from crane_stiffness.rosnode.run import make_executor
    node = Node(f'grid_{os.getpid()}_{next(_ids)}', context=rclpy_context)
    period_ns = 20 * MS
    phases: list[int] = []
    # Created half a period after a grid instant: a timer that kept its creation phase would tick ~10 ms off.
    time.sleep(((period_ns // 2 - time.time_ns() % period_ns) % period_ns) * 1e-9)
    timer = create_grid_timer(node, period_ns * 1e-9,
                              lambda: phases.append(grid_phase_ns(timer, node.get_clock(), period_ns)))
    ex = make_executor('events', rclpy_context)
    ex.add_node(node)
    end = time.monotonic() + PATIENCE_S
    while len(phases) < 75 and time.monotonic() < end:  # 1.5 s of calls (longer when the process is starved)
        ex.spin_once(timeout_sec=0.05)
    ex.remove_node(node)
    node.destroy_node()
    median = float(np.median(phases))
    print(f'grid timer: {len(phases)} calls, each due {median / MS:.3f} ms (median) from the grid, of a '
          f'{period_ns / MS:.0f} ms period')
    assert len(phases) >= 75  # (the starved process skips calls; rcl keeps the schedule)
    assert median <= 2 * ALIGN_TOLERANCE_NS
