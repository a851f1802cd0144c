"""Labelled (wrench, deflection) pairs of a six-axis session, streaming (:class:`Full6Pairing`, live) and vectorised
(:func:`full6_pairs`, offline from a bag) side by side; the tests pin them together pair by pair.

Inputs, all stamped [s] by their header stamps:

- the commands: wrench [fx, fy, fz, mx, my, mz] (N, N·m), crane_base (``/crane/wrench_command``): the load steps;
- the load cell's wrench, already at the platform centre in crane_base and as the load applied to the platform
  (crane_stiffness.estimation.frames.SensorMount), the *fast* stream (1 kHz);
- the pose sensor's pose: position (3,) [m] and orientation quaternion [x, y, z, w] (body → crane_base), the *slow*
  stream (250 Hz), turned into the deflection d (6,) [m, rad] of crane_stiffness.full6.deflection relative to the
  rest pose: the first finite pose received unless one is given. The fit's offset absorbs where the rest is.

**Rule.** Each pose sample is paired with the wrench linearly interpolated at its stamp
(crane_stiffness.estimation.sync.InterpolatingSync: the same admission, ``max_gap`` and ``max_age`` rules), and the
pair is labelled with the load step in force at its stamp (crane_stiffness.full6.steps, ``settle_s``). Pairs
without a step (settling, ramps, before the first command, after the last) are not returned.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from crane_stiffness.estimation.sync import FORCE, InterpolatingSync, pair_by_interpolation
from crane_stiffness.full6.deflection import pose_deflection
from crane_stiffness.full6.steps import NO_STEP, StepLabeller, label_steps
from crane_stiffness.model.rotation import quaternion_to_matrix

#: Pose samples and their wrench must be this close: wider brackets of the 1 kHz wrench are dropouts [s].
DEFAULT_MAX_GAP_S = 0.005
#: A pose sample further behind the newest wrench than this is stale, as in the 1-D estimator [s].
DEFAULT_MAX_AGE_S = 0.5


@dataclass(frozen=True)
class Rest:
    """The pose deflections are measured from: centre position (3,) [m] and rotation matrix (3, 3), crane_base."""

    position: NDArray[np.float64]
    rotation: NDArray[np.float64]

    @classmethod
    def of(cls, position: ArrayLike, quaternion: ArrayLike) -> 'Rest':
        return cls(np.asarray(position, dtype=float).reshape(3).copy(),
                   quaternion_to_matrix(np.asarray(quaternion, dtype=float).reshape(4)))


def deflections(position: ArrayLike, quaternion: ArrayLike, rest: Rest) -> NDArray[np.float64]:
    """Deflections (n, 6) [m, rad] of poses (position (n, 3) [m], quaternion (n, 4) [x, y, z, w]) from ``rest``."""
    q = np.asarray(quaternion, dtype=float).reshape(-1, 4)
    rotation = np.stack([quaternion_to_matrix(row) for row in q]) if q.size else np.zeros((0, 3, 3))
    return pose_deflection(np.asarray(position, dtype=float).reshape(-1, 3), rotation, rest.position, rest.rotation)


@dataclass(frozen=True)
class LabelledPairs:
    """Pairs in stamp order: stamp (n,) [s], wrench (n, 6) [N, N·m], deflection (n, 6) [m, rad], step (n,)."""

    stamp: NDArray[np.float64]
    wrench: NDArray[np.float64]
    deflection: NDArray[np.float64]
    step: NDArray[np.int64]

    def __len__(self) -> int:
        return int(self.stamp.size)


def full6_pairs(command_stamp: ArrayLike, command_wrench: ArrayLike, wrench_stamp: ArrayLike, wrench_log: ArrayLike,
                wrench: ArrayLike, pose_stamp: ArrayLike, pose_log: ArrayLike, position: ArrayLike,
                quaternion: ArrayLike, *, settle_s: float, max_gap_s: float = DEFAULT_MAX_GAP_S,
                max_age_s: float = DEFAULT_MAX_AGE_S, rest: Rest | None = None) -> LabelledPairs:
    """The pairs :class:`Full6Pairing` returns for the same samples, at once.

    Streams in arrival order (``*_log``: the arrival or log times, ascending, which decide what is stale as live);
    commands in stamp order; non-finite samples already left out (as the node drops them before pairing)."""
    ws = np.asarray(wrench_stamp, dtype=float).reshape(-1)
    ps = np.asarray(pose_stamp, dtype=float).reshape(-1)
    pos = np.asarray(position, dtype=float).reshape(-1, 3)
    quat = np.asarray(quaternion, dtype=float).reshape(-1, 4)
    if rest is None:
        if ps.size == 0:
            return _empty()
        rest = Rest.of(pos[0], quat[0])
    d = deflections(pos, quat, rest)
    result = pair_by_interpolation(ws, np.asarray(wrench_log, dtype=float).reshape(-1), ps,
                                   np.asarray(pose_log, dtype=float).reshape(-1), FORCE,
                                   np.asarray(wrench, dtype=float).reshape(-1, 6), max_gap_s, max_age_s)
    labels = label_steps(command_stamp, command_wrench, result.stamp, settle_s)
    keep = labels != NO_STEP
    return LabelledPairs(result.stamp[keep], np.asarray(result.fast_value, dtype=float).reshape(-1, 6)[keep],
                         d[result.slow_index[keep]], labels[keep])


def _empty() -> LabelledPairs:
    return LabelledPairs(np.zeros(0), np.zeros((0, 6)), np.zeros((0, 6)), np.zeros(0, dtype=np.int64))


class Full6Pairing:
    """:func:`full6_pairs` one sample at a time: :meth:`command`, :meth:`wrench`, :meth:`pose` as they arrive;
    each returns the pairs that became labelled (list of (stamp [s], wrench (6,), deflection (6,), step))."""

    def __init__(self, *, settle_s: float, max_gap_s: float = DEFAULT_MAX_GAP_S,
                 max_age_s: float = DEFAULT_MAX_AGE_S, rest: Rest | None = None) -> None:
        self.settings = (settle_s, max_gap_s, max_age_s)
        self.labeller = StepLabeller(settle_s)
        self.sync = InterpolatingSync(FORCE, max_gap=max_gap_s, max_age=max_age_s, dropout_factor=None)
        self.rest = rest
        self._waiting: deque[tuple[float, NDArray[np.float64], NDArray[np.float64]]] = deque()  # paired, unlabelled
        self.unlabelled = 0  # pairs that fell in no step (settling, ramps)

    def command(self, stamp_s: float, wrench: ArrayLike) -> list[tuple[float, NDArray[np.float64],
                                                                       NDArray[np.float64], int]]:
        self.labeller.command(stamp_s, wrench)
        return self._label()

    def wrench(self, stamp_s: float, wrench: ArrayLike) -> list[tuple[float, NDArray[np.float64],
                                                                      NDArray[np.float64], int]]:
        for pair in self.sync.push(FORCE, stamp_s, np.asarray(wrench, dtype=float).reshape(6)):
            self._waiting.append((pair.stamp_s, np.asarray(pair.force, dtype=float), pair.displacement))
        return self._label()

    def pose(self, stamp_s: float, position: ArrayLike, quaternion: ArrayLike) -> list[
            tuple[float, NDArray[np.float64], NDArray[np.float64], int]]:
        if self.rest is None:
            self.rest = Rest.of(position, quaternion)
        d = deflections(position, quaternion, self.rest)[0]
        for pair in self.sync.push('displacement', stamp_s, d):
            self._waiting.append((pair.stamp_s, np.asarray(pair.force, dtype=float), pair.displacement))
        return self._label()

    def _label(self) -> list[tuple[float, NDArray[np.float64], NDArray[np.float64], int]]:
        out = []
        while self._waiting:
            stamp, w, d = self._waiting[0]
            step = self.labeller.label(stamp)
            if step is None:
                break  # pairs come in stamp order: the later ones wait too
            self._waiting.popleft()
            if step == NO_STEP:
                self.unlabelled += 1
            else:
                out.append((stamp, w, d, step))
        return out

    @property
    def waiting(self) -> int:
        """Pairs formed but not yet labelled (no command after them yet)."""
        return len(self._waiting)

    def reset(self) -> None:
        """Start again (the rest pose too)."""
        settle_s, max_gap_s, max_age_s = self.settings
        self.__init__(settle_s=settle_s, max_gap_s=max_gap_s, max_age_s=max_age_s)  # type: ignore[misc]


__all__ = ['DEFAULT_MAX_AGE_S', 'DEFAULT_MAX_GAP_S', 'Full6Pairing', 'LabelledPairs', 'Rest', 'deflections',
           'full6_pairs']
