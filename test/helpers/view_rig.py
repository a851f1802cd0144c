"""The live_view node and a node publishing what the rig publishes, in one rclpy context spun on a thread of its own
(real DDS on loopback): the rig the page and Foxglove tests of the 6×6 feed by hand."""
from __future__ import annotations

import threading
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, WrenchStamped
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from crane_stiffness.contract import topics
from crane_stiffness.nodes.live_view import LiveViewNode
from crane_stiffness.rosnode.qos import LATCHED_QOS, RELIABLE_QOS


class ViewRig:
    """``view``: a LiveViewNode on free ports at 20 Hz (``six_axis_program`` as given); ``pub``: a node with the
    publishers of the six-axis estimator (``k``, ``c``, ``status6``: latched), the one-axis estimate (``estimate``,
    latched) and the crane's state (``wires``, ``pose``, ``wrench``). Close with :meth:`close` (or use as a context
    manager). ``params``: more live_view parameters (e.g. ``allowed_origins``, ``token``)."""

    def __init__(self, ctx: Any, publisher_name: str, *, six_axis_program: bool | None = None, **params: Any) -> None:
        overrides = [Parameter('port', value=0), Parameter('http_port', value=0), Parameter('rate_hz', value=20.0),
                     *(Parameter(name, value=value) for name, value in params.items())]
        if six_axis_program is not None:
            overrides.append(Parameter('six_axis_program', value=six_axis_program))
        self.view = LiveViewNode(context=ctx, parameter_overrides=overrides)
        self.pub = Node(publisher_name, context=ctx)
        self.k = self.pub.create_publisher(Float64MultiArray, topics.STIFFNESS6, LATCHED_QOS)
        self.c = self.pub.create_publisher(Float64MultiArray, topics.COMPLIANCE6, LATCHED_QOS)
        self.status6 = self.pub.create_publisher(DiagnosticArray, topics.STIFFNESS6_STATUS, LATCHED_QOS)
        self.estimate = self.pub.create_publisher(DiagnosticArray, topics.STIFFNESS_ESTIMATE, LATCHED_QOS)
        self.wires = self.pub.create_publisher(JointState, topics.WIRE_STATES, RELIABLE_QOS)
        self.pose = self.pub.create_publisher(PoseStamped, topics.PLATFORM_POSE, RELIABLE_QOS)
        self.wrench = self.pub.create_publisher(WrenchStamped, topics.APPLIED_WRENCH, RELIABLE_QOS)
        self.executor = SingleThreadedExecutor(context=ctx)
        self.executor.add_node(self.view)
        self.executor.add_node(self.pub)
        self.stopping = False
        self.thread = threading.Thread(target=self._spin, daemon=True)
        self.thread.start()

    def _spin(self) -> None:
        while not self.stopping:
            self.executor.spin_once(timeout_sec=0.05)

    def close(self) -> None:
        self.stopping = True
        self.thread.join(10)
        self.view.close()
        self.executor.shutdown()
        self.view.destroy_node()
        self.pub.destroy_node()

    def __enter__(self) -> ViewRig:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
