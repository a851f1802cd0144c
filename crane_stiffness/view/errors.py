"""Errors of the live view's pure parts."""
from __future__ import annotations

from crane_stiffness.errors import CraneStiffnessError


class ViewError(CraneStiffnessError, ValueError):
    """A value the view cannot show: a bad parameter, a message definition that cannot be found."""


__all__ = ['ViewError']
