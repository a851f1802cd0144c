"""stiffness6_estimator, the node: fed a six-axis session over real DDS (in-process, every message accounted), it
publishes the 6x6 K and C with intervals equal to the offline fit of the same samples, OK; a pose stream that
stops turns its status STALE, naming the stream, and nothing after it is fitted."""
from __future__ import annotations

import json
import time

import numpy as np
import pytest

from helpers import PATIENCE_S
from crane_stiffness.contract import stiffness6_layout
from crane_stiffness.full6.design import d_optimal_design
from crane_stiffness.full6.identify import identify
from crane_stiffness.full6.pairs import full6_pairs
from crane_stiffness.full6.program import design_program
from crane_stiffness.full6.reference import reference_at_rest
from crane_stiffness.model.geometry import lab_model
from crane_stiffness.model.rotation import matrix_to_quaternion, rotvec_to_matrix
from crane_stiffness.serde.stamps import stamp_seconds
from crane_stiffness.contract.status import STALE
from crane_stiffness.testing.synthetic_full6 import model_responses

pytestmark = pytest.mark.ros
LAB = lab_model(0.5, 50.0)
PEAKS = [2.8, 3.3, 24.0, 1.6, 1.4, 0.75]


def _streams(t0: float, seed: int = 2):
    """A short D-optimal program (12 steps held 1 s) played from ``t0`` [s]: commands at 100 Hz, the load cell at
    1 kHz (0.02 N, 0.002 N·m noise), the pose at 250 Hz (2 um, 20 urad noise): the model's deflection at the
    step in force (the platform settles at once)."""
    design = d_optimal_design(LAB, PEAKS, n_steps=12, hold_s=1.0, settle_s=0.3, baseline_s=0.5)
    program = design_program(design)
    truth = model_responses(LAB, program, 0.0)
    rng = np.random.default_rng(seed)
    tc = np.arange(0.0, program.duration_s, 0.01)
    wc = np.array([program.wrench_at(t).wrench for t in tc])
    tw = np.arange(0.0, program.duration_s, 0.001)
    step_of = np.clip(np.searchsorted([s.start_s for s in truth.steps], tw, side='right') - 1, 0, None)
    w = truth.wrenches[step_of] + rng.normal(0, [0.02] * 3 + [0.002] * 3, (tw.size, 6))
    tp = np.arange(0.0, program.duration_s, 0.004) + 0.0002
    k = np.clip(np.searchsorted([s.start_s for s in truth.steps], tp, side='right') - 1, 0, None)
    d = truth.deflection[k] + rng.normal(0, [2e-6] * 3 + [2e-5] * 3, (tp.size, 6))
    rest = np.array([0.0, 0.0, 0.0])
    position = rest + d[:, :3]
    quaternion = np.array([matrix_to_quaternion(rotvec_to_matrix(r)) for r in d[:, 3:]])
    return _as_stamped(t0 + tc), wc, _as_stamped(t0 + tw), w, _as_stamped(t0 + tp), position, quaternion, truth


def _as_stamped(t: np.ndarray) -> np.ndarray:
    """Times [s] as a header stamp carries them (whole ns) and the node reads them back."""
    ns = np.round(t * 1e9).astype(np.int64)
    return stamp_seconds(ns // 1_000_000_000, ns % 1_000_000_000)


def test_the_live_6x6_fit_equals_the_offline_one_and_a_stopped_pose_stream_is_stale(rclpy_context):
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import PoseStamped, WrenchStamped
    from rclpy.executors import SingleThreadedExecutor
    from std_msgs.msg import Float64MultiArray

    from crane_stiffness.contract import topics
    from crane_stiffness.nodes.stiffness6_estimator import Stiffness6EstimatorNode
    from crane_stiffness.rosnode.qos import KEPT_QOS, RELIABLE_QOS, SENSOR_QOS
    from crane_stiffness.serde.stamps import split_ns

    node = Stiffness6EstimatorNode(context=rclpy_context, parameter_overrides=[
        rclpy.parameter.Parameter('settle_s', value=0.3), rclpy.parameter.Parameter('publish_rate_hz', value=5.0)])
    feeder = rclpy.create_node('feeder', context=rclpy_context)
    got: dict[str, list] = {'k': [], 'status': []}
    feeder.create_subscription(Float64MultiArray, topics.STIFFNESS6, got['k'].append, KEPT_QOS)
    feeder.create_subscription(DiagnosticArray, topics.STIFFNESS6_STATUS, got['status'].append, KEPT_QOS)
    pub_c = feeder.create_publisher(WrenchStamped, topics.WRENCH_COMMAND, RELIABLE_QOS)
    pub_w = feeder.create_publisher(WrenchStamped, topics.LOAD_CELL_WRENCH, SENSOR_QOS)
    pub_p = feeder.create_publisher(PoseStamped, topics.POSE_SENSOR_POSE, SENSOR_QOS)
    executor = SingleThreadedExecutor(context=rclpy_context)
    executor.add_node(node)
    executor.add_node(feeder)
    try:
        deadline = time.monotonic() + PATIENCE_S
        while not all(pub.get_subscription_count() for pub in (pub_c, pub_w, pub_p)):
            assert time.monotonic() < deadline, 'the node never matched the feeder'
            executor.spin_once(timeout_sec=0.05)
        t0 = node.get_clock().now().nanoseconds * 1e-9
        tc, wc, tw, w, tp, position, quaternion, truth = _streams(t0)
        events = sorted([(t, 0, i) for i, t in enumerate(tc)] + [(t, 1, i) for i, t in enumerate(tw)]
                        + [(t, 2, i) for i, t in enumerate(tp)])

        def stamp(msg, t: float) -> None:
            msg.header.stamp.sec, msg.header.stamp.nanosec = split_ns(round(t * 1e9))

        sent = {'commands': 0, 'wrenches': 0, 'poses': 0}
        for n, (t, kind, i) in enumerate(events):
            if kind == 2:
                msg = PoseStamped()
                stamp(msg, t)
                p, q = msg.pose.position, msg.pose.orientation
                p.x, p.y, p.z = position[i]
                q.x, q.y, q.z, q.w = quaternion[i]
                pub_p.publish(msg)
                sent['poses'] += 1
            else:
                msg = WrenchStamped()
                stamp(msg, t)
                f, m = msg.wrench.force, msg.wrench.torque
                v = wc[i] if kind == 0 else w[i]
                f.x, f.y, f.z, m.x, m.y, m.z = v
                (pub_c if kind == 0 else pub_w).publish(msg)
                sent['commands' if kind == 0 else 'wrenches'] += 1
            if n % 200 == 199:  # the node takes what was sent before more is sent (the queues hold 1000)
                while any(node.counters[key] < sent[key] for key in sent):
                    executor.spin_once(timeout_sec=0.01)
        while any(node.counters[key] < sent[key] for key in sent):
            executor.spin_once(timeout_sec=0.01)
        assert {key: node.counters[key] for key in sent} == sent and node.counters['malformed'] == 0
        node._publish()
        executor.spin_once(timeout_sec=0.1)
        fit = node.fit
        # the same samples offline (arrival order = stamp order here)
        offline = full6_pairs(tc, wc, tw, tw, w, tp, tp, position, quaternion, settle_s=0.3)
        expected = identify(offline.wrench, offline.deflection, offline.step)
        assert fit is not None and fit.n == len(offline) == node.counters['pairs']
        np.testing.assert_allclose(fit.stiffness, expected.stiffness, rtol=1e-9)
        np.testing.assert_allclose(fit.stiffness_low, expected.stiffness_low, rtol=1e-9)
        assert fit.ok, fit.message
        tangent = reference_at_rest(LAB).tangent
        # (a 17 s program, a sixth of config/program_full6.yaml: its diagonal within 2 %, the full one's within 1 %)
        assert np.all(np.abs(np.diag(fit.stiffness) / np.diag(tangent) - 1) < 0.02)
        # what the node published: the fit, laid out quantity x row x column
        # (crane_stiffness.contract.stiffness6_layout)
        deadline = time.monotonic() + PATIENCE_S
        while not got['k'] or not np.allclose(stiffness6_layout.decode(got['k'][-1].data)[0], fit.stiffness,
                                              rtol=1e-12):
            assert time.monotonic() < deadline, 'no /stiffness6/stiffness with the fit'
            executor.spin_once(timeout_sec=0.05)
        message = got['k'][-1]
        assert stiffness6_layout.dims_of(message) == (('quantity', 3, 108), ('row', 6, 36), ('column', 6, 6))
        cube = stiffness6_layout.decode_message(message)
        np.testing.assert_array_equal(cube[1], fit.stiffness_low)
        np.testing.assert_array_equal(cube[2], fit.stiffness_high)
        # the pose sensor stops; the load cell and the program go on, stamped now: STALE naming the pose stream
        pairs_before, waiting = node.counters['pairs'], node.pairing.waiting
        last_pose = tp[-1]
        got['status'].clear()
        deadline = time.monotonic() + PATIENCE_S
        def pose_stale(s) -> bool:  # STALE for the pose stream alone (the load cell is fresh again)
            st = s.status[0]
            return st.level == bytes([STALE]) and topics.LOAD_CELL_WRENCH not in st.message

        while not any(pose_stale(s) for s in got['status']):
            assert time.monotonic() < deadline, ([s.status[0].message for s in got['status']][-3:], node.newest)
            now = node.get_clock().now().nanoseconds * 1e-9
            for pub, value in ((pub_c, wc[-1]), (pub_w, w[-1])):
                msg = WrenchStamped()
                stamp(msg, now)
                f, m = msg.wrench.force, msg.wrench.torque
                f.x, f.y, f.z, m.x, m.y, m.z = value
                pub.publish(msg)
            sent['commands'] += 1
            sent['wrenches'] += 1
            while any(node.counters[key] < sent[key] for key in sent):  # taken before more is sent
                executor.spin_once(timeout_sec=0.01)
            executor.spin_once(timeout_sec=0.02)  # the status timer
        first = next(s for s in got['status'] if pose_stale(s))
        stale, stale_at = first.status[0], first.header.stamp
        assert topics.POSE_SENSOR_POSE in stale.message
        assert stale_at.sec + stale_at.nanosec * 1e-9 - last_pose >= 0.5  # not before the rule (stale_after_s)
        # nothing after the pose stream stopped was paired: only the pairs that waited for a command after them
        assert pairs_before <= node.counters['pairs'] <= pairs_before + waiting
        values = {kv.key: kv.value for kv in stale.values}
        assert values['level'] == 'STALE' and json.loads(values['pairs']) <= pairs_before + waiting
    finally:
        executor.shutdown()
        feeder.destroy_node()
        node.destroy_node()


def test_a_design_that_cannot_determine_c_yet_is_waiting_while_the_program_runs():
    from crane_stiffness.nodes.stiffness6_estimator import shown_status
    from crane_stiffness.contract.status import ERROR, WAITING
    rng = np.random.default_rng(0)
    w = np.repeat(rng.normal(size=(3, 6)), 50, axis=0) + rng.normal(0, 0.01, (150, 6))
    fit = identify(w, w * 1e-5 + rng.normal(0, 1e-8, (150, 6)), np.repeat([0, 1, 2], 50))
    assert fit.level == ERROR and fit.message.startswith('undetermined')  # 3 steps: fewer than 8
    level, message = shown_status(fit, 'running')
    assert level == WAITING and message.startswith('waiting: 3 steps so far') and 'undetermined' in message
    assert shown_status(fit, 'paused')[0] == WAITING
    for over in ('done', ''):  # the program ended (or none is known): the design is what it is
        assert shown_status(fit, over) == (ERROR, fit.message)
