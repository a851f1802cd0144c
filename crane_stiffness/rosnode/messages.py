"""Small helpers over ROS messages the nodes share: stamps in seconds, finite values, a pose as a vector."""
from __future__ import annotations

import math
from typing import Iterable

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseStamped

from crane_stiffness.model.rotation import quaternion_to_matrix
from crane_stiffness.serde import stamp_seconds


def stamp_to_s(stamp: Time) -> float:
    return stamp_seconds(stamp.sec, stamp.nanosec)


def finite(values: Iterable[float]) -> bool:
    return all(math.isfinite(v) for v in values)


def pose_vector(msg: PoseStamped) -> np.ndarray | None:
    """[u (3), Q row-major (9)] of a pose message, or None for NaN/Inf or a zero quaternion."""
    p, o = msg.pose.position, msg.pose.orientation
    values = (p.x, p.y, p.z, o.x, o.y, o.z, o.w)
    if not finite(values) or math.hypot(o.x, o.y, o.z, o.w) < 1e-9:
        return None
    return np.concatenate([values[:3], quaternion_to_matrix(np.array(values[3:])).ravel()])


def pose_position_quaternion(msg: PoseStamped) -> np.ndarray | None:
    """[position (3), quaternion x y z w (4)] of a pose message as it is (not normalised), or None for NaN/Inf or a
    zero quaternion."""
    p, o = msg.pose.position, msg.pose.orientation
    values = (p.x, p.y, p.z, o.x, o.y, o.z, o.w)
    if not finite(values) or math.hypot(o.x, o.y, o.z, o.w) < 1e-9:
        return None
    return np.array(values)


def pose_stamped(t_ns: int, frame_id: str, position: Iterable[float], quaternion: Iterable[float]) -> PoseStamped:
    """A PoseStamped stamped ``t_ns`` [ns] in ``frame_id``: position x y z [m], orientation quaternion x y z w (the
    pose sensor's and the LVDT array's message)."""
    from crane_stiffness.serde.stamps import split_ns
    msg = PoseStamped()
    msg.header.stamp.sec, msg.header.stamp.nanosec = split_ns(t_ns)
    msg.header.frame_id = frame_id
    p, o = msg.pose.position, msg.pose.orientation
    p.x, p.y, p.z = position
    o.x, o.y, o.z, o.w = quaternion
    return msg
