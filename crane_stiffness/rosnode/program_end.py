"""When a recording of a test program ends (session_recorder's ``stop_on_program_done``): the program's state as the
recorder reads it from /load_program/state, and the instant its session ends.

On simulated time with the lock-step the session ends at the instant the load program fixed when it started (the
clock's ``end``, announced with its watermarks): the recorder closes the bag once its own watermark reaches it, with
every message the rig published through it and nothing later, the same at any speed and load. Otherwise (the wall
clock, or a clock that announces no end) it closes ``stop_delay_s`` after the program said 'done'.
"""
from __future__ import annotations

import json
from typing import Any


class ProgramEnd:
    """The program's state for one recording: whether it ran, whether it is done, its last state (a JSON object)."""

    def __init__(self) -> None:
        self.ran = False
        self.done = False
        self.state: dict[str, Any] = {}

    def read(self, text: str) -> bool:
        """A /load_program/state message's text; True when it is the first 'done' after the program ran (the
        recording's end is then due). Text that is not a JSON object is ignored."""
        try:
            state = json.loads(text)
        except ValueError:
            return False
        if not isinstance(state, dict):
            return False
        self.state = state
        if state.get('state') in ('running', 'paused'):
            self.ran = True
        elif state.get('state') == 'done' and self.ran and not self.done:
            self.done = True
            return True
        return False

    def end_ns(self, lockstep: bool, clock_end_ns: int | None) -> int | None:
        """Where the session ends on simulated time [ns]: the clock's end, once the program is done, with the
        lock-step (``lockstep``: its watermarks heard) and a clock that announced its end; else None (a timer of
        ``stop_delay_s`` ends it)."""
        return clock_end_ns if self.done and lockstep and clock_end_ns is not None else None
