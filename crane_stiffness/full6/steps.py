"""The load step a pair belongs to, from the commanded wrench: the label the 6×6 fit groups pairs by
(crane_stiffness.full6.statistics), streaming (:class:`StepLabeller`, live) and vectorised (:func:`label_steps`,
offline) side by side; the tests pin them together.

**Rule.** The commands (``/crane/wrench_command``, [fx, fy, fz, mx, my, mz] in N and N·m, stamped) are cut into
*stretches* of one wrench: a stretch starts at the stamp of every command whose wrench differs from the previous
command's (the first command starts stretch 0), and stretches are numbered in time order. A pair stamped t belongs to
the stretch in force at t (the last one started at or before t) once the stretch has held for ``settle_s``
(t − start ≥ settle_s: the platform has settled after the step); earlier in the stretch, before the first command,
during a ramp (every command a new wrench, so no stretch lasts ``settle_s``), or at or after the last command (see
below) the pair has no label (−1) and is not fitted. A ramp's stretches are numbered too, so labels need not be
consecutive; the fit takes any integers.

Live, the label of a pair stamped t is known only once a command stamped after t has arrived (a step at t' ≤ t
may still be on its way): :meth:`StepLabeller.label` answers None until then. The load program commands
continuously (every 1 / ``rate_hz``), so a pair waits at most one command period.
"""
from __future__ import annotations

import bisect
import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from crane_stiffness.full6.errors import Full6InputError

#: No label: before the first command, or within ``settle_s`` of a step.
NO_STEP = -1


def _check_settle(settle_s: float) -> float:
    if not (isinstance(settle_s, (int, float)) and math.isfinite(settle_s) and settle_s >= 0.0):
        raise Full6InputError('settle_s', settle_s, 'must be a finite number >= 0 (s)')
    return float(settle_s)


def stretch_starts(command_stamp: ArrayLike, command_wrench: ArrayLike) -> NDArray[np.float64]:
    """The start stamps [s] of the stretches of constant wrench of commands in stamp order (``command_stamp`` (n,),
    ``command_wrench`` (n, 6))."""
    stamp = np.asarray(command_stamp, dtype=float).reshape(-1)
    wrench = np.asarray(command_wrench, dtype=float).reshape(stamp.size, -1)
    if stamp.size == 0:
        return stamp
    if np.any(np.diff(stamp) < 0.0):
        raise Full6InputError('command_stamp', 'not ascending', 'commands must be in stamp order')
    new = np.ones(stamp.size, dtype=bool)
    new[1:] = np.any(wrench[1:] != wrench[:-1], axis=1)
    return stamp[new]


def label_steps(command_stamp: ArrayLike, command_wrench: ArrayLike, stamp: ArrayLike,
                settle_s: float) -> NDArray[np.int64]:
    """Labels (m,) of pairs stamped ``stamp`` (m,) [s]: the index of the stretch in force, or :data:`NO_STEP`."""
    settle = _check_settle(settle_s)
    starts = stretch_starts(command_stamp, command_wrench)
    t = np.asarray(stamp, dtype=float).reshape(-1)
    index = np.searchsorted(starts, t, side='right') - 1
    newest = float(np.max(command_stamp)) if starts.size else -math.inf
    ok = (index >= 0) & (t < newest)  # as live: a pair is labelled once a command stamped after it is in
    settled = np.zeros(t.size, dtype=bool)
    settled[ok] = t[ok] - starts[index[ok]] >= settle
    return np.where(ok & settled, index, NO_STEP).astype(np.int64)


class StepLabeller:
    """:func:`label_steps` one command and one pair at a time (commands in stamp order, pairs in any order)."""

    def __init__(self, settle_s: float) -> None:
        self.settle_s = _check_settle(settle_s)
        self._starts: list[float] = []
        self._last_wrench: tuple[float, ...] | None = None
        self.newest_command_s = -math.inf

    def command(self, stamp_s: float, wrench: ArrayLike) -> None:
        """A command [s; N, N·m]; one older than the newest is ignored (out of order: the offline rule, which sorts,
        would place it elsewhere; the load program never sends one)."""
        if not stamp_s >= self.newest_command_s:
            return
        w = tuple(float(v) for v in np.asarray(wrench, dtype=float).reshape(-1))
        if w != self._last_wrench:
            self._starts.append(float(stamp_s))
            self._last_wrench = w
        self.newest_command_s = float(stamp_s)

    def label(self, stamp_s: float) -> int | None:
        """The label of a pair stamped ``stamp_s``, or None while no command stamped after it has arrived."""
        if not stamp_s < self.newest_command_s:
            return None
        i = bisect.bisect_right(self._starts, stamp_s) - 1
        if i < 0 or stamp_s - self._starts[i] < self.settle_s:
            return NO_STEP
        return i

    @property
    def stretches(self) -> int:
        """Stretches started so far."""
        return len(self._starts)

    def reset(self) -> None:
        self.__init__(self.settle_s)  # type: ignore[misc]


__all__ = ['NO_STEP', 'StepLabeller', 'label_steps', 'stretch_starts']
