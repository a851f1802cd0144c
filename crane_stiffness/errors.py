"""Base exception of the crane_stiffness package.

Each subpackage has its own ``errors`` module whose exceptions derive from :class:`CraneStiffnessError`, so a caller
can catch everything this package raises with one ``except``.
"""
from __future__ import annotations

from typing import Any


class CraneStiffnessError(Exception):
    """Base class of every error raised on purpose by crane_stiffness."""


class FieldError(CraneStiffnessError, ValueError):
    """An invalid value of a named field or parameter: the message says ``field = value: rule``."""

    def __init__(self, field: str, value: Any, rule: str) -> None:
        self.field = field
        self.value = value
        self.rule = rule
        super().__init__(f'{field} = {value!r}: {rule}')


class ParameterError(FieldError):
    """An invalid constructor or configuration value of a pure core (sensor model, load program, estimator,
    driver); the same class whichever subpackage raises it, re-exported by each subpackage's ``errors``."""
