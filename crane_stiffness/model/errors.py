"""Errors raised by the physics model."""
from __future__ import annotations


from crane_stiffness.errors import CraneStiffnessError, FieldError


class ModelError(CraneStiffnessError):
    """Base class of the model's errors."""


class GeometryError(ModelError, FieldError):
    """An invalid geometry, wire or weight value. Names the field, the value and the rule it breaks."""


class NoEquilibriumError(ModelError):
    """No static equilibrium exists for this load (for example an upward force larger than the weight)."""


class ConvergenceError(ModelError):
    """The solver stopped without meeting its tolerance; the message says how far it got."""
