"""An emulator that stays up between sessions (a lab's stand-in for the box, started once, the rig launched again
and again over it) never serves the previous session's physics: when the session's crane_model leaves (the last
publisher of its input gone) and on ~/reset, rdt_emulator forgets the held wrench (records not ready) and
modbus_emulator the held pose and its zero (reads answer busy), until the next session's model publishes."""
from __future__ import annotations

import pytest
from geometry_msgs.msg import PoseStamped, WrenchStamped
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter

from crane_stiffness.contract import topics
from crane_stiffness.nodes import modbus_emulator, rdt_emulator
from crane_stiffness.rosnode.qos import RELIABLE_QOS
from helpers import PATIENCE_S, call_trigger, isolated, spin_until

pytestmark = pytest.mark.ros


def session_model(ctx, prefix: str, n: int) -> tuple[Node, object, object]:
    """A stand-in for one session's crane_model: publishes the applied wrench and the platform pose."""
    node = Node(f'session_model_{n}', context=ctx)
    return (node, node.create_publisher(WrenchStamped, f'{prefix}{topics.APPLIED_WRENCH}', RELIABLE_QOS),
            node.create_publisher(PoseStamped, f'{prefix}{topics.PLATFORM_POSE}', RELIABLE_QOS))


def publish(ex, node: Node, wrench_pub, pose_pub, fy: float, y: float) -> None:
    """One applied wrench and one pose, once both emulators have matched the publishers (nothing in flight later)."""
    assert spin_until(ex, lambda: wrench_pub.get_subscription_count() >= 1 and pose_pub.get_subscription_count() >= 1,
                      PATIENCE_S)
    wrench = WrenchStamped()
    wrench.header.stamp = node.get_clock().now().to_msg()
    wrench.wrench.force.y = fy
    wrench_pub.publish(wrench)
    pose = PoseStamped()
    pose.header.stamp = wrench.header.stamp
    pose.pose.position.y = y
    pose.pose.position.z = 0.5
    pose.pose.orientation.w = 1.0
    pose_pub.publish(pose)


def test_emulators_forget_a_session_when_its_model_leaves_and_on_reset(rclpy_context):
    rdt_name, prefix, rdt_args = isolated('rdt_emulator')
    rdt = rdt_emulator.RdtEmulator(context=rclpy_context, cli_args=rdt_args, parameter_overrides=[
        Parameter('port', value=0), Parameter('http_port', value=-1)])
    # The same topic prefix for both emulators: one session's model feeds both.
    mb_args = [a.replace(rdt_name, rdt_name + '_mb') if a.startswith('__node:=') else a for a in rdt_args]
    mb = modbus_emulator.ModbusEmulator(context=rclpy_context, cli_args=mb_args,
                                        parameter_overrides=[Parameter('port', value=0)])
    ex = SingleThreadedExecutor(context=rclpy_context)
    for node in (rdt, mb):
        ex.add_node(node)
    try:
        # Session 1: its model publishes; the emulators serve it (the LVDT zeroed on its first pose).
        model, wrench_pub, pose_pub = session_model(rclpy_context, prefix, 1)
        ex.add_node(model)
        publish(ex, model, wrench_pub, pose_pub, 3.0, 0.0)
        assert spin_until(ex, lambda: rdt.applied is not None and mb.pose is not None, PATIENCE_S)
        publish(ex, model, wrench_pub, pose_pub, 3.0, 0.002)
        assert spin_until(ex, lambda: rdt.applied[1] == 3.0 and mb.pose[1] == 0.002, PATIENCE_S)
        assert mb._reading() == pytest.approx(0.002, abs=1e-4)  # along the LVDT's default axis y, from its zero
        # (each emulator looks at the graph every SESSION_CHECK_S: until it has seen the model there)
        assert spin_until(ex, lambda: rdt._publisher_seen and mb._publisher_seen, PATIENCE_S)
        # The session ends: its model leaves. Both forget what it held.
        ex.remove_node(model)
        model.destroy_node()
        assert spin_until(ex, lambda: rdt.applied is None and mb.pose is None, PATIENCE_S)
        assert rdt.counters.resets == 1 and mb.resets == 1 and mb.zero_pose is None
        assert mb._reading() is None  # "server device busy" until the next session's pose
        # Session 2 starts displaced: the emulator zeroes there as a fresh one would.
        model, wrench_pub, pose_pub = session_model(rclpy_context, prefix, 2)
        ex.add_node(model)
        publish(ex, model, wrench_pub, pose_pub, 0.0, 0.010)
        assert spin_until(ex, lambda: rdt.applied is not None and mb.pose is not None, PATIENCE_S)
        assert rdt.applied[1] == 0.0 and mb._reading() == pytest.approx(0.0, abs=1e-4)
        # ~/reset forgets at once, with the model still there.
        probe = Node('reset_caller', context=rclpy_context)
        ex.add_node(probe)
        for name in (rdt_name, rdt_name + '_mb'):
            reply = call_trigger(ex, probe, f'/{name}/reset')
            assert reply.success, reply.message
        assert rdt.applied is None and mb.pose is None and rdt.counters.resets == 2 and mb.resets == 2
    finally:
        ex.shutdown()
        rdt.close()
        mb.close()
