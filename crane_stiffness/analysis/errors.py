"""Errors raised by the analysis package (offline analysis of recorded sessions)."""
from __future__ import annotations

from crane_stiffness.errors import CraneStiffnessError, FieldError


class AnalysisError(CraneStiffnessError):
    """Base class of the analysis package's errors."""


class SessionAnalysisError(AnalysisError, ValueError):
    """A session that cannot be analysed (no pairs, no readable data); the message says why."""


class MappingError(AnalysisError, FieldError):
    """A bad topic mapping or displacement type asked of the offline analysis: the message names it and the rule."""
