"""The verdict of a session's analysis: OK, or NOT OK with the reasons, when a number would be one the lab cannot
sign. Pure: no ROS import.

NOT OK when a branch fit is not a stiffness (:func:`crane_stiffness.estimation.quality.fit_problems`: a slope that is
not positive, a 95 % interval holding zero, a scatter far beyond the sensors' noise), when the fitted axis is not
the one the commands load (:func:`~crane_stiffness.estimation.quality.axis_problem`), or when a branch is far from
the model (|E_n| > 1, :func:`crane_stiffness.analysis.stiffness_uncertainty.model_disagreements`). What the report
lists beside them and does not judge (a topic missing, samples lost within the estimator's tolerance, a damaged bag
read up to its damage) leaves the verdict OK. ``crane-stiffness analyze`` exits with
:data:`crane_stiffness.cli.exit_codes.EXIT_NOT_OK` when the verdict is NOT OK.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Sequence

OK = 'OK'
NOT_OK = 'NOT OK'
#: Where a slope that is not positive comes from, in the order a lab checks it.
NEGATIVE_SLOPE_HINT = ("check the sign of displacement_gain, the LVDT's axis parameter and its mounting direction, "
                       "then the load cell's axis and frame")


def fit_problem_line(branch: str, found: Sequence[str], stiffness: float) -> str:
    """The problem line of a branch fit not trusted (``found``: the reasons :func:`~crane_stiffness.estimation.
    quality.fit_problems` gave), with where a slope that is not positive comes from."""
    line = f'{branch} fit not trusted: ' + '; '.join(found)
    if not stiffness > 0.0:
        line += f': {NEGATIVE_SLOPE_HINT}'
    return line


@dataclass
class Verdict:
    """OK when ``reasons`` is empty, else NOT OK; the reasons are lines of the report's problems."""

    reasons: list[str] = field(default_factory=list)

    @property
    def level(self) -> str:
        return OK if not self.reasons else NOT_OK

    @property
    def ok(self) -> bool:
        return not self.reasons

    def to_dict(self) -> dict[str, Any]:
        return {'level': self.level, 'reasons': list(self.reasons)}


__all__ = ['NEGATIVE_SLOPE_HINT', 'NOT_OK', 'OK', 'Verdict', 'fit_problem_line']
