"""Who called a node's service, and announcing a call (crane_stiffness.contract.control_events over ROS).

:class:`ServiceCallers` is the serving side: a node that must say who stopped, tared or reset it subscribes to the
control events and asks :meth:`ServiceCallers.caller` in its service callback. The announcing node waits for every
reader's acknowledgement of its event before it calls, so the event is in the serving node's queue before the
request: rclpy's executors take it first (the SingleThreadedExecutor takes a wait's subscriptions before its
services, the EventsExecutor its events in the order they came). :class:`CallAnnouncer` is the calling side (the
live view).
"""
from __future__ import annotations

import time
import uuid

from rclpy.duration import Duration
from rclpy.node import Node
from std_msgs.msg import String

from crane_stiffness.contract.control_events import CONTROL_EVENTS, CONTROL_EVENTS_QOS, ControlCallers, control_event
from crane_stiffness.rosnode.qos import rclpy_qos

#: The longest the announcer waits for the readers' acknowledgement before it calls anyway [s].
ACK_TIMEOUT_S = 2.0


class ServiceCallers:
    """The control events ``node`` receives; :meth:`caller` names who calls one of its services."""

    def __init__(self, node: Node) -> None:
        self._node = node
        self.callers = ControlCallers()
        node.create_subscription(String, CONTROL_EVENTS, self._on_event, rclpy_qos(CONTROL_EVENTS_QOS))

    def _on_event(self, msg: String) -> None:
        self.callers.add(msg.data)

    def caller(self, service: str) -> str:
        """Who calls ``service`` (its absolute name, e.g. '/session_recorder/stop') now, in words."""
        return self.callers.caller(service, time.time_ns())

    def service_name(self, name: str) -> str:
        """The absolute name of the node's private service ``~/name``."""
        return f'{self._node.get_fully_qualified_name().rstrip("/")}/{name.removeprefix("~/")}'


class CallAnnouncer:
    """Publishes a control event before each call ``node`` makes for a client."""

    def __init__(self, node: Node) -> None:
        self._node = node
        self._pub = node.create_publisher(String, CONTROL_EVENTS, rclpy_qos(CONTROL_EVENTS_QOS))

    def announce(self, service: str, by: str) -> bool:
        """Announce that ``by`` calls ``service`` now; True once every matched reader acknowledged it (False after
        :data:`ACK_TIMEOUT_S`: the call goes on, its node may then name a ROS client)."""
        self._pub.publish(String(data=control_event(service, by, self._node.get_fully_qualified_name(),
                                                    time.time_ns(), uuid.uuid4().hex)))
        return bool(self._pub.wait_for_all_acked(Duration(seconds=ACK_TIMEOUT_S)))


__all__ = ['ACK_TIMEOUT_S', 'CallAnnouncer', 'ServiceCallers']
