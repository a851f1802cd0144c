"""What the session recorder keeps of each topic it records (:class:`RecordedChannel`), and which topics the
lock-step counts on simulated time (:data:`SIM_INPUTS`); the recorder is crane_stiffness.nodes.session_recorder."""
from __future__ import annotations

from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.qos import QoSProfile
from rclpy.subscription import Subscription

from crane_stiffness.contract import topics
from crane_stiffness.rosnode.session_qos import has_header, message_class


# rclpy puts a QoS-event handler into every wait of the executor for each subscription with the default event
# callbacks (~15 µs each per wait): with a dozen recorded topics at a few kHz that is a large share of a core.
NO_EVENTS = SubscriptionEventCallbacks(use_default_callbacks=False)


class RecordedChannel:
    """One subscribed topic: type, subscriber QoS, whether its messages carry a header stamp, count."""

    __slots__ = ('topic', 'msg_type', 'msg_class', 'qos', 'stamped', 'subscription', 'added', 'count')

    def __init__(self, topic: str, msg_type: str, qos: QoSProfile) -> None:
        self.topic = topic
        self.msg_type = msg_type
        self.msg_class = message_class(msg_type)
        self.qos = qos
        self.stamped = has_header(self.msg_class)
        self.subscription: Subscription | None = None
        self.added = False
        self.count = 0


#: What the stages below the recorder publish (crane_stiffness.sim.lockstep): on simulated time the recorder waits
#: until it has every message of them up to the stage's watermark.
SIM_INPUTS = (topics.WRENCH_COMMAND, topics.APPLIED_WRENCH, topics.REJECTED_COMMAND, topics.PLATFORM_POSE,
              topics.WIRE_STATES, topics.LOAD_CELL_WRENCH, topics.LVDT_DISPLACEMENT, topics.POSE_SENSOR_POSE)
