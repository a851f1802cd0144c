"""Simulated time that advances only as fast as the simulated rig keeps up (pure Python, no ROS).

The simulated rig is a chain of stages: the load program (stage 0) commands, the crane model (1) turns commands into
the load in force and the pose, the sensors (2) sample them, the estimators (3) consume the samples, and the recorder
(4) records all of it, the estimators' outputs included.
Each participant reports its *progress*: the simulated time through which it has published everything (its outputs
acknowledged by every reliable reader). The clock source publishes, with the time itself, one *watermark* per stage:
the time through which every participant of the stages below has published. A participant of stage s works only up
to the watermark of stage s, so it never acts on an input that may still be in flight: a sensor samples instant t
only when the load in force at t is known, whatever the delivery delays.

The clock advances one step at a time (``step_ns``), never more than ``max_lead_ns`` ahead of the slowest
participant, and at most ``real_time_factor`` times as fast as the wall clock (0: as fast as the rig keeps up).
A busy machine therefore slows simulated time instead of losing samples, and what the rig computes does not depend
on the machine's speed.

Units: integer nanoseconds of simulated time (``*_ns``) and of the wall clock (``wall_ns``).
"""
from __future__ import annotations

from dataclasses import dataclass, field

from crane_stiffness.sim.errors import ParameterError

#: The progress a participant reports when it leaves (its node ends): it is waited for no more. The largest time a
#: ROS stamp holds (int32 seconds).
LEFT_NS = (2 ** 31 - 1) * 1_000_000_000
#: Stages of the simulated rig (see the module docstring); a participant reports its stage with its progress.
STAGES = 5


@dataclass
class Participant:
    """One node of the simulated rig as the clock sees it."""

    name: str
    stage: int = -1          #: -1 until it first reports
    progress_ns: int = -1    #: -1 until it first reports

    @property
    def heard(self) -> bool:
        return self.progress_ns >= 0

    @property
    def left(self) -> bool:
        return self.progress_ns == LEFT_NS


@dataclass
class LockstepClock:
    """Simulated time paced by the wall clock and held back by the slowest participant.

    Args:
        participants: Names of the nodes that must report before time starts and that time waits for.
        start_ns: Simulated time at start, ns (> 0: a zero stamp means "no stamp" to the rig's nodes).
        step_ns: Resolution of simulated time, ns (> 0); every published time is a multiple of it.
        real_time_factor: Simulated seconds per wall second, ≥ 0; 0 = as fast as the participants keep up.
        max_lead_ns: How far time may run ahead of the slowest participant's progress, ns (≥ step_ns).
    """

    participants: list[str]
    start_ns: int
    step_ns: int
    real_time_factor: float
    max_lead_ns: int
    now_ns: int = field(init=False)
    table: dict[str, Participant] = field(init=False)
    _anchor: tuple[int, int] | None = field(init=False, default=None)  # (wall ns, simulated ns) of the pacing
    held: int = field(init=False, default=0)  #: advances the participants held back (the wall clock allowed more)
    #: Where time stops, ns (a run with a known end: every run then ends at the same simulated time); None: never.
    end_ns: int | None = field(init=False, default=None)

    def __post_init__(self) -> None:
        if not self.participants:
            raise ParameterError('participants', self.participants, 'must name at least one node')
        if self.step_ns <= 0:
            raise ParameterError('step_ns', self.step_ns, 'must be > 0')
        if self.start_ns <= 0 or self.start_ns % self.step_ns:
            raise ParameterError('start_ns', self.start_ns, f'must be > 0 and a multiple of the step {self.step_ns}')
        if not self.real_time_factor >= 0.0:
            raise ParameterError('real_time_factor', self.real_time_factor, 'must be >= 0 (0 = as fast as possible)')
        if self.max_lead_ns < self.step_ns:
            raise ParameterError('max_lead_ns', self.max_lead_ns, f'must be >= the step {self.step_ns}')
        self.now_ns = self.start_ns
        self.table = {name: Participant(name) for name in dict.fromkeys(self.participants)}

    # --- participants ---
    def report(self, name: str, stage: int, progress_ns: int) -> bool:
        """A participant's progress; True if ``name`` is one of the participants (others are ignored)."""
        p = self.table.get(name)
        if p is None:
            return False
        if not 0 <= stage < STAGES:
            raise ParameterError('stage', stage, f'must be in 0 .. {STAGES - 1}')
        p.stage = stage
        p.progress_ns = max(p.progress_ns, int(progress_ns))
        return True

    def repace(self) -> None:
        """The pace changed (real_time_factor): pace on from now, at the new factor."""
        self._anchor = None

    def done_ns(self) -> int:
        """The time through which every participant still there has published (the clock when all have left)."""
        running = [p.progress_ns for p in self.table.values() if not p.left]
        return min(running) if running else self.now_ns

    def missing(self) -> list[str]:
        """Participants not heard from yet (time does not start before they are all there)."""
        return [p.name for p in self.table.values() if not p.heard]

    def slowest(self) -> Participant | None:
        """The participant with the least progress (None when every one has left)."""
        running = [p for p in self.table.values() if not p.left]
        return min(running, key=lambda p: p.progress_ns) if running else None

    def watermarks(self) -> list[int]:
        """Per stage s: the time through which every participant of the stages below s has published, ns (stage 0:
        the clock itself). Never beyond the clock."""
        marks = []
        for s in range(STAGES):
            below = [p.progress_ns for p in self.table.values() if 0 <= p.stage < s and not p.left]
            marks.append(min([self.now_ns, *below]))
        return marks

    # --- time ---
    def advance(self, wall_ns: int) -> bool:
        """Move time on as far as the wall clock and the participants allow (a whole number of steps); True if it
        moved. Nothing moves before every participant has reported once."""
        if self.missing():
            self._anchor = None
            return False
        slowest = self.slowest()
        allowed = LEFT_NS if slowest is None else slowest.progress_ns + self.max_lead_ns
        target = allowed
        if self.real_time_factor > 0.0:
            if self._anchor is None:
                self._anchor = (wall_ns, self.now_ns)
            wall0, sim0 = self._anchor
            paced = sim0 + int((wall_ns - wall0) * self.real_time_factor)
            target = min(paced, allowed)
            if paced > allowed:  # held back: pace on from where it is held, do not rush to catch up afterwards
                self.held += 1
                self._anchor = (wall_ns, max(self.now_ns, (target // self.step_ns) * self.step_ns))
        if self.end_ns is not None:
            target = min(target, self.end_ns)
        new = (target // self.step_ns) * self.step_ns
        if new <= self.now_ns:
            return False
        self.now_ns = new
        return True
