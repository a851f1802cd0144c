"""The result of the offline 6×6 analysis (crane_stiffness.analysis.full6): what :func:`~crane_stiffness.analysis
.full6.analyze_full6` returns and writes as ``full6.json``, and what its figures (full6_figures) and report
(full6_report) read. A module of its own so that those two do not import the analysis that calls them."""
from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import Any

from crane_stiffness.analysis.results import json_safe
from crane_stiffness.full6.identify import ComplianceFit
from crane_stiffness.full6.reference import Reference
from crane_stiffness.uncertainty.matrix import MatrixUncertainty


@dataclass
class Full6Analysis:
    """What :func:`analyze_full6` found; :meth:`to_dict` is the JSON written (NaN and inf as null).

    Attributes:
        bag, session, notes, recorded_with, analysed_with: the session and the software.
        duration_s: the bag's length [s]; counts: messages per topic; dropped: non-finite samples left out.
        geometry: the crane modelled (CraneGeometry.to_dict with l0 and k) or None.
        settings: the pairing and fit settings (crane_stiffness.analysis.full6_load.Full6Settings.to_dict).
        pairs: n (pairs), steps (distinct steps), dof (n − steps), poses and load-cell samples used.
        status: level (OK, WARN, ERROR, WAITING) and message of the fit; condition, lack_of_fit, lack_of_fit_p,
            inflation: its numbers (crane_stiffness.full6.identify).
        stiffness, compliance: {'value', 'low', 'high', 'stderr'}: (6, 6) lists each.
        offset: the fit's offset (6,) [m, rad].
        k2: K2 [N/rad]: value, low, high, stderr, sign, its four signed entries, against the tangent and eq. (18).
        reference: the model at the recorded geometry: tangent K, its C, eq. (18) or None, rest pose; None without
            a geometry.
        comparison: per entry of K and C: relative_error vs the tangent (None at its zeros), covers (the interval
            holds the tangent's entry); None without a geometry.
        diagonal: K's diagonal, one dict per axis: entry, unit, measured, low, high, tangent, relative_error, covers.
        compliance_covariance: the covariance of row-major vec C (36, 36) [SI²] (the calibration weighs a
            session's C with it: crane_stiffness.campaign.calibrate); None when the fit gave none.
        uncertainty: the measurement uncertainty (crane_stiffness.analysis.full6_uncertainty): per entry of K and C
            (and K2) u_c, U, k, coverage, interval, the statistical interval and the Monte Carlo's; the 36×36
            covariances; the model's prediction with its U and E_n per entry; None when the step means cannot give it.
        problems: what the reader should know; files: what was written.
        fit, model, matrix_uncertainty: the :class:`~crane_stiffness.full6.identify.ComplianceFit`,
            :class:`~crane_stiffness.full6.reference.Reference` and
            :class:`~crane_stiffness.uncertainty.matrix.MatrixUncertainty` themselves (not in the JSON).
    """

    bag: str
    session: str
    notes: str
    recorded_with: str
    analysed_with: str
    duration_s: float
    counts: dict[str, int]
    dropped: dict[str, int]
    geometry: dict[str, Any] | None
    settings: dict[str, Any]
    pairs: dict[str, int]
    status: dict[str, str]
    condition: float
    lack_of_fit: float
    lack_of_fit_p: float
    inflation: float
    stiffness: dict[str, Any]
    compliance: dict[str, Any]
    offset: list[float]
    k2: dict[str, Any]
    reference: dict[str, Any] | None
    comparison: dict[str, Any] | None
    diagonal: list[dict[str, Any]]
    problems: list[str]
    files: list[str] = field(default_factory=list)
    compliance_covariance: list[list[float]] | None = None
    uncertainty: dict[str, Any] | None = None
    fit: ComplianceFit | None = field(default=None, repr=False)
    model: Reference | None = field(default=None, repr=False)
    matrix_uncertainty: MatrixUncertainty | None = field(default=None, repr=False)

    def to_dict(self) -> dict[str, Any]:
        return {f.name: json_safe(getattr(self, f.name)) for f in fields(self)
                if f.name not in ('fit', 'model', 'matrix_uncertainty')}


__all__ = ['Full6Analysis']
