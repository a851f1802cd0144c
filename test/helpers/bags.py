"""Bags for the bag I/O tests: rig messages serialized by rclpy, written with our writer, read back by ours and by two
independent readers (rosbags, mcap_ros2)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PointStamped, PoseStamped, WrenchStamped
from rclpy.serialization import serialize_message as serialize
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64

from crane_stiffness.bag import BagReader, BagWriter, dump_qos_profiles, qos_profile
from crane_stiffness.bag.session_metadata import SESSION_METADATA, session_metadata

T0 = 1_700_000_000_000_000_000
TOPICS = {
    '/load_cell/wrench': 'geometry_msgs/msg/WrenchStamped',
    '/lvdt/displacement': 'geometry_msgs/msg/PointStamped',
    '/crane/platform_pose': 'geometry_msgs/msg/PoseStamped',
    '/program/setpoint': 'std_msgs/msg/Float64',
    '/crane/winches': 'sensor_msgs/msg/JointState',
}
JOINTS = ['winch_1', 'winch_2', 'winch_3', 'winch_4', 'winch_5', 'winch_6']
RIG = {'wires': 6, 'anchor_radius_m': 1.25, 'platform_radius_m': 0.3}



# ------------------------------------------------------------------------------------------------- helpers --
def _stamp(t_ns: int) -> Time:
    return Time(sec=t_ns // 10**9, nanosec=t_ns % 10**9)


def make_messages(n_fast: int = 1200, n_slow: int = 200, seed: int = 7) -> list[tuple[str, int, object, bytes]]:
    """(topic, log_time_ns, rclpy message, its CDR bytes) in log-time order; random floats.

    Serialized once: rclpy leaves CDR padding bytes uninitialized, so serializing again may differ in them.
    """
    rng = np.random.default_rng(seed)
    out: list[tuple[str, int, object]] = []
    for i in range(n_fast):
        t = T0 + i * 1_000_000
        w = WrenchStamped()
        w.header.stamp = _stamp(t)
        w.header.frame_id = 'load_cell' if i % 7 else 'load_cell_spare'  # two frame_id lengths
        f = rng.normal(size=6) * [50, 50, 900, 3, 3, 0.5]
        w.wrench.force.x, w.wrench.force.y, w.wrench.force.z = map(float, f[:3])
        w.wrench.torque.x, w.wrench.torque.y, w.wrench.torque.z = map(float, f[3:])
        out.append(('/load_cell/wrench', t + 120_000, w))
        p = PointStamped()
        p.header.stamp = _stamp(t + 1)
        p.header.frame_id = 'lvdt'
        p.point.x, p.point.y, p.point.z = map(float, rng.normal(size=3) * 1e-4)
        out.append(('/lvdt/displacement', t + 130_000, p))
        if i % (n_fast // n_slow) == 0:
            q = PoseStamped()
            q.header.stamp = _stamp(t + 2)
            q.header.frame_id = 'world'
            q.pose.position.x, q.pose.position.y, q.pose.position.z = map(float, rng.normal(size=3))
            quat = rng.normal(size=4)
            quat /= np.linalg.norm(quat)
            (q.pose.orientation.x, q.pose.orientation.y, q.pose.orientation.z,
             q.pose.orientation.w) = map(float, quat)
            out.append(('/crane/platform_pose', t + 140_000, q))
            out.append(('/program/setpoint', t + 150_000, Float64(data=float(rng.normal() * 1000))))
            j = JointState()
            j.header.stamp = _stamp(t + 3)
            j.header.frame_id = 'crane'
            j.name = JOINTS
            j.position = [float(x) for x in rng.normal(size=6)]
            j.velocity = [float(x) for x in rng.normal(size=6)]
            j.effort = [float(x) for x in rng.normal(size=6) * 100]
            out.append(('/crane/winches', t + 160_000, j))
    return [(topic, log, msg, serialize(msg)) for topic, log, msg in out]


def values_of(msg_type: str, m) -> tuple:
    """Comparable plain values of a message from rclpy, rosbags or mcap_ros2 (same attribute names)."""
    if msg_type == 'std_msgs/msg/Float64':
        return (float(m.data),)
    head = (int(m.header.stamp.sec), int(m.header.stamp.nanosec), str(m.header.frame_id))
    if msg_type.endswith('WrenchStamped'):
        f, t = m.wrench.force, m.wrench.torque
        return head + tuple(float(v) for v in (f.x, f.y, f.z, t.x, t.y, t.z))
    if msg_type.endswith('PointStamped'):
        return head + (float(m.point.x), float(m.point.y), float(m.point.z))
    if msg_type.endswith('PoseStamped'):
        p, o = m.pose.position, m.pose.orientation
        return head + tuple(float(v) for v in (p.x, p.y, p.z, o.x, o.y, o.z, o.w))
    return head + (tuple(str(x) for x in m.name), tuple(float(x) for x in m.position),
                   tuple(float(x) for x in m.velocity), tuple(float(x) for x in m.effort))


def values_of_row(msg_type: str, row: np.void) -> tuple:
    """The same values from one row of a bulk-decoded array."""
    if msg_type == 'std_msgs/msg/Float64':
        return (float(row['data']),)
    head = (int(row['stamp_sec']), int(row['stamp_nanosec']), row['frame_id'].decode())
    names = {'geometry_msgs/msg/WrenchStamped': ('fx', 'fy', 'fz', 'mx', 'my', 'mz'),
             'geometry_msgs/msg/PointStamped': ('x', 'y', 'z'),
             'geometry_msgs/msg/PoseStamped': ('x', 'y', 'z', 'qx', 'qy', 'qz', 'qw')}.get(msg_type)
    if names:
        return head + tuple(float(row[n]) for n in names)
    return head + (tuple(x.decode() for x in row['name']), tuple(map(float, row['position'])),
                   tuple(map(float, row['velocity'])), tuple(map(float, row['effort'])))


def expected_by_topic(messages) -> dict[str, list[tuple[int, tuple]]]:
    out: dict[str, list[tuple[int, tuple]]] = {t: [] for t in TOPICS}
    for topic, log, msg, _ in messages:
        out[topic].append((log, values_of(TOPICS[topic], msg)))
    return out


def write_bag(path: Path, messages, **options) -> Path:
    with BagWriter(path, metadata={SESSION_METADATA: session_metadata(
            rig=RIG, program={'kind': 'ramp', 'max_load_N': 900}, start_time_ns=T0, notes='test session')},
            **options) as writer:
        for topic, msg_type in TOPICS.items():
            writer.add_topic(topic, msg_type, dump_qos_profiles([qos_profile(depth=100)]))
        for topic, log, _, data in messages:
            writer.write(topic, data, log, log - 50_000)
    return path


def read_with_rosbags(bag: Path) -> dict[str, list[tuple[int, tuple]]]:
    from rosbags.highlevel import AnyReader
    out: dict[str, list[tuple[int, tuple]]] = {}
    with AnyReader([bag]) as reader:
        for connection, timestamp, raw in reader.messages():
            msg = reader.deserialize(raw, connection.msgtype)
            out.setdefault(connection.topic, []).append((timestamp, values_of(connection.msgtype, msg)))
    return out


def read_with_mcap_ros2(files: list[Path]) -> dict[str, list[tuple[int, tuple]]]:
    from mcap_ros2.reader import read_ros2_messages
    out: dict[str, list[tuple[int, tuple]]] = {}
    for path in files:
        for m in read_ros2_messages(str(path)):
            out.setdefault(m.channel.topic, []).append(
                (m.log_time_ns, values_of(m.schema.name, m.ros_msg)))
    return {t: sorted(v, key=lambda x: x[0]) for t, v in out.items()}


def decoded(reader: BagReader) -> dict[str, list[tuple[int, tuple]]]:
    arrays = reader.decode_topics([t for t in TOPICS if t in reader.topics])
    return {t: [(int(r['log_time_ns']), values_of_row(TOPICS[t], r)) for r in a] for t, a in arrays.items()}
