"""Errors of the campaign package."""
from __future__ import annotations

from crane_stiffness.errors import CraneStiffnessError


class CampaignError(CraneStiffnessError):
    """Base class of the campaign package's errors."""


class CampaignFileError(CampaignError, ValueError):
    """A campaign file that cannot be run: the message names the file, the key, the value and the rule."""


class CalibrationError(CampaignError, ValueError):
    """A calibration the data cannot support (a parameter they do not determine, too few sessions); the message
    names the parameter and why."""
