"""sim_clock's log of a wait: "waiting for NODE to join" (INFO) and then "held at ... by NODE" (WARN) come from one
method; rclpy's logger refuses a call site whose severity changes between calls (ValueError), which ended the
clock, and with it a session, the first time a hold followed a wait (seen under load in a cluster campaign)."""
from __future__ import annotations

from rclpy.parameter import Parameter

from crane_stiffness.nodes.sim_clock import SimClock


def test_a_wait_then_a_hold_then_a_wait_are_all_logged(rclpy_context):
    clock = SimClock(context=rclpy_context, parameter_overrides=[Parameter('log_period_s', value=0.1)])
    try:
        now = clock._last_log
        clock._log_held(now + 1.0, 'waiting for crane_model to join')
        clock._log_held(now + 2.0, 'held at 1000.100 s for 1 s by crane_model', warn=True)
        clock._log_held(now + 3.0, 'waiting for lvdt to join')
        assert clock._last_log == now + 3.0  # each was logged (none skipped as too soon)
    finally:
        clock.destroy_node()
