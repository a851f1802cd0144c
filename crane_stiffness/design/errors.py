"""Errors raised by the design package (workspace maps and margins)."""
from __future__ import annotations

from crane_stiffness.errors import CraneStiffnessError, FieldError


class DesignError(CraneStiffnessError):
    """Base class of the design package's errors."""


class DesignInputError(DesignError, FieldError):
    """A bad value for a design computation: names the field, the value and the rule it breaks."""
