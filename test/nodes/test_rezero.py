"""A sensor re-zeroed without a restart starts a new fit segment (real DDS).

The LVDT publishes its zero epoch (the number of zeros since it started) latched on /lvdt/zero; the estimator starts
a new segment when it changes while the segment holds LVDT readings, so the window never mixes two zero points.
"""
from __future__ import annotations

import numpy as np
import pytest
from rclpy.parameter import Parameter
from std_msgs.msg import Float64

from helpers import PATIENCE_S, spin_until
from crane_stiffness.contract import topics
from crane_stiffness.estimation.live import LiveStiffness
from crane_stiffness.estimation.sync import DISPLACEMENT, FORCE
from crane_stiffness.rosnode.qos import LATCHED_QOS
from crane_stiffness.nodes.stiffness_estimator import StiffnessEstimatorNode
from helpers.estimator import (C, K, EstimatorProbe, SyntheticRig, executor_with, identity, isolated_estimator,
                               statuses, wait_drained)

RATE_HZ = 500.0
WINDOW = 600


def test_lvdt_rezero_without_restart_starts_a_new_segment(rclpy_context):
    """During the loading ramp the LVDT re-zeroes (its readings step by the displacement there) and publishes zero
    epoch 1: the estimator starts segment 'lvdt re-zeroed' and the loading estimate is K within 1 %; the window
    it would have fitted without the new segment, mixing both zeros, is far off (a negative slope here)."""
    name, prefix, args = isolated_estimator()
    probe = EstimatorProbe(rclpy_context, prefix)
    estimator = StiffnessEstimatorNode(context=rclpy_context, cli_args=args, parameter_overrides=[
        Parameter('window', value=WINDOW), Parameter('diagnostics_rate_hz', value=20.0),
        Parameter('expected_period_s', value=1.0 / RATE_HZ)])
    rig = SyntheticRig(rclpy_context, prefix, rate_hz=RATE_HZ, ramp_s=2.5, seed=31)
    zero = rig.node.create_publisher(Float64, prefix + topics.LVDT_ZERO, LATCHED_QOS)
    zero.publish(Float64(data=0.0))  # the LVDT's epoch at start, latched
    ex = executor_with(rclpy_context, estimator, probe.node, rig.node)
    assert spin_until(ex, lambda: rig.pub_force.get_subscription_count() >= 1 and zero.get_subscription_count() >= 1
                      and rig.pub_point.get_subscription_count() >= 1 and rig.pub_cmd.get_subscription_count() >= 1,
                      PATIENCE_S)
    rig.start()
    assert spin_until(ex, lambda: rig.sent >= 1000, PATIENCE_S)  # 0.6 s before the peak (sample 1300)
    # The latched first epoch started nothing: still the start-up segment.
    assert estimator.core.counters.segments == 1 and estimator.core.segment_reason == 'start'
    # Re-zero between two bursts, at the current load: no restart, same publisher, readings step by -x here.
    rezero_at = rig.sent
    t_s = rezero_at / RATE_HZ  # the rig's time of the next sample from its start
    rig.x_offset = (rig.load(t_s) - C) / K
    zero.publish(Float64(data=1.0))
    assert spin_until(ex, lambda: rig.done, PATIENCE_S)
    wait_drained(ex, rig, estimator, probe)
    core = estimator.core
    loading, unloading = probe.last(0), probe.last(1)
    print(f'segments {core.counters.segments} ({core.segment_reason}); re-zero at sample {rezero_at}, offset '
          f'{rig.x_offset * 1e3:.4f} mm; loading {loading["stiffness"]:.1f}, unloading {unloading["stiffness"]:.1f} '
          f'N/m (true {K})')
    assert core.counters.segments == 2 and core.segment_reason == 'lvdt re-zeroed'
    assert spin_until(ex, lambda: any('new fit segment' in b.message and 'lvdt re-zeroed' in b.message
                                      for a in probe.estimates for b in statuses(a)[0]), PATIENCE_S)
    assert loading['stiffness'] == pytest.approx(K, rel=0.01)
    assert loading['intercept'] == pytest.approx(C + K * rig.x_offset, abs=0.03)  # the new zero: F = C + K·offset at 0
    assert unloading['stiffness'] == pytest.approx(K, rel=0.01)
    # Without the new segment the last loading window (the WINDOW samples up to the peak) would straddle the
    # re-zero: fit such a window directly (noise-free).
    peak = round((rig.lead_s + rig.ramp_s) * RATE_HZ)
    assert peak - WINDOW < rezero_at < peak - 100
    i = np.arange(peak - WINDOW, peak + 1)
    f = np.array([rig.load(k / RATE_HZ) for k in i])
    x = (f - C) / K - np.where(i >= rezero_at, rig.x_offset, 0.0)
    k_mixed = np.polyfit(x, f, 1)[0]
    print(f'a window mixing both zeros: {k_mixed:.1f} N/m')
    assert abs(k_mixed - K) > 0.5 * K
    identity(core.accounting())
    ex.shutdown()


def test_zero_epoch_rule():
    """The first epoch, an unchanged one and a change before any reading start nothing; a change with readings in the
    segment does, named for the sensor."""
    core = LiveStiffness()
    assert not core.zero_epoch(DISPLACEMENT, 0.0)   # latched value at start
    assert not core.zero_epoch(DISPLACEMENT, 1.0)   # zeroed at its first pose, before any reading
    assert not core.zero_epoch(FORCE, 3.0)
    core.add_force(1.0, (0.0, 1.0, 0.0, 0.0, 0.0, 0.0))
    core.add_displacement(1.0, 1e-4)
    assert not core.zero_epoch(DISPLACEMENT, 1.0)   # the same epoch again (a late joiner's latched copy)
    segments = core.counters.segments
    assert core.zero_epoch(DISPLACEMENT, 2.0)
    assert core.segment_reason == 'lvdt re-zeroed' and core.counters.segments == segments + 1
    assert not core.zero_epoch(FORCE, 4.0)           # no force reading in the new segment yet
    core.add_force(1.01, (0.0, 1.0, 0.0, 0.0, 0.0, 0.0))
    assert core.zero_epoch(FORCE, 5.0) and core.segment_reason == 'load cell tared'
