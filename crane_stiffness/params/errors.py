"""Errors of the parameter files and declarations."""
from __future__ import annotations

from crane_stiffness.errors import CraneStiffnessError, ParameterError


class ConfigError(CraneStiffnessError, ValueError):
    """A config file that cannot be read or holds a bad value; the message names the file and the key."""


__all__ = ['ConfigError', 'ParameterError']
