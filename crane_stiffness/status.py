"""Status levels, as diagnostic_msgs/DiagnosticStatus numbers them (OK 0, WARN 1, ERROR 2, STALE 3). The pure cores
report with them and the nodes publish them unchanged. Pure Python, no ROS import.
"""
from __future__ import annotations

OK, WARN, ERROR, STALE = 0, 1, 2, 3
#: The levels by name, for people.
NAMES = {OK: 'OK', WARN: 'WARN', ERROR: 'ERROR', STALE: 'STALE'}

__all__ = ['ERROR', 'NAMES', 'OK', 'STALE', 'WARN']
