"""Status levels, as diagnostic_msgs/DiagnosticStatus numbers them (OK 0, WARN 1, ERROR 2, STALE 3), and WAITING:
a part that has not begun (no data for it yet). The pure cores report with them and the nodes publish them. Pure
Python, no ROS import.

What each means to the people at the rig:

- WAITING: not begun, nothing wrong: the unloading branch during the first loading ramp, the inputs before the first
  sample. It has no diagnostic_msgs number: it is published as OK with a message that starts with
  :data:`WAITING_PREFIX` (:func:`wire_level`), and read back from the two (:func:`read_level`).
- OK, WARN, ERROR: as diagnostic_msgs means them.
- STALE: data that was flowing stopped (a silent sensor): the numbers shown are frozen.

A part that does not apply to the run (the one-axis estimate in a six-axis program) is no level of its own: it is
OK with a message that starts with :data:`NOT_APPLICABLE_PREFIX` and says where the run's result is.

The overall status of several parts (:func:`overall`) is the worst of them in the order WAITING < OK < WARN < ERROR <
STALE: a part that waits never makes it worse than the parts that are running, and it reads WAITING only when every
part waits.
"""
from __future__ import annotations

from collections.abc import Iterable

OK, WARN, ERROR, STALE = 0, 1, 2, 3
#: Not begun (not a diagnostic_msgs level: published as OK, the message starting with WAITING_PREFIX).
WAITING = -1
#: The levels by name, for people.
NAMES = {WAITING: 'WAITING', OK: 'OK', WARN: 'WARN', ERROR: 'ERROR', STALE: 'STALE'}
#: How the message of a WAITING status starts, on the wire and for people.
WAITING_PREFIX = 'waiting: '
#: How the message of a status starts whose part does not apply to the run (the one-axis fit of a six-axis
#: program): level OK, nothing wrong and nothing to stand by; the message says where to look instead.
NOT_APPLICABLE_PREFIX = 'not applicable: '


def wire_level(level: int) -> int:
    """``level`` as a diagnostic_msgs/DiagnosticStatus level (0..3): WAITING is published as OK."""
    return OK if level == WAITING else level


def read_level(level: int, message: str) -> int:
    """The level of a published status (its diagnostic_msgs ``level`` and ``message``): WAITING for an OK whose
    message starts with :data:`WAITING_PREFIX`, else ``level``."""
    return WAITING if level == OK and message.startswith(WAITING_PREFIX) else level


def overall(levels: Iterable[int]) -> int:
    """The overall level of several parts: the worst (WAITING < OK < WARN < ERROR < STALE); WAITING with none."""
    return max(levels, default=WAITING)


def status_value(value: float) -> str:
    """A number as a status's key/value string (6 significant digits; 'nan' for no value)."""
    return f'{value:.6g}'


__all__ = ['ERROR', 'NAMES', 'NOT_APPLICABLE_PREFIX', 'OK', 'STALE', 'WAITING', 'WAITING_PREFIX', 'WARN', 'overall',
           'read_level', 'status_value', 'wire_level']
