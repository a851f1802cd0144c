"""Status levels, as diagnostic_msgs/DiagnosticStatus numbers them (OK 0, WARN 1, ERROR 2, STALE 3). The pure cores
report with them and the nodes publish them unchanged. Pure Python, no ROS import.
"""
from __future__ import annotations

OK, WARN, ERROR, STALE = 0, 1, 2, 3
#: The levels by name, for people.
NAMES = {OK: 'OK', WARN: 'WARN', ERROR: 'ERROR', STALE: 'STALE'}



def status_value(value: float) -> str:
    """A number as a status's key/value string (6 significant digits; 'nan' for no value)."""
    return f'{value:.6g}'


__all__ = ['ERROR', 'NAMES', 'OK', 'STALE', 'WARN', 'status_value']
