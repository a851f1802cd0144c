"""Errors raised by the estimation package (fits, branch tracking, time pairing)."""
from __future__ import annotations

from crane_stiffness.errors import CraneStiffnessError, ParameterError


class EstimationError(CraneStiffnessError):
    """Base class of the estimation package's errors."""


class DataError(EstimationError, ValueError):
    """Data that cannot be fitted: too few points, no spread in displacement, NaN or Inf values."""


class SyncError(EstimationError, ValueError):
    """Misuse of the time pairing, for example a sample pushed on an unknown stream."""


__all__ = ['DataError', 'EstimationError', 'ParameterError', 'SyncError']
