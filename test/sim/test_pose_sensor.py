"""The simulated pose sensor: the pure model (noise, bias, the seeded stream) and the pose_sensor node in-process with
real rclpy and DDS on loopback: on simulated time beside the real sim_clock, every sample on the grid and exactly the
pose in force at its stamp plus the seeded noise, nothing lost; on wall-clock time no sample out before its latency;
parameters refused naming the bad value."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from geometry_msgs.msg import PoseStamped
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter

from helpers import PATIENCE_S, isolated, spin_until, stamp_ns
from helpers.probe import ProbeNode
from crane_stiffness.contract import topics
from crane_stiffness.full6.deflection import pose_deflection, rotation_vector
from crane_stiffness.model.rotation import (euler_zxy_to_matrix, matrix_to_quaternion, quaternion_multiply,
                                            quaternion_to_matrix, rotvec_to_matrix, rotvec_to_quaternion)
from crane_stiffness.nodes import pose_sensor
from crane_stiffness.nodes.sim_clock import SimClock
from crane_stiffness.params.files import load_params
from crane_stiffness.rosnode.qos import RELIABLE_QOS, SENSOR_QOS, SIM_STREAM_QOS
from crane_stiffness.rosnode.sim_time import SimTimeParticipant, drain
from crane_stiffness.serde.stamps import split_ns
from crane_stiffness.sim import ParameterError, PoseSensorModel
from crane_stiffness.sim.pose_sensor import POSE_SENSOR_PARAMS, pose_sensor_from_params

MS = 1_000_000  # ns
REST_Q = matrix_to_quaternion(euler_zxy_to_matrix(0.02, -0.01, 0.03))  # a platform turned a little at rest


def _rotations(quaternions: np.ndarray) -> np.ndarray:
    return np.stack([quaternion_to_matrix(q) for q in quaternions])


# --- the quaternion helpers the model is built on ---

def test_quaternion_helpers_agree_with_the_rotation_matrices():
    rng = np.random.default_rng(0)
    for w in [np.zeros(3), np.array([1e-9, 0.0, -2e-9]), np.array([3e-5, -1e-4, 2e-5]), *rng.normal(0, 1.0, (5, 3))]:
        q = rotvec_to_quaternion(w)
        assert np.linalg.norm(q) == pytest.approx(1.0, abs=1e-15)
        np.testing.assert_allclose(quaternion_to_matrix(q), rotvec_to_matrix(w), atol=1e-15)
    assert rotvec_to_quaternion(np.zeros(3)).tolist() == [0.0, 0.0, 0.0, 1.0]  # exactly: no noise, no change
    a, b = rotvec_to_quaternion(rng.normal(0, 1, (4, 3))), rotvec_to_quaternion(rng.normal(0, 1, (4, 3)))
    ab = quaternion_multiply(a, b)
    np.testing.assert_allclose(_rotations(ab), _rotations(a) @ _rotations(b), atol=1e-14)


# --- the pure model ---

def test_zero_noise_and_bias_returns_the_true_pose_exactly():
    model = PoseSensorModel(position_noise_std=0.0, angle_noise_std=0.0, rng=1)
    u = np.array([1e-4, -2e-4, 3.5e-5])
    position, orientation = model.measure(u, REST_Q)
    assert position.tolist() == u.tolist() and orientation.tolist() == REST_Q.tolist()
    batch_u = np.tile(u, (5, 1)) * np.arange(5)[:, None]
    position, orientation = model.measure(batch_u, np.tile(REST_Q, (5, 1)))
    assert (position == batch_u).all() and (orientation == REST_Q).all()
    # A quaternion that is not unit (a tracker's message may hold one) comes out normalised: the same rotation.
    _, unit = model.measure(u, 3.0 * REST_Q)
    np.testing.assert_allclose(unit, REST_Q, atol=1e-16)


def test_noise_std_and_bias_measured_over_many_samples():
    n = 40_000
    position_bias, angle_bias = np.array([5e-6, -3e-6, 1e-5]), np.array([2e-4, -1e-4, 5e-5])
    model = PoseSensorModel(position_noise_std=2e-6, angle_noise_std=20e-6, position_bias=position_bias,
                            angle_bias=angle_bias, rng=2024)
    u = np.tile([1e-3, 2e-3, 2.4e-5], (n, 1))
    q = np.tile(REST_Q, (n, 1))
    position, orientation = model.measure(u, q)
    assert np.allclose(np.linalg.norm(orientation, axis=1), 1.0, rtol=0.0, atol=4.5e-16)  # unit to 2 ulp
    # The deflection the 6x6 fit reads from a pose (full6.deflection): translation and fixed-frame rotation vector.
    d = pose_deflection(position, _rotations(orientation), u[0], quaternion_to_matrix(REST_Q))
    # Bounds of 5 standard errors of the estimates (relative SE of a std: 1 / sqrt(2 (n - 1))): any seed passes
    # with probability 1 - 1e-6 per number.
    std = d.std(axis=0, ddof=1)
    expected_std = np.array([2e-6] * 3 + [20e-6] * 3)
    print('pose sensor std measured', std.tolist(), 'configured', expected_std.tolist())
    assert np.all(np.abs(std / expected_std - 1.0) < 5.0 / math.sqrt(2 * (n - 1)))
    mean = d.mean(axis=0)
    print('pose sensor bias measured', mean.tolist())
    assert np.all(np.abs(mean - np.concatenate([position_bias, angle_bias])) < 5.0 * expected_std / math.sqrt(n))
    # The structure, sample for sample: the seed's six standard normals per sample, scaled, plus the bias.
    draws = np.random.default_rng(2024).standard_normal((n, 6))
    np.testing.assert_allclose(d[:, :3], position_bias + 2e-6 * draws[:, :3], rtol=0.0, atol=1e-18)
    np.testing.assert_allclose(d[:, 3:], angle_bias + 20e-6 * draws[:, 3:], rtol=0.0, atol=1e-15)


def test_same_seed_same_stream_however_batched():
    u = np.random.default_rng(5).normal(0.0, 1e-4, (30, 3))
    q = rotvec_to_quaternion(np.random.default_rng(6).normal(0.0, 1e-2, (30, 3)))
    whole = PoseSensorModel(rng=11).measure(u, q)
    params = {spec.name: spec.default for spec in POSE_SENSOR_PARAMS} | {'seed': 11}
    parts = pose_sensor_from_params(params)
    pieces = [parts.measure(u[i:j], q[i:j]) for i, j in ((0, 1), (1, 8), (8, 9), (9, 30))]
    singles = np.concatenate([p[0] for p in pieces]), np.concatenate([p[1] for p in pieces])
    assert (whole[0] == singles[0]).all() and (whole[1] == singles[1]).all()
    other = PoseSensorModel(rng=12).measure(u, q)
    assert not (other[0] == whole[0]).any()
    # A new set-up of the sensor (another parameter changed, the node builds a new model) continues the stream.
    first, renewed = PoseSensorModel(rng=11), PoseSensorModel(rng=11)
    first.measure(u[:9], q[:9])
    renewed.continue_noise_of(first)
    rest = renewed.measure(u[9:], q[9:])
    assert (rest[0] == whole[0][9:]).all() and (rest[1] == whole[1][9:]).all()
    # seed -1: random, a fresh stream each time
    random = pose_sensor_from_params(params | {'seed': -1}).measure(u, q)
    assert not (random[0] == whole[0]).any()


@pytest.mark.parametrize('field, value, rule', [
    ('position_noise_std', -1e-6, '>= 0'), ('angle_noise_std', float('nan'), 'finite'),
    ('position_bias', [0.0, 1.0], '3 numbers'), ('angle_bias', [0.0, float('inf'), 0.0], 'finite'),
    ('seed', 1.5, 'seed')])
def test_bad_model_parameters_are_refused_naming_them(field, value, rule):
    with pytest.raises(ParameterError, match=rule) as info:
        PoseSensorModel.from_params({field: value})
    assert info.value.field == field


def test_bad_poses_are_refused():
    model = PoseSensorModel(rng=0)
    with pytest.raises(ParameterError, match='one quaternion per position'):
        model.measure(np.zeros((2, 3)), np.tile(REST_Q, (3, 1)))
    with pytest.raises(ParameterError, match='non-zero quaternion'):
        model.measure(np.zeros(3), np.zeros(4))
    with pytest.raises(ParameterError, match=r'shape \(3,\)'):
        model.measure(np.zeros(2), REST_Q)


# --- the node (rclpy, DDS) ---

def _isolated(base: str) -> tuple[str, str, list[str]]:
    """helpers.isolated, the pose sensor's topic under the test's prefix too."""
    name, prefix, args = isolated(base)
    return name, prefix, args + ['-r', f'{topics.POSE_SENSOR_POSE}:={prefix}{topics.POSE_SENSOR_POSE}']


def _pose_msg(t_ns: int, u, q) -> PoseStamped:
    msg = PoseStamped()
    msg.header.stamp.sec, msg.header.stamp.nanosec = split_ns(int(t_ns))
    msg.header.frame_id = 'crane_base'
    p, o = msg.pose.position, msg.pose.orientation
    p.x, p.y, p.z = (float(v) for v in u)
    o.x, o.y, o.z, o.w = (float(v) for v in q)
    return msg


def _sample(msg: PoseStamped) -> tuple[int, str, list[float], list[float]]:
    p, o = msg.pose.position, msg.pose.orientation
    return stamp_ns(msg.header.stamp), msg.header.frame_id, [p.x, p.y, p.z], [o.x, o.y, o.z, o.w]


START = 1000 * 1_000_000_000  # sim_clock's start_time_s
END = START + 2000 * MS


def _schedule() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The crane model's poses for the simulated-time test: (stamps [ns], positions (n, 3) [m], quaternions (n, 4)):
    the first at time's start, then irregular ones, some exactly on the sensor's 4 ms grid, some 1 ns before or after
    an instant of it."""
    rng = np.random.default_rng(42)
    stamps = {START, START + 4 * MS, START + 10 * MS + 500_000, START + 12 * MS - 1, START + 16 * MS + 1,
              START + 400 * MS, START + 1996 * MS}
    stamps |= set((START + rng.integers(1, 2000 * MS, 60)).tolist())
    t = np.array(sorted(stamps), dtype=np.int64)
    u = rng.normal(0.0, 1e-4, (len(t), 3))
    q = quaternion_multiply(rotvec_to_quaternion(rng.normal(0.0, 1e-3, (len(t), 3))), REST_Q)
    return t, u, q


def test_on_simulated_time_every_sample_is_the_pose_in_force_plus_the_seeded_noise(rclpy_context):
    """The real sim_clock, a stand-in for crane_model (stage 1) playing a known pose sequence, the node (stage 2) and a
    consumer (stage 3), each in the lockstep: the stream is every instant of the 4 ms grid up to the run's end, each
    the pose in force at its stamp plus the noise the model with the same seed draws, value for value; latency_s
    changes nothing there."""
    sim = [Parameter('use_sim_time', value=True)]
    name, prefix, args = _isolated('pose_sensor')
    settings = {'seed': 7, 'position_bias': [1e-6, 0.0, -2e-6], 'angle_bias': [0.0, 3e-5, 0.0], 'latency_s': 0.05,
                'frame_id': 'mocap'}
    node = pose_sensor.PoseSensor(context=rclpy_context, cli_args=args, parameter_overrides=sim + [
        Parameter(k, value=v) for k, v in settings.items()])
    stamps, positions, quaternions = _schedule()

    source = Node(f'{name}_model', context=rclpy_context, parameter_overrides=sim)
    pose_pub = source.create_publisher(PoseStamped, prefix + topics.PLATFORM_POSE, SIM_STREAM_QOS)
    played = [0]

    def play(t_ns: int) -> None:  # what crane_model does: the poses up to the watermark, then its progress
        while played[0] < len(stamps) and stamps[played[0]] <= t_ns:
            i = played[0]
            pose_pub.publish(_pose_msg(stamps[i], positions[i], quaternions[i]))
            played[0] += 1
        source_sim.report(t_ns, end_ns=END)
    source_sim = SimTimeParticipant(source, 1, play)
    source_sim.counted(pose_pub)

    sink = Node(f'{name}_sink', context=rclpy_context, parameter_overrides=sim)
    samples: list = []
    marks = [0]

    def take(msg) -> None:
        samples.append(_sample(msg))
        sink_sim.received(prefix + topics.POSE_SENSOR_POSE)
    sub = sink.create_subscription(PoseStamped, prefix + topics.POSE_SENSOR_POSE, take, SIM_STREAM_QOS)

    def consumed(t_ns: int) -> None:
        marks[0] = t_ns
        sink_sim.report(t_ns)
    sink_sim = SimTimeParticipant(sink, 3, consumed, drain=lambda: drain(sub, take),
                                  inputs=[prefix + topics.POSE_SENSOR_POSE])

    clock = SimClock(context=rclpy_context, cli_args=['--ros-args', '-r', f'__node:={name}_clock'],
                     parameter_overrides=[Parameter('participants', value=[source.get_name(), name, sink.get_name()]),
                                          Parameter('real_time_factor', value=0.0),
                                          Parameter('settle_s', value=0.2)])
    ex = SingleThreadedExecutor(context=rclpy_context)
    for n in (clock, source, node, sink):
        ex.add_node(n)
    # How long this takes is the machine's business: the timeout only ends a run that would never finish.
    assert spin_until(ex, lambda: marks[0] >= END, 600.0), (marks[0] - START, len(samples), clock.counters)
    ex.shutdown()
    print(f'pose_sensor on simulated time: {len(samples)} samples, {clock.counters["steps"]} clock steps')

    got_t = np.array([s[0] for s in samples], dtype=np.int64)
    # Every instant of the grid after time's start, up to the end, once: nothing lost, nothing early or late.
    np.testing.assert_array_equal(got_t, START + 4 * MS * np.arange(1, 501))
    assert {s[1] for s in samples} == {'mocap'}
    assert node.counters.published == 500 and node.counters.waiting_samples == 0
    assert node.counters.received == node.counters.used == len(stamps) and node.pose.late == 0
    assert node.clock.skipped == 0
    # The pose in force at each stamp (the last stamped at or before it), through the model with the same seed.
    in_force = np.searchsorted(stamps, got_t, side='right') - 1
    expected_u, expected_q = pose_sensor_from_params(
        {spec.name: spec.default for spec in POSE_SENSOR_PARAMS} | settings).measure(positions[in_force],
                                                                                     quaternions[in_force])
    got_u, got_q = np.array([s[2] for s in samples]), np.array([s[3] for s in samples])
    np.testing.assert_array_equal(got_u, expected_u)
    np.testing.assert_array_equal(got_q, expected_q)
    # Those are noisy readings of the pose in force, not of a neighbouring one: within 6 sigma plus the bias.
    d = pose_deflection(got_u, _rotations(got_q), np.zeros(3), np.eye(3)) - np.concatenate(
        [positions[in_force], [rotation_vector(quaternion_to_matrix(q)) for q in quaternions[in_force]]], axis=1)
    assert np.all(np.abs(d[:, :3] - settings['position_bias']) < 6 * 2e-6)
    assert np.all(np.abs(d[:, 3:] - settings['angle_bias']) < 6 * 20e-6 + 1e-9)
    assert np.all(d.std(axis=0) > 0.5 * np.array([2e-6] * 3 + [20e-6] * 3))  # the noise is there
    for n in (clock, source, node, sink):
        n.destroy_node()


def test_on_wall_clock_time_no_sample_goes_out_before_its_latency(rclpy_context):
    """latency_s: a sample stamped t is published at t + latency_s at the earliest (an invariant, whatever the load);
    its stamp stays on the grid and its value is the pose in force with the bias (noise off: exact)."""
    latency_ns = 30 * MS
    position_bias, angle_bias = [1e-3, -2e-3, 5e-4], [1e-3, 0.0, -2e-3]
    name, prefix, args = _isolated('pose_sensor')
    node = pose_sensor.PoseSensor(context=rclpy_context, cli_args=args, parameter_overrides=[
        Parameter('position_noise_std', value=0.0), Parameter('angle_noise_std', value=0.0),
        Parameter('position_bias', value=position_bias), Parameter('angle_bias', value=angle_bias),
        Parameter('latency_s', value=latency_ns * 1e-9), Parameter('publish_rate_hz', value=500.0)])
    probe = ProbeNode(rclpy_context, prefix, diagnostics_depth=10)
    clock = probe.node.get_clock()
    samples = probe.record(topics.POSE_SENSOR_POSE, PoseStamped, SENSOR_QOS,
                           lambda m: (*_sample(m), clock.now().nanoseconds))
    pose_pub = probe.publisher(topics.PLATFORM_POSE, PoseStamped, RELIABLE_QOS)
    ex = SingleThreadedExecutor(context=rclpy_context)
    ex.add_node(node)
    ex.add_node(probe.node)
    assert spin_until(ex, lambda: pose_pub.get_subscription_count() >= 1, PATIENCE_S)
    poses = [(np.array([0.0, 0.0, 2.4e-5]), REST_Q),
             (np.array([1e-4, 5e-5, 2.6e-5]), quaternion_multiply(rotvec_to_quaternion([1e-3, 0, 0]), REST_Q))]
    t1 = clock.now().nanoseconds
    pose_pub.publish(_pose_msg(t1, *poses[0]))
    assert spin_until(ex, lambda: sum(s[0] > t1 for s in samples) >= 50, PATIENCE_S)
    t2 = clock.now().nanoseconds
    pose_pub.publish(_pose_msg(t2, *poses[1]))
    assert spin_until(ex, lambda: sum(s[0] > t2 for s in samples) >= 50, PATIENCE_S)
    ex.shutdown()
    stamps = np.array([s[0] for s in samples], dtype=np.int64)
    arrivals = np.array([s[4] for s in samples], dtype=np.int64)
    assert np.all(stamps % (4 * MS) == 0) and np.all(np.diff(stamps) > 0)
    print(f'pose_sensor: stamp to arrival {np.min(arrivals - stamps) / MS:.2f} .. {np.max(arrivals - stamps) / MS:.2f}'
          f' ms with latency_s {latency_ns / MS:.0f} ms')
    assert np.all(arrivals - stamps >= latency_ns)
    assert node.delay_min_ns is not None and node.delay_min_ns >= latency_ns
    noiseless = PoseSensorModel(0.0, 0.0, position_bias, angle_bias)
    expected = [noiseless.measure(*pose) for pose in poses]
    for t, frame, u, q, _ in samples:
        assert frame == 'crane_base'
        # Before t2, the first pose; from t2 on the second, or the first where it was read before the second arrived.
        allowed = expected[:1] if t < t2 else expected
        assert any(u == e[0].tolist() and q == e[1].tolist() for e in allowed), (t - t2, u, q)
    assert samples[-1][2] == expected[1][0].tolist()
    # The bias as rotation matrices: R(measured) = exp([angle_bias]x) R(true).
    np.testing.assert_allclose(quaternion_to_matrix(expected[1][1]),
                               rotvec_to_matrix(np.array(angle_bias)) @ quaternion_to_matrix(poses[1][1]), atol=1e-15)
    assert node.counters.received == node.counters.used == 2
    node.destroy_node()


def test_bad_parameters_are_refused_naming_the_value_and_the_old_one_kept(rclpy_context):
    node = pose_sensor.PoseSensor(context=rclpy_context, cli_args=_isolated('pose_sensor')[2])
    for param, words in [(Parameter('angle_bias', value=[0.0, 0.0]), ('angle_bias', '3 numbers')),
                         (Parameter('position_bias', value=[0.0, float('nan'), 0.0]), ('position_bias', 'finite')),
                         (Parameter('sample_rate_hz', value=-5.0), ('sample_rate_hz = -5.0', '> 0')),
                         (Parameter('frame_id', value=''), ('frame_id', 'non-empty')),
                         (Parameter('position_noise_std', value=-1e-6), ('position_noise_std',)),
                         (Parameter('latency_s', value=10.0), ('latency_s',))]:
        result = node.set_parameters([param])[0]
        assert not result.successful and all(w in result.reason for w in words), (param.name, result.reason)
    assert list(node.get_parameter('angle_bias').value) == [0.0, 0.0, 0.0]
    assert node.get_parameter('sample_rate_hz').value == 250.0 and node.clock.period_ns == 4 * MS
    assert node.get_parameter('latency_s').value == 0.0 and node.latency.wait_ns == 0
    model = node.model
    assert node.set_parameters([Parameter('angle_noise_std', value=1e-5)])[0].successful
    assert node.model is not model and node.model.angle_noise_std == 1e-5
    assert node.model._rng is model._rng  # the same seed: the noise stream goes on
    node.destroy_node()
    with pytest.raises(ValueError, match='angle_noise_std = -1'):
        pose_sensor.PoseSensor(context=rclpy_context, cli_args=_isolated('pose_sensor')[2],
                       parameter_overrides=[Parameter('angle_noise_std', value=-1.0)])


@pytest.mark.ros  # main() starts rclpy and a node in this process
def test_main_exits_2_naming_a_bad_parameter(capsys):
    assert pose_sensor.main(['--ros-args', '-p', 'angle_bias:=[0.0]']) == 2
    assert 'angle_bias' in capsys.readouterr().err


def test_sensors_yaml_sets_every_parameter_with_its_declared_type(rclpy_context):
    path = Path(__file__).resolve().parents[2] / 'config' / 'sensors.yaml'
    values = load_params(path, 'pose_sensor')
    assert set(values) == {spec.name for spec in pose_sensor.PARAMS}
    node = pose_sensor.PoseSensor(context=rclpy_context, cli_args=['--ros-args', '--params-file', str(path)])
    for name, value in values.items():
        got = node.get_parameter(name).value
        assert (list(got) if isinstance(value, list) else got) == value, name
    node.destroy_node()

