"""Errors of :mod:`crane_stiffness.serde`.

:class:`SerdeError` is a :class:`~crane_stiffness.errors.CraneStiffnessError`; :class:`CdrError` is also a
:class:`ValueError`, so code that catches ``ValueError`` around a decode keeps working.
"""
from __future__ import annotations

from crane_stiffness.errors import CraneStiffnessError


class SerdeError(CraneStiffnessError):
    """Base class of the serialization package's errors."""


class CdrError(SerdeError, ValueError):
    """A serialized message that does not have the expected layout."""
