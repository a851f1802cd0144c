"""The load cell's full scale in the 6×6 measurement: a sample at it is not a measurement. One rule, used live
(nodes/stiffness6_estimator.py) and offline (analysis/full6_load.py, analysis/full6.py). Pure numpy.

A load cell past its range reads its full scale (the simulated one clips there, config/sensors.yaml
``load_cell.full_scale``; a real one saturates its ADC). Fitted, such a sample would bend the step means (on the
simulated rig a program past the 2 N·m full scale about x read K[mx, θ_x] 26 % off; the lack-of-fit test flagged
it as "nonlinear", not as what it was). So a wrench sample with any component in the last :data:`MARGIN` of the
range or beyond, |w_j| >= (1 − MARGIN)·full_scale_j (in the sensor's own frame, before the mounting moves it to the
platform centre; a full scale of 0 leaves its axis unchecked), is left out before pairing; the margin because a
tare shifts the reading at saturation by the bias it removed (the simulated load cell saturates the raw value,
then subtracts the tare: its mx reads 2 − 0.001 N·m there). It is counted per axis, and the fit's status says so:
never OK while any sample of the window was at full scale (WARN, the counts in the message; an ERROR stays ERROR).
"""
from __future__ import annotations

from typing import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from crane_stiffness.contract.axes import AXES
from crane_stiffness.full6.errors import Full6InputError
from crane_stiffness.contract.status import OK, WAITING, WARN

#: The last fraction of the range that counts as at full scale (a designed program stays below 0.9 of it:
#: crane_stiffness.full6.linearity).
MARGIN = 0.02


def check_full_scale(full_scale: ArrayLike) -> NDArray[np.float64]:
    """``full_scale`` as (6,) [N, N·m], each >= 0 (0: unchecked); Full6InputError naming it otherwise."""
    fs = np.asarray(full_scale, dtype=float).reshape(-1)
    if fs.shape != (6,) or not np.all(np.isfinite(fs) & (fs >= 0.0)):
        raise Full6InputError('load_cell_full_scale', fs.tolist(), 'must be 6 numbers >= 0 (N x3, N·m x3; 0 = '
                              'unchecked)')
    return fs


def full_scale_limits(full_scale: ArrayLike) -> NDArray[np.float64]:
    """The magnitude (6,) [N, N·m] from which a reading counts as at full scale: (1 − MARGIN)·full_scale, inf for
    an unchecked axis (0). Checked once (Full6InputError); :func:`at_limits` then compares samples against it."""
    fs = check_full_scale(full_scale)
    return np.where(fs > 0.0, fs * (1.0 - MARGIN), np.inf)


def at_limits(wrench: ArrayLike, limits: NDArray[np.float64]) -> NDArray[np.bool_]:
    """Per sample and axis: the wrench (n, 6) (or one, (6,)) [N, N·m], sensor frame, at or beyond ``limits``
    (:func:`full_scale_limits`); (n, 6) bool."""
    return np.abs(np.asarray(wrench, dtype=float).reshape(-1, 6)) >= limits


def at_full_scale(wrench: ArrayLike, full_scale: ArrayLike) -> NDArray[np.bool_]:
    """Per sample (n,) and axis: the wrench (n, 6) [N, N·m], sensor frame, in the last MARGIN of ``full_scale``
    (6,) or beyond; (n, 6) bool. Axes with a full scale of 0 are never at it."""
    return at_limits(wrench, full_scale_limits(full_scale))


def full_scale_note(counts: Sequence[int] | NDArray[np.int64]) -> str:
    """'load cell at full scale: 12 sample(s) left out (mx 10, my 2)'; '' for none."""
    c = np.asarray(counts, dtype=np.int64).reshape(6)
    if not c.any():
        return ''
    axes = ', '.join(f'{a} {int(n)}' for a, n in zip(AXES, c) if n)
    return f'load cell at full scale: samples left out ({axes})'


def with_full_scale(level: int, message: str, counts: Sequence[int] | NDArray[np.int64]) -> tuple[int, str]:
    """The fit's status (level, message) with the samples at full scale said: WARN at least once any was left out
    (an OK or WAITING fit), the note first; unchanged when none was."""
    note = full_scale_note(counts)
    if not note:
        return level, message
    return (WARN if level in (OK, WAITING) else level), f'{note}; {message}'


__all__ = ['MARGIN', 'at_full_scale', 'at_limits', 'check_full_scale',
           'full_scale_limits', 'full_scale_note', 'with_full_scale']
