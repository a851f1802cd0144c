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
#: The sensor streams on simulated time: reliable (the clock waits for every reader to acknowledge, so nothing is
#: lost at any load), as deep as the sensor-data class. A best-effort reader (``ros2 topic echo``) still matches.
SIM_SENSOR_QOS = rclpy_qos(topics.QoS('reliable', 'volatile', topics.SENSOR_QUEUE_DEPTH))


def sensor_qos(sim_time: bool) -> QoSProfile:
    """The QoS of a sensor stream's publisher or reader: best effort on wall-clock time (real drivers publish so),
    reliable on simulated time."""
    return SIM_SENSOR_QOS if sim_time else SENSOR_QOS
