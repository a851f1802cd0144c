"""Offered QoS profiles in rosbag2's bag format (metadata version 9): dicts with policy names, and their YAML text.

rosbag2 Jazzy stores a topic's offered profiles as a YAML sequence in metadata.yaml and, as a string, in the MCAP
channel metadata ``offered_qos_profiles``. Policies are lower-case names; durations are ``{sec, nsec}``. Older
bags (Humble) use integers for the policies: :func:`normalize_qos_profiles` turns them into names (for the bag
writer, strict), :func:`recorded_qos_profiles` and :func:`policy_name` read them for playback (lenient: what cannot
be read is left out).
"""
from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import yaml

from .errors import BagWriterError
from .yamlfmt import dump_yaml, load_yaml

DURATION_INFINITE = {'sec': 9223372036, 'nsec': 854775807}
"""rmw's RMW_DURATION_INFINITE as rosbag2 writes it in QoS profiles."""

QOS_POLICY_NAMES = {
    'history': {0: 'system_default', 1: 'keep_last', 2: 'keep_all', 3: 'unknown'},
    'reliability': {0: 'system_default', 1: 'reliable', 2: 'best_effort', 3: 'unknown', 4: 'best_available'},
    'durability': {0: 'system_default', 1: 'transient_local', 2: 'volatile', 3: 'unknown', 4: 'best_available'},
    'liveliness': {0: 'system_default', 1: 'automatic', 2: 'manual_by_node', 3: 'manual_by_topic', 4: 'unknown',
                   5: 'best_available'},
}
"""Integer policy values (rmw enums, as older bags store them) → the names rosbag2 v9 writes."""
QOS_KEYS = ('history', 'depth', 'reliability', 'durability', 'deadline', 'lifespan', 'liveliness',
            'liveliness_lease_duration', 'avoid_ros_namespace_conventions')
"""The keys of one profile, in rosbag2's order."""


def qos_profile(*, history: str = 'keep_last', depth: int = 10, reliability: str = 'reliable',
                durability: str = 'volatile', deadline: Mapping[str, int] | None = None,
                lifespan: Mapping[str, int] | None = None, liveliness: str = 'automatic',
                liveliness_lease_duration: Mapping[str, int] | None = None,
                avoid_ros_namespace_conventions: bool = False) -> dict[str, Any]:
    """One offered QoS profile as rosbag2 v9 writes it (policy names lower case; durations {sec, nsec})."""
    return {
        'history': history, 'depth': int(depth), 'reliability': reliability, 'durability': durability,
        'deadline': dict(deadline or DURATION_INFINITE), 'lifespan': dict(lifespan or DURATION_INFINITE),
        'liveliness': liveliness,
        'liveliness_lease_duration': dict(liveliness_lease_duration or DURATION_INFINITE),
        'avoid_ros_namespace_conventions': bool(avoid_ros_namespace_conventions),
    }


def normalize_qos_profiles(profiles: str | Sequence[Mapping[str, Any]] | None) -> list[dict[str, Any]]:
    """Parse offered QoS profiles (a YAML string, or dicts) into rosbag2 v9 form (integer policies → names)."""
    if profiles is None:
        return []
    if isinstance(profiles, str):
        if not profiles.strip():
            return []
        try:
            loaded = load_yaml(profiles)
        except yaml.YAMLError as exc:
            raise BagWriterError(f'offered QoS profiles are not valid YAML: {exc}') from None
        profiles = loaded if loaded is not None else []
    if not isinstance(profiles, (list, tuple)):
        raise BagWriterError('offered QoS profiles must be a YAML sequence of profiles')
    result: list[dict[str, Any]] = []
    for raw in profiles:
        if not isinstance(raw, Mapping):
            raise BagWriterError(f'offered QoS profile {raw!r} is not a mapping')
        profile = qos_profile()
        profile.update({k: v for k, v in raw.items() if k in QOS_KEYS})
        for key in QOS_POLICY_NAMES:
            profile[key] = policy_name(key, profile[key])
        result.append(profile)
    return result


def policy_name(key: str, value: Any) -> Any:
    """A recorded policy (``key``: one of QOS_POLICY_NAMES) by name: rosbag2's names as they are, rmw's integers
    (older bags) turned into them, ``'unknown'`` for an integer rmw does not define."""
    if isinstance(value, int) and not isinstance(value, bool):
        return QOS_POLICY_NAMES[key].get(value, 'unknown')
    return value


def recorded_qos_profiles(offered: str | Iterable[Mapping[str, Any]] | None) -> list[Mapping[str, Any]]:
    """The offered QoS profiles recorded for a topic (a YAML string, or dicts), as they are: [] for none, invalid
    YAML or not a sequence; entries that are not mappings left out (playback falls back to the topic contract)."""
    if offered is None:
        return []
    if isinstance(offered, str):
        try:
            loaded = load_yaml(offered) if offered.strip() else []
        except yaml.YAMLError:
            return []
        offered = loaded if isinstance(loaded, list) else []
    return [p for p in offered if isinstance(p, Mapping)]


def dump_qos_profiles(profiles: str | Sequence[Mapping[str, Any]] | None) -> str:
    """The YAML string rosbag2 Jazzy stores in the MCAP channel metadata ``offered_qos_profiles``.

    yaml-cpp's dump of the profile list; ``[]`` when there are none (unknown), as rosbag2 writes it.
    """
    return dump_yaml(normalize_qos_profiles(profiles))
