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
        # (/clock's message begins with its time as a header begins with its stamp: it is logged at the time it says)
        self.stamped = has_header(self.msg_class) or topic == topics.CLOCK
        self.subscription: Subscription | None = None
        self.added = False
        self.count = 0


#: What the stages below the recorder publish (crane_stiffness.sim.lockstep): on simulated time the recorder waits
#: until it has every message of them up to the stage's watermark.
SIM_INPUTS = (topics.WRENCH_COMMAND, topics.APPLIED_WRENCH, topics.REJECTED_COMMAND, topics.PLATFORM_POSE,
              topics.WIRE_STATES, topics.LOAD_CELL_WRENCH, topics.LVDT_DISPLACEMENT, topics.POSE_SENSOR_POSE)
#: What the stages below the recorder also count, without a stamp to log them at (the sensors' zero epochs, the
#: program's progress and state, the model's prediction, the estimators' outputs): the recorder waits for them too,
#: as *soft* inputs (latched, history depth 1: one replaced before delivery is taken as lost after a while, not
#: waited for for ever), and logs each at the watermark of the step it was published in
#: (crane_stiffness.sim.log_times).
SIM_OUTPUTS = (topics.LOAD_CELL_TARE, topics.LVDT_ZERO, topics.PROGRAM_PROGRESS, topics.PROGRAM_STATE,
               topics.PREDICTED_STIFFNESS, topics.PREDICTED_AXIS_STIFFNESS, topics.STIFFNESS_ESTIMATE,
               topics.STIFFNESS_VALUES, topics.STIFFNESS,
               topics.FITTED_PAIRS, topics.FIT_LINES, topics.STIFFNESS6, topics.STIFFNESS6_EXPANDED, topics.COMPLIANCE6,
               topics.STIFFNESS6_STATUS)


def deep(qos: QoSProfile) -> QoSProfile:
    """``qos`` with a queue of :data:`topics.SENSOR_QUEUE_DEPTH`: the recorder's reader of a soft input on simulated
    time, where it takes what came only at the next watermark (a reader of depth 1 would keep the last of a step)."""
    return QoSProfile(history=qos.history, depth=topics.SENSOR_QUEUE_DEPTH, reliability=qos.reliability,
                      durability=qos.durability)
