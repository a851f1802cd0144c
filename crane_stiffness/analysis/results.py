"""Results of the offline analysis of sessions (:mod:`crane_stiffness.analysis.analyze`,
:mod:`crane_stiffness.analysis.compare`) and their JSON: NaN and Inf are written as null, a line fit
(:class:`~crane_stiffness.estimation.fit.LineFit`) as the fields of :data:`FIT_JSON_FIELDS`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, is_dataclass
from typing import Any

import numpy as np

from crane_stiffness.estimation.fit import LineFit
from crane_stiffness.estimation.live import VALUE_FIELDS


_FIT_FIELDS = tuple(f.name for f in fields(LineFit))
#: A line fit as written to the JSON (the intercept's standard error is not reported).
FIT_JSON_FIELDS = tuple(name for name in _FIT_FIELDS if name != 'intercept_stderr')
#: The values of a published live estimate (VALUE_FIELDS) that a line fit of the same window gives: those of the
#: fit record but the nonlinearity (published only after the estimator's slow refresh).
WINDOW_FIT_FIELDS = tuple(name for name in VALUE_FIELDS if name in _FIT_FIELDS and name != 'nonlinearity')
#: The values of the live estimate compared offline (:class:`LiveComparison`): the window fit's and the RLS stiffness.
COMPARED_FIELDS = WINDOW_FIT_FIELDS + ('rls_stiffness',)


def _num(value: Any) -> float | None:
    """JSON-safe float: None for NaN/Inf."""
    if value is None:
        return None
    value = float(value)
    return value if math.isfinite(value) else None


@dataclass
class Step:
    """One hold of the test program: the commanded level and the settled mean response.

    Times are seconds from the program start (the first command's stamp).
    """

    index: int
    level: float
    approach: str
    repeat: int | None
    segment: int | None
    start_s: float
    end_s: float
    n: int
    force_mean: float
    force_std: float
    displacement_mean: float
    displacement_std: float
    model_displacement: float = math.nan


@dataclass
class CycleFits:
    """Branch fits of one repeat of the program."""

    repeat: int
    start_s: float
    end_s: float
    loading: LineFit | None
    unloading: LineFit | None


@dataclass
class LiveComparison:
    """The last live estimate recorded (/stiffness/estimate_values) beside the same window fitted offline."""

    sample_stamp_s: float
    log_time_s: float
    live: dict[str, dict[str, float]]
    offline: dict[str, dict[str, float]]
    max_rel_diff: dict[str, float]
    """Per branch: largest relative difference of stiffness, intercept, stderr, CI, r², n, rms (NaN if no estimate)."""
    inputs: dict[str, float] = field(default_factory=dict)
    """What the live estimator reported receiving and pairing (its /stiffness/estimate input status) between its
    first and last recorded report, beside what the bag holds over the same time: the estimate can be reproduced
    exactly only when both saw the same samples."""


@dataclass
class ModelSummary:
    """The paper's models for the recorded geometry along the tested axis."""

    axis: str
    unit: str
    tangent_at_rest: float
    eq18: float
    elastic_w0: float
    single_wire_w6: float
    recorded_prediction: float
    lvdt_scale: float
    """LVDT reading per unit displacement along the axis (1 when the LVDT measures along the axis)."""
    curves: dict[str, list[float]] = field(default_factory=dict)


@dataclass
class SessionAnalysis:
    """Everything :func:`~crane_stiffness.analysis.analyze.analyze_session` found; :meth:`to_dict` is the JSON
    written."""

    bag: str
    session: str
    notes: str
    recorded_with: str
    analysed_with: str
    start_time_utc: str
    duration_s: float
    axis: str
    unit: str
    program: dict[str, Any] | None
    geometry: dict[str, Any] | None
    settings: dict[str, Any]
    counts: dict[str, int]
    pairing: dict[str, float]  # counters, and each stream's received fraction
    branch_fits: dict[str, LineFit | None]
    hold_fits: dict[str, LineFit | None]
    cycle_fits: list[CycleFits]
    steps: list[Step]
    live: LiveComparison | None
    model: ModelSummary | None
    problems: list[str]
    missing_topics: list[str]
    files: list[str] = field(default_factory=list)
    timings_s: dict[str, float] = field(default_factory=dict)
    #: The delay between the streams estimated from the data (the keys the live input status reports, stream_delay_*).
    stream_delay: dict[str, str] = field(default_factory=dict)
    #: What was read and how (analysis.mapping.MappingUsed): the load and displacement topics and their types, the
    #: displacement type, gain and offset, where the sample instants and the geometry came from.
    mapping: dict[str, Any] = field(default_factory=dict)
    #: Each branch's measured stiffness with its GUM uncertainty and E_n against the model's prediction with its own
    #: (analysis.stiffness_uncertainty.session_uncertainty): {'prediction': …, 'loading': …, 'unloading': …}.
    uncertainty: dict[str, Any] = field(default_factory=dict)
    #: The problems about a branch far from the model (|E_n| > 1), each with its likely causes; also in ``problems``.
    model_disagreements: list[str] = field(default_factory=list)
    #: OK, or NOT OK with the reasons (analysis.verdict.Verdict.to_dict): {'level': …, 'reasons': [...]}.
    verdict: dict[str, Any] = field(default_factory=lambda: {'level': 'OK', 'reasons': []})

    def to_dict(self) -> dict[str, Any]:
        return json_safe(self)


@dataclass
class SessionComparison:
    """Sessions side by side: one row per session (see :func:`~crane_stiffness.analysis.compare.compare_sessions`)."""

    rows: list[dict[str, Any]]
    sessions: list[SessionAnalysis]
    files: list[str] = field(default_factory=list)
    #: Every two sessions branch by branch: both k with their U and E_n (analysis.compare.session_agreement).
    agreement: list[dict[str, Any]] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return json_safe({'rows': self.rows, 'agreement': self.agreement, 'files': self.files})


def json_safe(value: Any) -> Any:
    if isinstance(value, LineFit):
        return {name: json_safe(getattr(value, name)) for name in FIT_JSON_FIELDS}
    if is_dataclass(value) and not isinstance(value, type):
        return {f.name: json_safe(getattr(value, f.name)) for f in fields(value)}
    if isinstance(value, dict):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    if isinstance(value, (float, np.floating)):
        return _num(value)
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.ndarray):
        return json_safe(value.tolist())
    return value
