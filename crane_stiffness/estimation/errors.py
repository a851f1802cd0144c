"""Errors raised by the estimation package (fits, branch tracking, time pairing)."""
from __future__ import annotations

from typing import Any

from crane_stiffness.errors import CraneStiffnessError


class EstimationError(CraneStiffnessError):
    """Base class of the estimation package's errors."""


class ParameterError(EstimationError, ValueError):
    """An invalid constructor or configuration value. Names the field, the value and the rule it breaks."""

    def __init__(self, field: str, value: Any, rule: str) -> None:
        self.field = field
        self.value = value
        self.rule = rule
        super().__init__(f'{field} = {value!r}: {rule}')


class DataError(EstimationError, ValueError):
    """Data that cannot be fitted: too few points, no spread in displacement, NaN or Inf values."""


class SyncError(EstimationError, ValueError):
    """Misuse of the time pairing, for example a sample pushed on an unknown stream."""
