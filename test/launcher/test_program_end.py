"""How long a session waits for its program (crane_stiffness.launcher.rig.wait_for_program_end): on simulated time
a busy machine slows the rig down, so a program that keeps advancing is waited for past its length however slow it
is; one whose progress stops fails the session, naming where it stopped. Stand-ins for the processes and the rig
observer: the rule, not the rig, is under test (the rig runs it in every campaign test)."""
from __future__ import annotations

import pytest

from crane_stiffness.launcher.rig import wait_for_program_end
from crane_stiffness.launcher.rosrun import RosRunError


class _Program:
    """load_program's process: exits with status 0 once told to."""

    def __init__(self) -> None:
        self.code: int | None = None

    def poll(self) -> int | None:
        return self.code


class _Procs:
    def __init__(self) -> None:
        self.procs = {'load_program': _Program()}

    def check_alive(self, allow_exit=()) -> None:
        pass

    def log(self, name: str) -> str:
        return f'{name} log'


class _Observer:
    """Each spin advances the program by ``step`` (0: stuck) until ``end_after`` spins, then load_program exits."""

    def __init__(self, procs: _Procs, step: float, end_after: int | None) -> None:
        self.procs, self.step, self.end_after = procs, step, end_after
        self.progress = 0.0
        self.state: dict = {'state': 'running'}  # the program's latest state message: running, never holding
        self.spins = 0

    def spin_once(self, timeout_sec: float) -> None:
        self.spins += 1
        self.progress = min(1.0, self.progress + self.step)
        if self.end_after is not None and self.spins >= self.end_after:
            self.procs.procs['load_program'].code = 0


def test_a_program_that_keeps_advancing_is_waited_for_past_its_length():
    procs = _Procs()
    observer = _Observer(procs, step=1e-4, end_after=30)  # 30 spins of 0.1 s: well past a length of 0 and margin 0
    seen = []
    wait_for_program_end(procs, observer, duration_s=0.0, progress=seen.append, margin_s=0.0, stall_s=2.0)
    assert observer.spins == 30 and seen[-1] == pytest.approx(30e-4)


def test_a_program_whose_progress_stops_fails_the_session_naming_where():
    procs = _Procs()
    observer = _Observer(procs, step=0.0, end_after=None)
    observer.progress = 0.4
    with pytest.raises(RosRunError, match=r'load_program did not finish \(its progress stayed at 0\.400 for \d+ s\)'):
        wait_for_program_end(procs, observer, duration_s=0.0, margin_s=0.0, stall_s=0.3)


def test_a_failed_program_is_reported_at_once():
    procs = _Procs()
    procs.procs['load_program'].code = 2
    with pytest.raises(RosRunError, match=r'load_program did not finish: load_program log'):
        wait_for_program_end(procs, _Observer(procs, step=0.0, end_after=None), duration_s=100.0)
