"""QoS of recorded and replayed topics, shared by session_recorder and session_player.

- :func:`contract_qos`: the QoS a subscriber needs to match the rig's publishers of a topic (the contract of
  crane_stiffness.topics and nodes.common): sensor streams best effort, latched topics transient local, the rest
  reliable. Topics outside the contract adapt to the publishers found in the graph (:func:`adapted_qos`), the way
  rosbag2 does.
- :func:`offered_profiles`: the publishers' offered QoS as rosbag2 stores it in a bag (``offered_qos_profiles``).
- :func:`playback_qos`: the QoS to republish a topic with, from the offered profiles recorded in the bag.
"""
from __future__ import annotations

from typing import Any, Iterable, Mapping, Sequence

import yaml
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from crane_stiffness import topics
from crane_stiffness.nodes.common import LATCHED_QOS, RELIABLE_QOS, SENSOR_QOS

#: Depth of the recorder's and player's queues where the publisher's own depth is unknown.
DEFAULT_DEPTH = 100

SENSOR_TOPICS = frozenset({topics.LOAD_CELL_WRENCH, topics.LVDT_DISPLACEMENT})
LATCHED_TOPICS = frozenset({topics.PREDICTED_STIFFNESS, topics.PREDICTED_AXIS_STIFFNESS, topics.PROGRAM_PROGRESS,
                            topics.PROGRAM_STATE, topics.MODEL_STATUS})
RELIABLE_TOPICS = frozenset({topics.WRENCH_COMMAND, topics.PLATFORM_POSE, topics.WIRE_STATES,
                             topics.STIFFNESS_ESTIMATE, topics.STIFFNESS_VALUES, topics.STIFFNESS})


def _copy(profile: QoSProfile, depth: int | None = None) -> QoSProfile:
    return QoSProfile(history=profile.history, depth=profile.depth if depth is None else depth,
                      reliability=profile.reliability, durability=profile.durability)


def contract_qos(topic: str) -> QoSProfile | None:
    """Subscriber QoS matching the rig's publishers of ``topic``; None for a topic outside the contract.

    Latched topics get a deeper queue than the publishers' depth 1: progress is published at the command rate and
    the recorder must not lose updates while it writes.
    """
    if topic in SENSOR_TOPICS:
        return _copy(SENSOR_QOS)
    if topic in LATCHED_TOPICS:
        return _copy(LATCHED_QOS, DEFAULT_DEPTH)
    if topic in RELIABLE_TOPICS:
        return _copy(RELIABLE_QOS)
    return None


def adapted_qos(profiles: Sequence[QoSProfile]) -> QoSProfile:
    """A subscriber QoS that matches every given publisher profile (rosbag2's rule).

    Reliable only if every publisher is reliable (a reliable subscriber does not match a best-effort publisher);
    transient local only if every publisher is (otherwise volatile publishers would not match).
    """
    reliable = bool(profiles) and all(p.reliability == ReliabilityPolicy.RELIABLE for p in profiles)
    latched = bool(profiles) and all(p.durability == DurabilityPolicy.TRANSIENT_LOCAL for p in profiles)
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=DEFAULT_DEPTH,
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


def _parse_profiles(offered: str | Iterable[Mapping[str, Any]] | None) -> list[Mapping[str, Any]]:
    if offered is None:
        return []
    if isinstance(offered, str):
        try:
            loaded = yaml.safe_load(offered) if offered.strip() else []
        except yaml.YAMLError:
            return []
        offered = loaded if isinstance(loaded, list) else []
    return [p for p in offered if isinstance(p, Mapping)]


def playback_qos(topic: str, offered: str | Iterable[Mapping[str, Any]] | None) -> QoSProfile:
    """Publisher QoS for replaying ``topic``, from the offered QoS profiles recorded in the bag.

    Reliable if every recorded publisher was reliable, transient local if every one was (so late subscribers of a
    latched topic still get its last value). Depth: the largest recorded depth, or the contract's where the
    recording does not know it (DDS does not propagate the history), at least 1. Without recorded profiles the
    topic contract applies, and reliable/volatile outside it.
    """
    profiles = _parse_profiles(offered)
    contract = contract_qos(topic)
    if not profiles:
        return contract or _copy(RELIABLE_QOS, DEFAULT_DEPTH)
    names = {'reliability': {1: 'reliable', 2: 'best_effort'}, 'durability': {1: 'transient_local', 2: 'volatile'}}

    def policy(p: Mapping[str, Any], key: str) -> str:
        value = p.get(key)
        return names[key].get(value, str(value)) if isinstance(value, int) else str(value)

    reliable = all(policy(p, 'reliability') == 'reliable' for p in profiles)
    latched = all(policy(p, 'durability') == 'transient_local' for p in profiles)
    depths = [int(p['depth']) for p in profiles if isinstance(p.get('depth'), int) and p['depth'] > 0]
    depth = max(depths) if depths else (contract.depth if contract is not None else DEFAULT_DEPTH)
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=max(1, depth),
                      reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)


def message_class(msg_type: str) -> Any:
    """The Python class of ``pkg/msg/Type`` (``pkg/Type`` accepted); raises ValueError if it is not installed."""
    import importlib
    parts = msg_type.split('/')
    if len(parts) == 2:
        parts = [parts[0], 'msg', parts[1]]
    if len(parts) != 3 or not all(parts):
        raise ValueError(f'message type {msg_type!r}: expected pkg/msg/Type')
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
