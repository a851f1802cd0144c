"""Errors of the uncertainty room: a bad input quantity, a bad correlation, a Monte Carlo run that cannot finish."""
from __future__ import annotations

from crane_stiffness.errors import CraneStiffnessError, FieldError


class UncertaintyError(CraneStiffnessError):
    """Base class of the uncertainty room's errors."""


class InputError(UncertaintyError, FieldError):
    """An invalid input quantity, certificate entry or correlation: names the field, the value and the rule."""


class MonteCarloError(UncertaintyError):
    """A Monte Carlo run that cannot give a result (the model returns non-finite values, or the adaptive procedure
    did not settle within its trial limit); the message says which and how far it got."""


__all__ = ['InputError', 'MonteCarloError', 'UncertaintyError']
