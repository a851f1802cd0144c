"""Errors raised by the physics model."""
from __future__ import annotations

from typing import Any

from crane_stiffness.errors import CraneStiffnessError


class ModelError(CraneStiffnessError):
    """Base class of the model's errors."""


class GeometryError(ModelError, ValueError):
    """An invalid geometry, wire or weight value. Names the field, the value and the rule it breaks."""

    def __init__(self, field: str, value: Any, rule: str) -> None:
        self.field = field
        self.value = value
        self.rule = rule
        super().__init__(f'{field} = {value!r}: {rule}')


class NoEquilibriumError(ModelError):
    """No static equilibrium exists for this load (for example an upward force larger than the weight)."""


class ConvergenceError(ModelError):
    """The solver stopped without meeting its tolerance; the message says how far it got."""
