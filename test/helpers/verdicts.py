"""A wall-clock session's exit status checked against its verdict (no ROS).

A session on the wall clock (hardware mode, drivers over the emulators) shares this machine's cores with the tests:
when the machine is busy its best-effort sensor streams lose samples, or a starved process leaves a stream silent
for a moment (the estimator then says STALE), and the session's verdict rightly says NOT OK ("never silently
wrong"). What holds at any load: the exit status is the verdict's (0 for OK, 5 for NOT OK), and NOT OK has no cause
but those; a gain, a sign, a far-from-model number or a cut bag still fails the test.
"""
from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

from crane_stiffness.cli.exit_codes import EXIT_SESSION_NOT_OK

_LOAD = re.compile(r'\blost\b|\bsilent for [0-9.]+ s\b')


def read_verdict(path: Path) -> dict[str, Any]:
    """The session's verdict.json ({} when there is none)."""
    return json.loads(path.read_text()) if path.is_file() else {}


def check_exit_and_verdict(code: int, verdict: dict[str, Any], context: str = '') -> None:
    """Assert ``code`` is the verdict's exit status and that NOT OK names nothing but lost samples or a stream
    silent for a moment."""
    assert verdict, f'no verdict (exit {code})\n{context}'
    if verdict['status'] == 'OK':
        assert code == 0, f'verdict OK, exit {code}\n{context}'
        return
    assert code == EXIT_SESSION_NOT_OK, f'verdict NOT OK, exit {code}: {verdict["reasons"]}\n{context}'
    others = [r for r in verdict['reasons'] if not _LOAD.search(r)]
    assert not others, f'NOT OK for more than what a loaded machine causes: {others}\n{context}'
