"""Errors raised by the simulation package (sensor models, load programs)."""
from __future__ import annotations

from crane_stiffness.errors import CraneStiffnessError, ParameterError


class SimError(CraneStiffnessError):
    """Base class of the simulation package's errors."""


class ProgramFileError(SimError):
    """A load-program parameter file that cannot be read or holds no usable ``ros__parameters`` block."""


__all__ = ['ParameterError', 'ProgramFileError', 'SimError']
