"""The rig's QoS classes (crane_stiffness.topics.TOPIC_QOS says which topic has which) as rclpy profiles."""
from __future__ import annotations

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from crane_stiffness import topics


def rclpy_qos(qos: topics.QoS, depth: int | None = None) -> QoSProfile:
    """The rclpy profile of a QoS class of crane_stiffness.topics (KEEP_LAST; ``depth`` overrides the class's)."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=qos.depth if depth is None else depth,
                      reliability=ReliabilityPolicy[qos.reliability.upper()],
                      durability=DurabilityPolicy[qos.durability.upper()])


#: The rig's three QoS classes (crane_stiffness.topics.TOPIC_QOS says which topic has which).
RELIABLE_QOS = rclpy_qos(topics.RELIABLE)
SENSOR_QOS = rclpy_qos(topics.SENSOR_DATA)
LATCHED_QOS = rclpy_qos(topics.LATCHED)
