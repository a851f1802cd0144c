"""Errors raised by the simulation package (sensor models, load programs)."""
from __future__ import annotations

from typing import Any

from crane_stiffness.errors import CraneStiffnessError


class SimError(CraneStiffnessError):
    """Base class of the simulation package's errors."""


class ParameterError(SimError, ValueError):
    """An invalid sensor or program parameter. Names the field, the value and the rule it breaks."""

    def __init__(self, field: str, value: Any, rule: str) -> None:
        self.field = field
        self.value = value
        self.rule = rule
        super().__init__(f'{field} = {value!r}: {rule}')


class ProgramFileError(SimError):
    """A load-program parameter file that cannot be read or holds no usable ``ros__parameters`` block."""
