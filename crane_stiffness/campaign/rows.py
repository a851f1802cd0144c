"""The campaign's result types: a session's row beside the nominal model and the campaign's analysis
(:mod:`.analyze` builds them), and the calibration's data and result (:mod:`.calibrate`). The report and the figures
read them; no workflow here."""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np


@dataclass
class SessionRow:
    """One session of a campaign beside the nominal model. Stiffness in the LVDT's reading units along the series'
    axis (N/m for fy, fz; N·m/rad for mz)."""

    session: str
    series: str
    weight: float
    l0: float
    height: float
    repeat: int
    unit: str
    status: str
    reasons: list[str]
    k: float
    ci95_low: float
    ci95_high: float
    k_holds: float
    model_tangent: float
    model_eq18: float
    model_elastic_w0: float
    model_single_wire: float
    relative_error: float
    n: int
    analysis: str
    nominal: dict[str, Any] = field(default_factory=dict)
    true: dict[str, Any] = field(default_factory=dict)
    k_gum: float = math.nan
    """The loading stiffness as the GUM states it (the hold means' fit when there are holds, else the samples')."""
    U: float = math.nan
    """Its expanded uncertainty (fit and declared calibrations), same unit."""
    coverage_factor: float = math.nan
    """k of U = k·u_c (Student's t at ν_eff)."""
    repeatability_low: float = math.nan
    """The 95 % interval of the fit U starts from (statistical only: the repeatability)."""
    repeatability_high: float = math.nan
    statistical_only: bool = False
    """No calibration declared by the sensors: U is the fit's alone."""
    prediction: float = math.nan
    """The model's prediction for the nominal crane, the reference of E_n, and its expanded uncertainty."""
    prediction_U: float = math.nan
    en: float = math.nan
    """E_n = (k_gum − prediction) / √(U² + prediction_U²): |E_n| <= 1, the two agree."""
    agreement: str = ''
    """'agree', 'disagree', or '' without an E_n."""

    @property
    def ok(self) -> bool:
        return self.status == 'OK'


def uncertainty_fields(analysis: dict[str, Any], branch: str = 'loading') -> dict[str, Any]:
    """The :class:`SessionRow` fields of a branch's measurement uncertainty and agreement from a session's
    analysis.json (its ``uncertainty`` entry, crane_stiffness.analysis.stiffness_uncertainty); none without one."""
    entry = (analysis.get('uncertainty') or {}).get(branch)
    if not entry:
        return {}

    def number(value: Any) -> float:
        try:
            return float(value)
        except (TypeError, ValueError):
            return math.nan
    u = entry.get('uncertainty') or {}
    low, high = (entry.get('ci95') or [math.nan, math.nan])[:2]
    out: dict[str, Any] = {'k_gum': number(u.get('value')), 'U': number(u.get('U')),
                           'coverage_factor': number(u.get('k')), 'repeatability_low': number(low),
                           'repeatability_high': number(high),
                           'statistical_only': bool(entry.get('statistical_only'))}
    en = entry.get('En')
    if en:
        out.update(prediction=number(en.get('reference')), prediction_U=number(en.get('U_reference')),
                   en=number(en.get('en')), agreement='agree' if en.get('agrees') else 'disagree')
    return out


@dataclass
class Full6Row:
    """One session of the series full: the 6×6 K measured (offline, from the bag: crane_stiffness.analysis.full6)
    beside the nominal model's exact tangent and eq. (18) at the session's W and l0. K row i the load [fx, fy, fz,
    mx, my, mz] (N, N·m), column j the displacement [u_x, u_y, u_z, θ_x, θ_y, θ_z] (m, rad)."""

    session: str
    weight: float
    l0: float
    height: float
    repeat: int
    status: str
    """OK, or NOT OK with the reasons."""
    reasons: list[str]
    diagonal: list[dict[str, Any]]
    """K's diagonal, one dict per axis: entry, unit, measured, low, high (95 %), tangent, relative_error, covers."""
    k2: float
    k2_low: float
    k2_high: float
    k2_tangent: float
    k2_eq18: float
    covered: int
    """How many of K's 36 intervals hold the tangent's entry."""
    live_difference: float
    """Largest |live K − offline K| over K's largest entry; NaN when the live fit published none."""
    pairs: int
    analysis: str
    nominal: dict[str, Any] = field(default_factory=dict)
    true: dict[str, Any] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return self.status == 'OK'

    @property
    def k2_relative_error(self) -> float:
        return self.k2 / self.k2_tangent - 1.0 if self.k2_tangent else float('nan')

    @property
    def worst_diagonal_error(self) -> float:
        """Largest |measured / tangent − 1| over K's diagonal (NaN without numbers)."""
        errors = [abs(d['relative_error']) for d in self.diagonal if d.get('relative_error') is not None]
        return max(errors) if len(errors) == 6 else float('nan')


@dataclass
class CampaignAnalysis:
    """What :func:`analyze_campaign` found and wrote."""

    out: Path
    campaign: str
    rows: list[SessionRow]
    """The one-axis sessions (series fy, fz, mz)."""
    full: list[Full6Row]
    """The sessions of the series full (the 6×6 stiffness)."""
    missing: list[str]
    """Sessions planned but not run (yet)."""
    analysed: list[str]
    """Sessions analysed now (the others were unchanged since their last analysis)."""
    failed: dict[str, str]
    """Sessions whose analysis failed, and why."""
    files: list[str] = field(default_factory=list)
    coverage: list[Any] = field(default_factory=list)
    """How often each quantity's 95 % intervals cover the model (crane_stiffness.campaign.coverage.Coverage)."""

    def to_dict(self) -> dict[str, Any]:
        from crane_stiffness.analysis.results import json_safe
        return json_safe({'campaign': self.campaign, 'rows': [asdict(r) for r in self.rows],
                           'full': [asdict(r) for r in self.full], 'missing': self.missing,
                           'analysed': self.analysed, 'failed': self.failed, 'files': self.files,
                           'coverage': [{'quantity': c.quantity, 'covered': c.covered, 'sessions': c.total,
                                         'fraction': c.fraction, 'ci95': list(c.interval),
                                         'consistent_with_95': c.consistent} for c in self.coverage]})


@dataclass
class CalibrationSession:
    """What the calibration uses of one session: its set-up and its hold means."""

    session: str
    series: str
    nominal: dict[str, Any]
    """geometry.* parameters of the nominal crane of the set-up."""
    lvdt_scale: float
    """The LVDT's reading per unit motion along the series' axis (1 for an LVDT along it)."""
    force: np.ndarray
    """(n,) mean load of each hold [N or N·m]."""
    force_se: np.ndarray
    displacement: np.ndarray
    """(n,) mean LVDT reading of each hold [m, or rad when converted by a lever arm]."""
    displacement_se: np.ndarray


@dataclass
class MatrixSession:
    """What the calibration uses of a session of the series full: its set-up and its measured 6×6 compliance."""

    session: str
    nominal: dict[str, Any]
    """geometry.* parameters of the nominal crane of the set-up."""
    compliance: np.ndarray
    """(36,) row-major vec C measured [m/N, m/(N·m), rad/N, rad/(N·m)] (crane_stiffness.analysis.full6)."""
    whiten: np.ndarray
    """(36, 36) Σ^(-1/2) of vec C's covariance: whiten @ (C − model) has unit covariance."""
    series: str = 'full'


@dataclass
class Parameter:
    name: str
    value: float
    stderr: float
    ci95_low: float
    ci95_high: float
    unit: str
    description: str


@dataclass
class Calibration:
    """The calibrated parameters and how well the model fits."""

    parameters: list[Parameter]
    correlation: list[list[float]]
    chi2: float
    dof: int
    sessions: list[dict[str, Any]]
    """Per session: holds, rms of the normalised residuals, its zero, measured and calibrated slope."""
    wire: dict[str, float] = field(default_factory=dict)
    """E·A of the wire and k at each length, nominal and calibrated."""

    def parameter(self, name: str) -> Parameter:
        return next(p for p in self.parameters if p.name == name)

    def to_dict(self) -> dict[str, Any]:
        from crane_stiffness.analysis.results import json_safe
        return json_safe(asdict(self))
