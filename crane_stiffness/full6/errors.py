"""Errors raised by the full6 package (designed multi-axis load programs and the 6×6 identification)."""
from __future__ import annotations

from crane_stiffness.errors import CraneStiffnessError, FieldError


class Full6Error(CraneStiffnessError):
    """Base class of the full6 package's errors."""


class Full6InputError(Full6Error, FieldError):
    """A bad value for a design or an identification: names the field, the value and the rule it breaks."""


class ArrangementError(Full6Error):
    """An arrangement of displacement sensors (crane_stiffness.full6.lvdt_array) that cannot determine the pose.

    Attributes:
        name: the arrangement's name.
        rank: how many independent motions it sees (6 determines the pose).
        condition: the condition number of its scaled, noise-weighted Jacobian (inf when rank < 6).
        unseen: the motion it sees least, as a unit 6-vector [u_x, u_y, u_z, L·θ_x, L·θ_y, L·θ_z] (L the
            arrangement's radius) [-]; None when there are fewer than six sensors.
    """

    def __init__(self, message: str, *, name: str, rank: int, condition: float, unseen=None) -> None:
        super().__init__(message)
        self.name = name
        self.rank = rank
        self.condition = condition
        self.unseen = unseen


class SlackDesignError(Full6Error):
    """A load program that would slacken a wire, or come closer to slack than its safety factor allows.

    Attributes:
        step: index of the offending step, 0-based, in play order (the message counts from 1).
        wrench: that step's wrench [fx, fy, fz, mx, my, mz] (6,) [N, N·m], fixed frame, z down; for a transition,
            the point of the straight path between two steps that was checked.
        direction: the wrench's unit vector (6,) (components in N and N·m, normalised together).
        wire: index 0..5 of the wire that goes slack first along that direction (−1: none; the platform loses
            equilibrium first).
        wire_name: its name, e.g. ``'wire_4 (CE)'``.
        factor: the slack factor: loading along the direction slackens that wire at ``factor`` times the wrench.
        safety_factor: the factor every wrench must keep.
        transition: True when the point is on the straight path from step ``step`` to the next one.
    """

    def __init__(self, message: str, *, step: int, wrench, direction, wire: int, wire_name: str, factor: float,
                 safety_factor: float, transition: bool = False) -> None:
        super().__init__(message)
        self.step = step
        self.wrench = wrench
        self.direction = direction
        self.wire = wire
        self.wire_name = wire_name
        self.factor = factor
        self.safety_factor = safety_factor
        self.transition = transition


__all__ = ['ArrangementError', 'Full6Error', 'Full6InputError', 'SlackDesignError']
