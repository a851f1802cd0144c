"""The rig's QoS classes (crane_stiffness.contract.topics.TOPIC_QOS says which topic has which) as rclpy profiles."""
from __future__ import annotations

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from crane_stiffness.contract import topics


def rclpy_qos(qos: topics.QoS, depth: int | None = None) -> QoSProfile:
    """The rclpy profile of a QoS class of crane_stiffness.contract.topics (KEEP_LAST; ``depth`` overrides the
    class's)."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=qos.depth if depth is None else depth,
                      reliability=ReliabilityPolicy[qos.reliability.upper()],
                      durability=DurabilityPolicy[qos.durability.upper()])


#: The rig's four QoS classes (crane_stiffness.contract.topics.TOPIC_QOS says which topic has which).
RELIABLE_QOS = rclpy_qos(topics.RELIABLE)
SENSOR_QOS = rclpy_qos(topics.SENSOR_DATA)
LATCHED_QOS = rclpy_qos(topics.LATCHED)
KEPT_QOS = rclpy_qos(topics.KEPT)
#: The streams the simulated-time protocol counts (commands, the model's answers, the sensor streams) on simulated
#: time: reliable, and transient local as deep as the sensor-data class, so a reader that DDS matched only after a
#: message went out still gets it (time waits for every message counted: none may be missed). A volatile or
#: best-effort reader (``ros2 topic echo``) still matches.
SIM_STREAM_QOS = rclpy_qos(topics.QoS('reliable', 'transient_local', topics.SENSOR_QUEUE_DEPTH))


def stream_qos(base: QoSProfile, sim_time: bool) -> QoSProfile:
    """``base`` on wall-clock time, :data:`SIM_STREAM_QOS` on simulated time (a counted stream's writer or
    reader)."""
    return SIM_STREAM_QOS if sim_time else base


def sensor_qos(sim_time: bool) -> QoSProfile:
    """The QoS of a sensor stream's publisher or reader: best effort on wall-clock time (real drivers publish so),
    :data:`SIM_STREAM_QOS` on simulated time."""
    return stream_qos(SENSOR_QOS, sim_time)
