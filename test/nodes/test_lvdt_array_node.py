"""The lvdt_array node: the grouping rule alone (pure), then the node in-process with real rclpy and DDS on loopback:
its pose is LvdtArray.solve of the readings of one instant, put on the rest pose as the pose sensor's is read back
(crane_stiffness.full6.deflection); an instant missing a reading is never published; a degenerate arrangement is
refused at start naming it; a bad change is refused with the reason, the old set-up kept; the lab config's six
simulated LVDTs and the node agree, and the node reads their pose back. Values are asserted, never timings."""
from __future__ import annotations

import numpy as np
import pytest
from geometry_msgs.msg import PointStamped, PoseStamped, PoseWithCovarianceStamped
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter

from helpers import PATIENCE_S, REPO, isolated, spin_until, stamp_ns
from helpers.probe import ProbeNode
from crane_stiffness.contract import topics
from crane_stiffness.full6.deflection import pose_deflection
from crane_stiffness.full6.lvdt_array import LvdtArray, lab_arrangement
from crane_stiffness.model.rotation import quaternion_to_matrix, rotvec_to_quaternion
from crane_stiffness.nodes import lvdt_array
from crane_stiffness.nodes.lvdt_array import LvdtArrayCounters, StampGroups
from crane_stiffness.params.files import load_params
from crane_stiffness.rosnode.qos import RELIABLE_QOS, SENSOR_QOS
from crane_stiffness.serde.stamps import split_ns
from crane_stiffness.sim.sensors import LVDT_PARAMS, lvdt_from_params

MS = 1_000_000  # ns
CONFIG = REPO / 'config' / 'lvdt_array_lab.yaml'


# --- the grouping rule (pure) ---

def _groups(n: int = 3, tolerance_ns: int = 0, wait_ns: int = 100 * MS) -> StampGroups:
    return StampGroups(n, tolerance_ns, wait_ns, LvdtArrayCounters())


def test_a_group_is_complete_with_one_reading_of_every_sensor_at_one_stamp():
    g = _groups()
    assert g.add(0, 10 * MS, 1.0) is None and g.add(2, 10 * MS, 3.0) is None
    assert g.add(1, 14 * MS, 9.0) is None  # another instant
    assert g.add(1, 10 * MS, 2.0) == (10 * MS, [1.0, 2.0, 3.0])
    assert g.add(0, 14 * MS, 7.0) is None and g.add(2, 14 * MS, 8.0) == (14 * MS, [7.0, 9.0, 8.0])
    c = g.counters
    assert (c.used, c.groups_complete, c.groups_incomplete, c.late_readings, c.duplicate_readings) == (6, 2, 0, 0, 0)


def test_incomplete_groups_are_dropped_never_returned():
    g = _groups()
    for i in (0, 1):  # instant 1: sensor 2 lost
        assert g.add(i, 1 * MS, 0.1) is None
    for i in (0, 1):
        assert g.add(i, 2 * MS, 0.2) is None
    assert g.add(2, 2 * MS, 0.2) == (2 * MS, [0.2] * 3)  # a later instant complete: instant 1 is given up
    assert g.counters.groups_incomplete == 1 and not g.open
    assert g.add(2, 1 * MS, 0.1) is None and g.counters.late_readings == 1  # the lost one, late: dropped
    assert g.add(0, 2 * MS, 0.3) is None and g.counters.late_readings == 2  # the done instant again: late
    # A sensor gone silent: its instants go once a reading stamped max_wait later arrives.
    for k in range(3, 10):
        g.add(0, k * MS, 0.0)
        g.add(1, k * MS, 0.0)
    assert len(g.open) == 7
    g.add(0, 104 * MS, 0.0)
    assert sorted(g.open) == [4 * MS, 5 * MS, 6 * MS, 7 * MS, 8 * MS, 9 * MS, 104 * MS]
    assert g.counters.groups_incomplete == 2 and g.counters.groups_complete == 1


def test_duplicates_are_dropped_and_a_tolerance_groups_nearby_stamps():
    g = _groups(tolerance_ns=100_000)
    assert g.add(0, 10 * MS, 1.0) is None
    assert g.add(0, 10 * MS + 50_000, 5.0) is None and g.counters.duplicate_readings == 1
    assert g.add(1, 10 * MS - 80_000, 2.0) is None
    assert g.add(2, 10 * MS + 200_000, 3.0) is None  # beyond the tolerance: an instant of its own
    stamp, readings = g.add(2, 10 * MS + 60_000, 3.5)
    assert readings == [1.0, 2.0, 3.5] and stamp == 10 * MS + round((-80_000 + 60_000) / 3)


# --- the node ---

def _node(ctx, **settings):
    """The node under a test's own names: the six reading topics and both outputs under its prefix."""
    name, prefix, args = isolated('lvdt_array')
    args = args + ['-r', f'{topics.POSE_SENSOR_POSE}:={prefix}{topics.POSE_SENSOR_POSE}',
                   '-r', f'{topics.LVDT_ARRAY_POSE}:={prefix}{topics.LVDT_ARRAY_POSE}']
    names = [f'{prefix}/lvdt_{i}/displacement' for i in range(1, 7)]
    overrides = [Parameter('topics', value=names)] + [Parameter(k, value=v) for k, v in settings.items()]
    return lvdt_array.LvdtArrayNode(context=ctx, cli_args=args, parameter_overrides=overrides), prefix, names


def _reading(t_ns: int, x: float) -> PointStamped:
    msg = PointStamped()
    msg.header.stamp.sec, msg.header.stamp.nanosec = split_ns(t_ns)
    msg.header.frame_id = 'lvdt'
    msg.point.x = float(x)
    return msg


def _pose(msg) -> tuple[int, str, np.ndarray, np.ndarray]:
    p, o = msg.pose.position, msg.pose.orientation
    return stamp_ns(msg.header.stamp), msg.header.frame_id, np.array([p.x, p.y, p.z]), np.array([o.x, o.y, o.z, o.w])


def test_the_pose_is_the_solution_of_each_complete_instant_and_an_incomplete_one_is_not_published(rclpy_context):
    """Three instants; the second misses LVDT 6. The node publishes the first and the third, each the pose the rest
    pose plus LvdtArray.solve of its readings gives (read back as stiffness6_estimator does), with the solution's
    covariance; the second never."""
    rest_q = rotvec_to_quaternion(np.array([0.01, -0.02, 0.005]))
    rest_u = np.array([1e-3, -2e-3, 0.48])
    node, prefix, names = _node(rclpy_context, rest_position=rest_u.tolist(), rest_orientation=rest_q.tolist(),
                                frame_id='mocap')
    array = lab_arrangement(rest_rotation=quaternion_to_matrix(rest_q))
    rng = np.random.default_rng(3)
    true = np.array([[1e-4, -2e-4, 3e-5, 1e-3, -5e-4, 2e-4], [0.0] * 6, [-3e-4, 1e-4, 2e-4, -2e-3, 1e-3, 8e-4]])
    readings = array.readings(true) + rng.normal(0.0, 2e-7, (3, 6))  # noisy: the residuals are not zero
    t0 = 5_000_000 * MS
    stamps = [t0, t0 + 4 * MS, t0 + 8 * MS]

    probe = ProbeNode(rclpy_context, prefix, name=f'probe_{node.get_name()}')
    poses = probe.record(topics.POSE_SENSOR_POSE, PoseStamped, SENSOR_QOS, _pose)
    covs = probe.record(topics.LVDT_ARRAY_POSE, PoseWithCovarianceStamped, SENSOR_QOS,
                        lambda m: (stamp_ns(m.header.stamp), np.array(m.pose.covariance).reshape(6, 6)))
    pubs = [probe.node.create_publisher(PointStamped, topic, RELIABLE_QOS) for topic in names]
    ex = SingleThreadedExecutor(context=rclpy_context)
    ex.add_node(node)
    ex.add_node(probe.node)
    assert spin_until(ex, lambda: all(p.get_subscription_count() >= 1 for p in pubs)
                      and node.pub.get_subscription_count() >= 1 and node.pub_cov.get_subscription_count() >= 1,
                      PATIENCE_S)
    for k, t in enumerate(stamps):
        for i, pub in enumerate(pubs):
            if not (k == 1 and i == 5):
                pub.publish(_reading(t, readings[k, i]))
    # The machine's speed decides when, never what: wait for the last instant's pose.
    assert spin_until(ex, lambda: len(poses) >= 2 and len(covs) >= 2, PATIENCE_S), (len(poses), node.counters)
    ex.shutdown()

    assert [p[0] for p in poses] == [stamps[0], stamps[2]] and [c[0] for c in covs] == [stamps[0], stamps[2]]
    assert {p[1] for p in poses} == {'mocap'}
    c = node.counters
    assert (c.received, c.used, c.groups_complete, c.groups_incomplete, c.published) == (17, 17, 2, 1, 2)
    for (_, _, u, q), (_, cov), k in zip(poses, covs, (0, 2)):
        expected = array.solve(readings[k])
        d = pose_deflection(u, quaternion_to_matrix(q), rest_u, quaternion_to_matrix(rest_q))
        np.testing.assert_allclose(d, expected.deflection, rtol=0.0, atol=1e-13)
        # (a batch's Gauss-Newton may take a step more than one instant alone: equal to rounding of the largest entry)
        np.testing.assert_allclose(cov, expected.covariance, rtol=0.0, atol=1e-12 * np.abs(expected.covariance).max())
        assert np.linalg.norm(q) == pytest.approx(1.0, abs=1e-15)
        # ... and the solution is the true deflection to within a few standard errors
        assert np.all(np.abs(expected.deflection - true[k]) < 5.0 * expected.stderr)
    node.destroy_node()
    probe.node.destroy_node()


def test_a_degenerate_arrangement_is_refused_at_start_naming_it(rclpy_context):
    vertical = [0.0, 0.0, 1.0] * 6  # six vertical LVDTs: u_x, u_y, θ_z unseen
    with pytest.raises(ValueError, match="LVDT arrangement 'all vertical': sees only 3 of the 6") as info:
        _node(rclpy_context, directions=vertical, arrangement='all vertical')
    assert 'ux; uy; thz·L' in str(info.value)
    five = lab_arrangement()
    with pytest.raises(ValueError, match="LVDT arrangement 'five': 5 LVDTs cannot determine"):
        name, prefix, args = isolated('lvdt_array')
        lvdt_array.LvdtArrayNode(context=rclpy_context, cli_args=args, parameter_overrides=[
            Parameter('topics', value=[f'{prefix}/l{i}' for i in range(5)]),
            Parameter('contact_points', value=five.contact_points[:5].ravel().tolist()),
            Parameter('directions', value=five.directions[:5].ravel().tolist()),
            Parameter('arrangement', value='five')])
    # Seen, but badly: the vertical LVDT at F moved to 1 % of its distance from the line D-E, the three vertical ones
    # nearly on one line -> the tilt about it is seen 169 times less well than the best seen motion.
    points = lab_arrangement().contact_points
    middle = (points[3] + points[4]) / 2
    points[5] = middle + 0.01 * (points[5] - middle)
    with pytest.raises(ValueError, match="'nearly in line': condition number 169.2 exceeds 100: the motion uz"):
        _node(rclpy_context, contact_points=points.ravel().tolist(), arrangement='nearly in line')
    node, _, _ = _node(rclpy_context, contact_points=points.ravel().tolist(), max_condition=200.0)  # if accepted
    assert node.array.condition_number == pytest.approx(169.2, abs=0.05)
    node.destroy_node()


@pytest.mark.ros  # main() starts rclpy and a node in this process
def test_main_exits_2_naming_a_degenerate_arrangement(capsys):
    assert lvdt_array.main(['--ros-args', '-p', 'directions:=' + str([0.0, 0.0, 1.0] * 6),
                            '-p', 'arrangement:=all_vertical']) == 2
    err = capsys.readouterr().err
    assert "cannot start" in err and "LVDT arrangement 'all_vertical'" in err and 'Traceback' not in err


def test_bad_changes_are_refused_with_the_reason_and_the_old_set_up_kept(rclpy_context):
    node, _, names = _node(rclpy_context)
    array = node.array
    for param, words in [
            (Parameter('directions', value=[0.0, 0.0, 1.0] * 6), ("LVDT arrangement 'lab: tangential and vertical "
                                                                  "at D, E, F'", 'sees only 3')),
            (Parameter('contact_points', value=[0.0] * 17), ('contact_points', '3 numbers per LVDT: 18')),
            (Parameter('noise_std', value=[2e-7, 3e-7]), ('noise_std', 'one number or 6')),
            (Parameter('noise_std', value=[0.0]), ('noise_std', '> 0')),
            (Parameter('rest_orientation', value=[0.0, 0.0, 0.0, 0.0]), ('rest_orientation', 'not all zero')),
            (Parameter('rest_position', value=[0.0, float('nan'), 0.0]), ('rest_position', 'finite')),
            (Parameter('topics', value=names[:5]), ('topics', 'read at start only')),
            (Parameter('frame_id', value=''), ('frame_id', 'non-empty')),
            (Parameter('max_condition', value=0.5), ('max_condition',)),
            (Parameter('stamp_tolerance_s', value=-1.0), ('stamp_tolerance_s',)),
            (Parameter('publish_rate_hz', value=0.0), ('publish_rate_hz',))]:
        result = node.set_parameters([param])[0]
        assert not result.successful and all(w in result.reason for w in words), (param.name, result.reason)
    assert node.array is array and list(node.get_parameter('directions').value) == array.directions.ravel().tolist()
    assert list(node.get_parameter('topics').value) == names
    # A good change is taken: another arrangement (the vertical LVDTs moved inward), a new solver.
    points = array.contact_points
    points[3:] *= 0.5
    assert node.set_parameters([Parameter('contact_points', value=points.ravel().tolist())])[0].successful
    assert node.array is not array and np.allclose(node.array.contact_points, points)
    node.destroy_node()


# --- the lab config: six simulated LVDTs and the node ---

def test_the_lab_config_sets_six_lvdts_on_the_lines_the_node_solves_with(rclpy_context):
    values = load_params(CONFIG, 'lvdt_array')
    assert set(values) == {spec.name for spec in lvdt_array.PARAMS}
    n = len(values['topics'])
    points, directions = np.reshape(values['contact_points'], (n, 3)), np.reshape(values['directions'], (n, 3))
    array = LvdtArray(points, directions, values['noise_std'][0], name=values['arrangement'])
    lab = lab_arrangement()
    np.testing.assert_allclose(array.contact_points, lab.contact_points, rtol=0.0, atol=1e-6)
    np.testing.assert_allclose(array.directions, lab.directions, rtol=0.0, atol=1e-7)
    assert array.condition_number == pytest.approx(np.sqrt(2.0), rel=1e-5)
    for i, topic in enumerate(values['topics']):
        lvdt = load_params(CONFIG, f'lvdt_{i + 1}')
        assert topic == f'/lvdt_{i + 1}/displacement'
        model = lvdt_from_params({spec.name: spec.default for spec in LVDT_PARAMS} | lvdt)
        np.testing.assert_allclose(model.axis, array.directions[i], rtol=0.0, atol=1e-15)
        assert lvdt['contact_point'] == points[i].tolist() and lvdt['noise_std'] == values['noise_std'][0]
    node = lvdt_array.LvdtArrayNode(context=rclpy_context, cli_args=['--ros-args', '--params-file', str(CONFIG)])
    for name, value in values.items():
        got = node.get_parameter(name).value
        assert (list(got) if isinstance(value, list) else got) == value, name
    node.destroy_node()


def test_six_simulated_lvdts_of_the_lab_config_give_the_pose_back(rclpy_context):
    """Six lvdt nodes (noise and quantization off) started from config/lvdt_array_lab.yaml under their own names and
    topics, the platform at rest then deflected: the node's poses, read back as deflections from the first, are the
    rest and then the true deflection, to rounding."""
    from crane_stiffness.model.rotation import quaternion_multiply
    from crane_stiffness.nodes.lvdt import Lvdt
    node, prefix, names = _node(rclpy_context, **{k: v for k, v in load_params(CONFIG, 'lvdt_array').items()
                                                  if k != 'topics'})
    exact = [Parameter('noise_std', value=0.0), Parameter('resolution', value=0.0),
             Parameter('state_wait_s', value=10.0)]  # each instant waits for the pose at it: any machine speed
    lvdts = []
    for i, topic in enumerate(names):
        args = ['--ros-args', '-r', f'__node:={node.get_name()}_lvdt_{i + 1}', '-r', f'{topics.PLATFORM_POSE}:='
                f'{prefix}{topics.PLATFORM_POSE}', '-r', f'{topics.LVDT_DISPLACEMENT}:={topic}', '-r',
                f'{topics.LVDT_ZERO}:={prefix}/lvdt_{i + 1}/zero', '-r', f'{topics.DIAGNOSTICS}:={prefix}/diagnostics']
        overrides = [Parameter(k, value=v) for k, v in load_params(CONFIG, f'lvdt_{i + 1}').items()]
        lvdts.append(Lvdt(context=rclpy_context, cli_args=args, parameter_overrides=overrides + exact))
    probe = ProbeNode(rclpy_context, prefix, name=f'probe_{node.get_name()}')
    poses = probe.record(topics.POSE_SENSOR_POSE, PoseStamped, SENSOR_QOS, _pose)
    platform = probe.publisher(topics.PLATFORM_POSE, PoseStamped, RELIABLE_QOS)
    ex = SingleThreadedExecutor(context=rclpy_context)
    for n in (node, probe.node, *lvdts):
        ex.add_node(n)
    assert spin_until(ex, lambda: platform.get_subscription_count() >= 6 and node.pub.get_subscription_count() >= 1
                      and all(n.pub.get_subscription_count() >= 1 for n in lvdts), PATIENCE_S)
    rest_u, rest_q = np.array([0.0, 0.0, 2.4e-5]), np.array([0.0, 0.0, 0.0, 1.0])
    d = np.array([2e-4, -1e-4, 3e-4, 1.5e-3, -1e-3, 5e-4])
    moved_u, moved_q = rest_u + d[:3], quaternion_multiply(rotvec_to_quaternion(d[3:]), rest_q)
    clock = probe.node.get_clock()
    current = [(rest_u, rest_q)]

    def send() -> None:  # the model's pose, again and again: each LVDT instant waits for the pose at it
        msg = PoseStamped()
        msg.header.stamp = clock.now().to_msg()
        msg.header.frame_id = 'crane_base'
        u, q = current[0]
        msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = (float(v) for v in u)
        o = msg.pose.orientation
        o.x, o.y, o.z, o.w = (float(v) for v in q)
        platform.publish(msg)
    timer = probe.node.create_timer(0.02, send)
    assert spin_until(ex, lambda: len(poses) >= 20, PATIENCE_S), node.counters
    current[0] = (moved_u, moved_q)
    moved_from = clock.now().nanoseconds

    def deflections() -> np.ndarray:
        first = poses[0]
        return np.array([pose_deflection(u, quaternion_to_matrix(q), first[2], quaternion_to_matrix(first[3]))
                         for _, _, u, q in poses])
    assert spin_until(ex, lambda: sum(p[0] > moved_from + 100 * MS for p in poses) >= 20, PATIENCE_S), node.counters
    probe.node.destroy_timer(timer)
    ex.shutdown()
    got = deflections()
    at_rest = np.all(np.abs(got) < 1e-12, axis=1)
    moved = np.all(np.abs(got - d) < 1e-12, axis=1)
    print(f'lvdt_array from six lvdt nodes: {len(got)} poses, {at_rest.sum()} at rest, {moved.sum()} deflected, '
          f'counters {node.counters}, LVDT samples skipped {[n.clock.skipped for n in lvdts]}')
    # Never a mixture of two poses' readings. A busy machine may lose a reading (best-effort streams, or an LVDT
    # skipping a stalled backlog): that instant is dropped, not published, and the others are still exact.
    assert np.all(at_rest | moved), got[~(at_rest | moved)]
    assert at_rest[0] and moved[-1]
    c = node.counters
    assert c.groups_complete == c.published + len(node.done) and c.received == c.used
    for n in (node, probe.node, *lvdts):
        n.destroy_node()

