"""The live 6×6 fit's expanded uncertainty U: the pure core (crane_stiffness.full6.live_uncertainty) equals the
offline law of propagation (crane_stiffness.uncertainty.matrix) on the same step means, and says what it counts; the
stiffness6_estimator node, fed a six-axis session over real DDS (in-process), publishes K ∓ U on
/stiffness6/stiffness_expanded and K2's U in its status equal to the offline matrix_uncertainty's law of propagation
for the step means of the same samples: "statistical only" before any sensor declares a calibration, the load cell's
and the pose sensor's declared calibrations once it has read them from their nodes, and again after a change of one
of them (re-read on /parameter_events)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from crane_stiffness.full6.live_uncertainty import LiveMatrixUncertainty
from crane_stiffness.full6.statistics import pair_statistics
from crane_stiffness.testing.synthetic_full6 import declared_calibrations
from crane_stiffness.uncertainty.calibration6 import six_axis_inputs
from crane_stiffness.uncertainty.matrix import matrix_uncertainty
from helpers import PATIENCE_S, spin_until
from helpers.full6_streams import feed, streams

SETTLE_S = 0.3


def _offline(stats, load_cell=None, pose_sensor=None):
    means = stats.step_means
    return matrix_uncertainty(means[:, :6], means[:, 6:], six_axis_inputs(load_cell, pose_sensor), trials=0)


def test_the_live_core_is_the_offline_law_of_propagation_and_names_what_it_counts():
    s = streams(0.0, wrench_rate_hz=250.0)
    pairs = s.pairs(SETTLE_S)
    stats = pair_statistics(pairs.wrench, pairs.deflection, pairs.step)
    live = LiveMatrixUncertainty()
    bare = live.of(stats)
    expected = _offline(stats)
    assert bare.stated and bare.statistical_only and bare.statement.startswith('statistical only')
    np.testing.assert_array_equal(bare.U, expected.stiffness.U)
    assert bare.k2_U == float(expected.k2.U) and bare.steps == len(stats.steps) >= 8
    assert live.of(stats) is bare  # the same step means: not computed again
    load_cell, pose = declared_calibrations()
    live.set_calibration('load_cell', load_cell)
    live.set_calibration('pose_sensor', pose)
    full = live.of(stats)
    expected = _offline(stats, load_cell, pose)
    np.testing.assert_array_equal(full.U, expected.stiffness.U)
    np.testing.assert_array_equal(full.k, expected.stiffness.k)
    assert full.k2_U == float(expected.k2.U) and not full.statistical_only
    assert 'load_cell sensitivity' in full.statement and 'pose_sensor angle' in full.statement
    assert np.all(full.U / full.k > bare.U / bare.k)  # the calibrations add to every entry's u_c
    # an LVDT array measuring the deflection: its channels are named as not counted
    live.set_calibration('lvdt_array', {})
    assert 'lvdt_array channel calibrations' in live.of(stats).statement
    # a declaration the budget refuses: no U at all, said, never a U that silently leaves it out
    live.set_calibration('load_cell', {**load_cell, 'calibration.sensitivity_distribution': 'lognormal'})
    refused = live.of(stats)
    assert not refused.stated and np.all(np.isnan(refused.U)) and math.isnan(refused.k2_U)
    assert 'refused' in refused.statement and 'sensitivity_distribution' in refused.problem
    # too few steps for a Type A: no U yet, said
    few = pair_statistics(pairs.wrench[pairs.step <= pairs.step.min() + 3],
                          pairs.deflection[pairs.step <= pairs.step.min() + 3],
                          pairs.step[pairs.step <= pairs.step.min() + 3])
    live.set_calibration('load_cell', load_cell)
    assert not live.of(few).stated and 'no U yet' in live.of(few).statement


@pytest.mark.ros
def test_the_node_states_u_of_k_and_k2_equal_to_the_offline_law_of_propagation(rclpy_context):
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import PoseStamped, WrenchStamped
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from std_msgs.msg import Float64MultiArray

    from crane_stiffness.contract import stiffness6_layout, topics
    from crane_stiffness.nodes.stiffness6_estimator import Stiffness6EstimatorNode
    from crane_stiffness.rosnode.qos import KEPT_QOS, RELIABLE_QOS, SENSOR_QOS

    node = Stiffness6EstimatorNode(context=rclpy_context, parameter_overrides=[
        Parameter('settle_s', value=SETTLE_S), Parameter('publish_rate_hz', value=0.01),
        Parameter('load_cell_nodes', value=['/u6_load_cell']),
        Parameter('pose_sensor_nodes', value=['/u6_pose_sensor'])])
    feeder = rclpy.create_node('u6_feeder', context=rclpy_context)
    got: dict[str, list] = {'expanded': [], 'k': [], 'status': []}
    feeder.create_subscription(Float64MultiArray, topics.STIFFNESS6_EXPANDED, got['expanded'].append, KEPT_QOS)
    feeder.create_subscription(Float64MultiArray, topics.STIFFNESS6, got['k'].append, KEPT_QOS)
    feeder.create_subscription(DiagnosticArray, topics.STIFFNESS6_STATUS, got['status'].append, KEPT_QOS)
    pubs = (feeder.create_publisher(WrenchStamped, topics.WRENCH_COMMAND, RELIABLE_QOS),
            feeder.create_publisher(WrenchStamped, topics.LOAD_CELL_WRENCH, SENSOR_QOS),
            feeder.create_publisher(PoseStamped, topics.POSE_SENSOR_POSE, SENSOR_QOS))
    executor = SingleThreadedExecutor(context=rclpy_context)
    for n in (node, feeder):
        executor.add_node(n)
    sensors: list = []

    def published(stats, load_cell=None, pose_sensor=None) -> dict[str, str]:
        """What the node publishes next (its fit now), checked against the offline law of propagation."""
        before = {kind: len(got[kind]) for kind in got}
        node._publish()  # (its own timer: once in 100 s, so this is the one publication of this fit)
        fit = node.fit
        assert fit is not None
        assert spin_until(executor, lambda: all(len(got[kind]) > before[kind] for kind in got))
        np.testing.assert_array_equal(stiffness6_layout.decode_message(got['k'][-1])[0], fit.stiffness)
        expected = _offline(stats, load_cell, pose_sensor)
        cube = stiffness6_layout.decode_message(got['expanded'][-1])
        np.testing.assert_allclose(cube[2] - cube[0], expected.stiffness.U, rtol=1e-6)
        np.testing.assert_allclose(cube[0] - cube[1], expected.stiffness.U, rtol=1e-6)
        values = {kv.key: kv.value for kv in got['status'][-1].status[0].values}
        assert float(values['k2_U']) == pytest.approx(float(expected.k2.U), rel=1e-6)
        assert float(values['k2_coverage_factor']) == pytest.approx(float(expected.k2.k), rel=1e-3)
        low, high = (float(v) for v in values['k2_U_interval'].split(' .. '))
        assert (high - low) / 2 == pytest.approx(float(expected.k2.U), rel=1e-6)
        assert int(values['uncertainty_steps']) == len(stats.steps)
        return values

    try:
        assert spin_until(executor, lambda: all(p.get_subscription_count() for p in pubs)), 'never matched'
        s = streams(node.get_clock().now().nanoseconds * 1e-9, wrench_rate_hz=250.0)
        feed(executor, node, pubs, s)
        pairs = s.pairs(SETTLE_S)
        assert node.counters['pairs'] == len(pairs)
        stats = pair_statistics(pairs.wrench, pairs.deflection, pairs.step)
        assert len(stats.steps) >= 8
        # no sensor node declares anything: statistical only, named
        values = published(stats)
        assert values['statistical_only'] == 'true' and values['uncertainty'].startswith('statistical only')
        bare_k2_u = float(values['k2_U'])

        # the sensors' nodes come up with their declarations: read, and counted
        load_cell, pose = declared_calibrations()
        for name, declared in (('u6_load_cell', load_cell), ('u6_pose_sensor', pose)):
            sensor = rclpy.create_node(name, context=rclpy_context)
            for key, value in declared.items():
                sensor.declare_parameter(key, value)
            executor.add_node(sensor)
            sensors.append(sensor)
        assert spin_until(executor, lambda: all(node.budget.calibrations[k] is not None
                                                for k in ('load_cell', 'pose_sensor')), PATIENCE_S)
        values = published(stats, load_cell, pose)
        assert values['statistical_only'] == 'false'
        assert 'load_cell sensitivity' in values['uncertainty'] and 'pose_sensor angle' in values['uncertainty']
        assert float(values['k2_U']) > bare_k2_u

        # the load cell's certificate changes: read again (/parameter_events), U follows
        before = node.budget.calibrations['load_cell']
        changed = {**load_cell, 'calibration.sensitivity': [2.0] * 6}
        sensors[0].set_parameters([Parameter('calibration.sensitivity', value=[2.0] * 6)])
        assert spin_until(executor, lambda: node.budget.calibrations['load_cell'] is not before, PATIENCE_S)
        published(stats, changed, pose)
    finally:
        executor.shutdown()
        for n in (*sensors, feeder, node):
            n.destroy_node()
