"""QoS of recorded and replayed topics, shared by session_recorder and session_player.

- :func:`contract_qos`: the QoS a subscriber needs to match the rig's publishers of a topic (the contract's table,
  crane_stiffness.contract.topics.TOPIC_QOS): sensor streams best effort, latched topics transient local, the rest
  reliable. Topics outside the contract adapt to the publishers found in the graph (:func:`adapted_qos`), the way
  rosbag2 does.
- :func:`offered_profiles`: the publishers' offered QoS as rosbag2 stores it in a bag (``offered_qos_profiles``).
- :func:`playback_qos`: the QoS to republish a topic with, from the offered profiles recorded in the bag.
"""
from __future__ import annotations

from typing import Any, Iterable, Mapping, Sequence

from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from crane_stiffness.contract import topics
from crane_stiffness.bag.errors import UnsupportedTypeError
from crane_stiffness.bag.msgdef import interface_prefix
from crane_stiffness.bag.qos import policy_name, recorded_qos_profiles
from crane_stiffness.rosnode.qos import rclpy_qos


def contract_qos(topic: str) -> QoSProfile | None:
    """Subscriber QoS matching the rig's publishers of ``topic``; None for a topic outside the contract.

    At least topics.RECORD_QUEUE_DEPTH deep (latched topics: deeper than the publishers' depth 1).
    """
    qos = topics.TOPIC_QOS.get(topic)
    if qos is None:
        return None
    return rclpy_qos(qos, max(qos.depth, topics.RECORD_QUEUE_DEPTH))


def adapted_qos(profiles: Sequence[QoSProfile]) -> QoSProfile:
    """A subscriber QoS that matches every given publisher profile (rosbag2's rule).

    Reliable only if every publisher is reliable (a reliable subscriber does not match a best-effort publisher);
    transient local only if every publisher is (otherwise volatile publishers would not match).
    """
    reliable = bool(profiles) and all(p.reliability == ReliabilityPolicy.RELIABLE for p in profiles)
    latched = bool(profiles) and all(p.durability == DurabilityPolicy.TRANSIENT_LOCAL for p in profiles)
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=topics.RECORD_QUEUE_DEPTH,
                      reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)


def _duration(value: Duration | Any) -> dict[str, int]:
    ns = int(value.nanoseconds) if isinstance(value, Duration) else int(getattr(value, 'nanoseconds', 0))
    return {'sec': ns // 1_000_000_000, 'nsec': ns % 1_000_000_000}


def profile_to_dict(profile: QoSProfile) -> dict[str, Any]:
    """One QoS profile in rosbag2's integer-policy form (crane_stiffness.bag.dump_qos_profiles names them)."""
    return {
        'history': int(profile.history), 'depth': int(profile.depth), 'reliability': int(profile.reliability),
        'durability': int(profile.durability), 'deadline': _duration(profile.deadline),
        'lifespan': _duration(profile.lifespan), 'liveliness': int(profile.liveliness),
        'liveliness_lease_duration': _duration(profile.liveliness_lease_duration),
        'avoid_ros_namespace_conventions': bool(profile.avoid_ros_namespace_conventions),
    }


def offered_profiles(node: Node, topic: str, fallback: QoSProfile | None = None) -> list[dict[str, Any]]:
    """The offered QoS of the publishers of ``topic`` now in the graph (``fallback`` if there are none)."""
    infos = node.get_publishers_info_by_topic(topic)
    profiles = [profile_to_dict(i.qos_profile) for i in infos]
    if not profiles and fallback is not None:
        profiles = [profile_to_dict(fallback)]
    return profiles


def publisher_types(node: Node, topic: str) -> set[str]:
    """Message types of the publishers of ``topic`` in the graph."""
    return {i.topic_type for i in node.get_publishers_info_by_topic(topic)}


def playback_qos(topic: str, offered: str | Iterable[Mapping[str, Any]] | None) -> QoSProfile:
    """Publisher QoS for replaying ``topic``, from the offered QoS profiles recorded in the bag.

    Reliable if every recorded publisher was reliable, transient local if every one was (so late subscribers of a
    latched topic still get its last value). Depth: the largest recorded depth, or the contract's where the
    recording does not know it (DDS does not propagate the history), at least 1. Without recorded profiles the
    topic contract applies, and reliable/volatile outside it.
    """
    profiles = recorded_qos_profiles(offered)
    contract = contract_qos(topic)
    if not profiles:
        return contract or rclpy_qos(topics.RELIABLE, topics.RECORD_QUEUE_DEPTH)
    reliable = all(policy_name('reliability', p.get('reliability')) == 'reliable' for p in profiles)
    latched = all(policy_name('durability', p.get('durability')) == 'transient_local' for p in profiles)
    depths = [int(p['depth']) for p in profiles if isinstance(p.get('depth'), int) and p['depth'] > 0]
    depth = max(depths) if depths else (contract.depth if contract is not None else topics.RECORD_QUEUE_DEPTH)
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=max(1, depth),
                      reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)


def message_class(msg_type: str) -> Any:
    """The Python class of ``pkg/msg/Type`` (``pkg/Type`` accepted); raises ValueError if it is not installed.

    Only a type the ament index lists as an interface (crane_stiffness.bag.msgdef.interface_prefix) is imported:
    a type name read from a bag or the graph cannot make this import an arbitrary Python module.
    """
    import importlib
    parts = msg_type.split('/')
    if len(parts) == 2:
        parts = [parts[0], 'msg', parts[1]]
    if len(parts) != 3 or not all(parts) or parts[1] != 'msg':
        raise ValueError(f'message type {msg_type!r}: expected pkg/msg/Type')
    try:
        interface_prefix(msg_type)
    except UnsupportedTypeError as exc:
        raise ValueError(str(exc)) from None
    try:
        module = importlib.import_module(f'{parts[0]}.{parts[1]}')
        return getattr(module, parts[2])
    except (ImportError, AttributeError):
        raise ValueError(f'message type {msg_type!r} is not installed (no Python module {parts[0]}.{parts[1]} '
                         f'with {parts[2]})') from None


def has_header(msg_class: Any) -> bool:
    """True when the message starts with a std_msgs/Header (its CDR stamp is then at bytes 4..12)."""
    fields = list(msg_class.get_fields_and_field_types().items())
    return bool(fields) and fields[0] == ('header', 'std_msgs/Header')
