"""The absurd-command rule, shared by the crane model (which rejects such a command) and the stiffness estimator
(which excludes the time it was in force from the fit): ONE module, the streaming and the vectorised form side by
side, pinned together by ``test/contract/test_command_limits.py``.

A command is a wrench [fx, fy, fz, mx, my, mz] on the platform, frame ``crane_base`` (z down), in N and N·m. It is
absurd when a component is not finite (NaN, ±inf) or a force component exceeds ``max_abs_force`` [N] or a moment
component exceeds ``max_abs_moment`` [N·m] in magnitude. Pure numpy, no ROS import.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from .axes import AXES
from crane_stiffness.errors import FieldError


@dataclass(frozen=True)
class CommandLimits:
    """The largest magnitudes a sane command may have: ``max_abs_force`` [N] on fx, fy, fz and ``max_abs_moment``
    [N·m] on mx, my, mz. Both must be finite and > 0."""

    max_abs_force: float = 1e4
    max_abs_moment: float = 1e3

    def __post_init__(self) -> None:
        for name in ('max_abs_force', 'max_abs_moment'):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and np.isfinite(value) and value > 0):
                raise FieldError(name, value, 'must be a finite number > 0')

    def bounds(self) -> np.ndarray:
        """The six per-component limits [N, N, N, N·m, N·m, N·m] in the order of
        :data:`crane_stiffness.contract.axes.AXES`."""
        return np.array([self.max_abs_force] * 3 + [self.max_abs_moment] * 3, dtype=float)


def _as_wrench(wrench: ArrayLike) -> np.ndarray:
    w = np.asarray(wrench, dtype=float).reshape(-1)
    if w.shape != (6,):
        raise FieldError('wrench', wrench, 'must have 6 components [fx fy fz mx my mz]')
    return w


def command_fault(wrench: ArrayLike, limits: CommandLimits = CommandLimits()) -> str | None:
    """Why one command is absurd, or None when it is sane (streaming form).

    ``wrench``: 6 components [fx fy fz mx my mz] in N and N·m. The reason names the first bad component and its value,
    e.g. ``'fy = 1e+30 N exceeds max_abs_force = 10000 N'`` or ``'mz = nan is not finite'``.
    """
    w = _as_wrench(wrench)
    bounds = limits.bounds()
    for i, (axis, value) in enumerate(zip(AXES, w)):
        unit = 'N' if i < 3 else 'N·m'
        if not np.isfinite(value):
            return f'{axis} = {value!r} is not finite'
        if abs(value) > bounds[i]:
            name = 'max_abs_force' if i < 3 else 'max_abs_moment'
            return f'{axis} = {value:g} {unit} exceeds {name} = {bounds[i]:g} {unit}'
    return None


def command_faults(wrenches: ArrayLike, limits: CommandLimits = CommandLimits()) -> np.ndarray:
    """Vectorised :func:`command_fault`: for an (n, 6) array of commands [N, N·m], a bool array (n,) that is True
    where the command is absurd (not finite, or beyond the limits)."""
    w = np.asarray(wrenches, dtype=float)
    if w.ndim != 2 or w.shape[1] != 6:
        raise FieldError('wrenches', f'array of shape {w.shape}', 'must have shape (n, 6) [fx fy fz mx my mz]')
    with np.errstate(invalid='ignore'):
        bad = ~np.isfinite(w) | (np.abs(w) > limits.bounds())
    return bad.any(axis=1)


__all__ = ['CommandLimits', 'command_fault', 'command_faults']
