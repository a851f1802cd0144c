"""Who asked a rig node to act: the control events that name the caller of a service. Pure Python, no ROS.

A ``std_srvs/Trigger`` request is empty and ROS 2 tells a service nothing about its client, so the services that cut
a session or a fit short (the recorder's ``~/stop``, the load cell's ``~/tare``, the estimator's ``~/reset``) cannot
know who called. A caller that can say who it acts for announces the call first: it publishes one control event on
:data:`CONTROL_EVENTS` (``std_msgs/String``, JSON, reliable and transient local, :data:`CONTROL_EVENTS_QOS`), waits
until every reader has acknowledged it, then calls. The live view does so for every call forwarded from its WebSocket,
naming the client's address and its ``Origin``. The node serving the call takes the newest event for its service not
older than :data:`MAX_AGE_S` and not used before (:class:`ControlCallers`); without one the caller is
:data:`ROS_CALLER`: a plain ROS service client, which may be anyone on this machine's DDS domain.

An event's JSON: ``{"service": "/session_recorder/stop", "by": "…", "via": "/live_view", "stamp_ns": <wall clock,
ns since the epoch>, "id": "<unique>"}``. A claim, not a proof: any process of the domain may publish one, as it may
call the service itself; it tells the lab who asked through the view, which checked the client's token.
"""
from __future__ import annotations

import json
import math
from typing import Any

from crane_stiffness.contract.topics import QoS

#: The topic of control events (std_msgs/String holding the JSON above).
CONTROL_EVENTS = '/rig/control_events'
CONTROL_EVENTS_TYPE = 'std_msgs/msg/String'
#: Reliable and transient local: a serving node that matched late still gets the recent events.
CONTROL_EVENTS_QOS = QoS('reliable', 'transient_local', 20)
#: An event older than this [s, wall clock] names no call: the call it announced was answered long since (the view
#: waits at most its service_timeout_s, 5 s by default) or never arrived.
MAX_AGE_S = 15.0
#: session_recorder's exit status when a ~/stop call cut its last recording while the rig's program had not finished
#: (the bag is not the whole run, bag.session_metadata.cut_short): a launch ends non-zero naming it
#: (launcher.rig_description.exit_problem). A recording started and stopped by hand, without a program, is no cut.
RECORDER_CUT_STATUS = 3
#: Who called when no event names the caller.
ROS_CALLER = 'a ROS service client (not through the live view: a std_srvs/Trigger call names no caller)'
_FIELDS = ('service', 'by', 'via', 'stamp_ns', 'id')


def control_event(service: str, by: str, via: str, stamp_ns: int, event_id: str) -> str:
    """The JSON of an event announcing that ``by`` (a client, in words) calls ``service`` through ``via`` (the
    announcing node) at ``stamp_ns`` (wall clock, ns since the epoch)."""
    return json.dumps({'service': service, 'by': by, 'via': via, 'stamp_ns': int(stamp_ns), 'id': event_id})


def read_event(text: str) -> dict[str, Any] | None:
    """An event's fields, or None when ``text`` is not one (not JSON, a field missing or of the wrong type)."""
    try:
        event = json.loads(text)
    except ValueError:
        return None
    if not isinstance(event, dict) or any(f not in event for f in _FIELDS):
        return None
    if not all(isinstance(event[f], str) for f in ('service', 'by', 'via', 'id')) or \
            not isinstance(event['stamp_ns'], int):
        return None
    return event


class ControlCallers:
    """The events a serving node has received, and who called each of its services."""

    def __init__(self, keep: int = 64) -> None:
        self._events: list[dict[str, Any]] = []
        self._used: set[str] = set()
        self._keep = keep
        self.ignored = 0  # messages that were no event

    def add(self, text: str) -> bool:
        """One message of :data:`CONTROL_EVENTS`; False (counted) when it is no event."""
        event = read_event(text)
        if event is None:
            self.ignored += 1
            return False
        if all(e['id'] != event['id'] for e in self._events):
            self._events = (self._events + [event])[-self._keep:]
        return True

    def caller(self, service: str, now_ns: int) -> str:
        """Who calls ``service`` now (``now_ns``: wall clock, ns since the epoch): the ``by`` of the newest unused
        event for it at most :data:`MAX_AGE_S` old (marked used), else :data:`ROS_CALLER`."""
        for event in reversed(self._events):
            age_s = (now_ns - event['stamp_ns']) * 1e-9
            if event['service'] != service or event['id'] in self._used or not -1.0 <= age_s <= MAX_AGE_S \
                    or not math.isfinite(age_s):
                continue
            self._used.add(event['id'])
            return f"{event['by']} (through {event['via']})"
        return ROS_CALLER


__all__ = ['CONTROL_EVENTS', 'CONTROL_EVENTS_QOS', 'CONTROL_EVENTS_TYPE', 'ControlCallers', 'MAX_AGE_S', 'ROS_CALLER',
           'control_event', 'read_event']
