"""Who asked: the control events that name a service's caller (contract.control_events), without ROS."""
from __future__ import annotations

from crane_stiffness.contract.control_events import MAX_AGE_S, ROS_CALLER, ControlCallers, control_event, read_event

NOW = 1_800_000_000 * 10**9  # ns since the epoch
STOP = '/session_recorder/stop'


def _event(service: str = STOP, by: str = 'client A', age_s: float = 0.5, event_id: str = 'a') -> str:
    return control_event(service, by, '/live_view', NOW - int(age_s * 1e9), event_id)


def test_an_announced_call_names_its_caller_once() -> None:
    callers = ControlCallers()
    assert callers.add(_event())
    assert callers.caller(STOP, NOW) == 'client A (through /live_view)'
    # used: the next call, not announced, is a plain ROS client's
    assert callers.caller(STOP, NOW) == ROS_CALLER


def test_an_event_names_only_its_own_service_and_only_while_fresh() -> None:
    callers = ControlCallers()
    callers.add(_event(service='/load_cell/tare', event_id='t'))
    callers.add(_event(age_s=MAX_AGE_S + 1.0, event_id='old'))
    assert callers.caller(STOP, NOW) == ROS_CALLER  # the tare's event names no stop; the other is too old
    assert callers.caller('/load_cell/tare', NOW) == 'client A (through /live_view)'


def test_the_newest_event_wins_and_a_repeated_one_counts_once() -> None:
    callers = ControlCallers()
    callers.add(_event(by='first', age_s=3.0, event_id='1'))
    callers.add(_event(by='second', age_s=1.0, event_id='2'))
    callers.add(_event(by='second', age_s=1.0, event_id='2'))  # the same event delivered twice (transient local)
    assert callers.caller(STOP, NOW).startswith('second')
    assert callers.caller(STOP, NOW).startswith('first')
    assert callers.caller(STOP, NOW) == ROS_CALLER


def test_what_is_no_event_is_counted_not_believed() -> None:
    callers = ControlCallers()
    for text in ('not json', '[]', '{"service": "/session_recorder/stop", "by": "x"}',
                 '{"service": 1, "by": "x", "via": "v", "stamp_ns": 1, "id": "i"}'):
        assert not callers.add(text) and read_event(text) is None
    assert callers.ignored == 4 and callers.caller(STOP, NOW) == ROS_CALLER
