"""Offline analysis of a recorded test session: stiffness per load branch and test step, the paper's model beside
the measurements, the live estimate checked, figures, a report (Markdown, HTML) and JSON. Pure: no ROS import.

:func:`analyze_session` reads a bag written by session_recorder (crane_stiffness.bag.BagReader, bulk numpy decode):

1. **Pairing.** Load-cell and LVDT samples are paired by header stamp with the semantics of the live estimator
   (crane_stiffness.estimation.live.LiveStiffness → ApproximateTimeSync), vectorized over the whole arrays: the same
   input checks (NaN/Inf, zero stamp, absurd values), out-of-order samples dropped, stale samples dropped (a stamp
   more than ``max_age_s`` behind the other stream's newest at arrival, arrival = the recorded log time), then
   mutual nearest neighbours within ``slop_s`` (ties to the earlier sample) found with ``np.searchsorted``.
   The estimator's parameters are those recorded with the session: read from the running node
   (``crane_stiffness/node_parameters``), else the ``stiffness_estimator`` section of its parameter file.
2. **Branches.** Each pair is labelled loading or unloading like the live BranchTracker (hysteresis on |load|, the
   commanded load in effect at the pair's stamp once a command was seen, else the measured force), vectorized.
3. **Test steps.** Holds of the commanded load on the tested axis (runs of equal /crane/wrench_command values),
   matched to the recorded program's holds (level, loading/unloading approach, repeat); the mean load and
   displacement over the settled part of each hold (``settle_fraction``) are the quasi-static points.
4. **Fits** with :func:`crane_stiffness.estimation.fit.fit_line` (the live estimator's code): all pairs of each
   branch over the program, the hold means of each approach, each repeat's branches; and the live-equivalent window
   (the last ``window`` pairs of each branch up to the last recorded /stiffness/estimate_values) compared with that
   live estimate.
5. **Model** from the recorded geometry (crane_stiffness.analysis.sweep.force_displacement): the nonlinear model,
   the linearized eq. (18), the W = 0 elastic model and a single wire carrying W/6, as in the paper's Figs. 5–9.

A damaged bag (truncated, bad chunk) is analysed from its readable part, with the damage listed in the report; a
missing sensor topic raises :class:`~crane_stiffness.bag.TopicNotFoundError` naming it and the topics present;
missing optional topics (commands, program state, live estimates) are named in the report.
"""
from __future__ import annotations

import json
import math
import time
import warnings
from dataclasses import asdict, dataclass, field, replace
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Iterable, Sequence

import numpy as np

from crane_stiffness import __version__, topics
from crane_stiffness.bag import BagDamageWarning, BagReader, TopicNotFoundError
from crane_stiffness.config import geometry_from_params
from crane_stiffness.errors import CraneStiffnessError
from crane_stiffness.estimation.errors import DataError
from crane_stiffness.estimation.fit import BRANCHES, LOADING, UNLOADING, LineFit, RecursiveLeastSquares, fit_line
from crane_stiffness.estimation.live import AXES, VALUE_FIELDS, LiveSettings
from crane_stiffness.serde import CdrError, decode_diagnostic_array, decode_float64_multiarray, decode_string
from crane_stiffness.session import read_node_parameters, read_session
from crane_stiffness.sim.program import LoadProgram

REQUIRED_TOPICS = (topics.LOAD_CELL_WRENCH, topics.LVDT_DISPLACEMENT)
OPTIONAL_TOPICS = (topics.WRENCH_COMMAND, topics.PROGRAM_STATE, topics.STIFFNESS_VALUES,
                   topics.PREDICTED_AXIS_STIFFNESS, topics.STIFFNESS)
STAGES = ('open+decode', 'pair', 'steps', 'fits', 'model', 'figures', 'report')
#: Pairs of a branch fed to the recursive least squares for the live comparison (its memory is ~1/(1-λ)).
RLS_REPLAY_PAIRS = 20_000
#: Largest number of points drawn per series in a figure.
PLOT_POINTS = 20_000
#: Shortest run of equal commands taken as a hold [s].
MIN_HOLD_S = 0.2
COMPARED_FIELDS = ('stiffness', 'intercept', 'stderr', 'ci95_low', 'ci95_high', 'r2', 'n', 'residual_rms',
                   'rls_stiffness')


class SessionAnalysisError(CraneStiffnessError, ValueError):
    """A session that cannot be analysed (no pairs, no readable data); the message says why."""


# --------------------------------------------------------------------------------------------------- results --
def _num(value: Any) -> float | None:
    """JSON-safe float: None for NaN/Inf."""
    if value is None:
        return None
    value = float(value)
    return value if math.isfinite(value) else None


@dataclass
class FitSummary:
    """A line fit ``load = stiffness · displacement + intercept`` (N/m or N·m/rad of the LVDT reading)."""

    stiffness: float
    intercept: float
    stderr: float
    ci95_low: float
    ci95_high: float
    r2: float
    n: int
    residual_rms: float
    nonlinearity: float

    @classmethod
    def of(cls, fit: LineFit) -> FitSummary:
        return cls(float(fit.stiffness), float(fit.intercept), float(fit.stderr), float(fit.ci95_low),
                   float(fit.ci95_high), float(fit.r2), int(fit.n), float(fit.residual_rms),
                   float(fit.nonlinearity))


def _fit(x: np.ndarray, y: np.ndarray) -> FitSummary | None:
    if len(x) < 3:
        return None
    try:
        return FitSummary.of(fit_line(x, y))
    except DataError:
        return None


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
    loading: FitSummary | None
    unloading: FitSummary | None


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
    """Everything :func:`analyze_session` found; :meth:`to_dict` is the JSON written."""

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
    pairing: dict[str, int]
    branch_fits: dict[str, FitSummary | None]
    hold_fits: dict[str, FitSummary | None]
    cycle_fits: list[CycleFits]
    steps: list[Step]
    live: LiveComparison | None
    model: ModelSummary | None
    problems: list[str]
    missing_topics: list[str]
    files: list[str] = field(default_factory=list)
    timings_s: dict[str, float] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return _json_safe(asdict(self))


def _json_safe(value: Any) -> Any:
    if isinstance(value, dict):
        return {str(k): _json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_safe(v) for v in value]
    if isinstance(value, (float, np.floating)):
        return _num(value)
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.ndarray):
        return _json_safe(value.tolist())
    return value


# ------------------------------------------------------------------------------------------ vectorized core --
def _nearest(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Index of the nearest element of sorted ``b`` for each of ``a``; ties go to the earlier (lower) index."""
    j = np.searchsorted(b, a, side='left')  # b[j - 1] < a <= b[j]
    padded = np.concatenate([[-np.inf], b, [np.inf]])  # padded[j] = b[j - 1], padded[j + 1] = b[j]
    pick = np.where(padded[j + 1] - a < a - padded[j], j, j - 1)
    if b.size > 1 and not (np.diff(b) > 0).all():
        pick = np.searchsorted(b, b[pick], side='left')  # the first of equal stamps
    return pick


def _in_order(stamp: np.ndarray) -> np.ndarray:
    """True where a stamp is not older than every stamp before it (arrival order), as ApproximateTimeSync."""
    ok = np.ones(stamp.size, bool)
    if stamp.size > 1:
        ok[1:] = stamp[1:] >= np.maximum.accumulate(stamp)[:-1]
    return ok


def _stale(stamp: np.ndarray, log: np.ndarray, other_stamp: np.ndarray, other_log: np.ndarray,
           max_age: float) -> np.ndarray:
    """True where a sample is older than the other stream's newest stamp at its arrival by more than max_age."""
    if other_stamp.size == 0:
        return np.zeros(stamp.size, bool)
    newest = np.concatenate([[-np.inf], np.maximum.accumulate(other_stamp)])
    return stamp < newest[np.searchsorted(other_log, log, side='left')] - max_age


@dataclass
class PairResult:
    """Indices of paired samples (into the arrays given) and the counters of the live synchroniser."""

    force_index: np.ndarray
    displacement_index: np.ndarray
    counters: dict[str, int]


def _greedy(f: list[float], d: list[float], slop: float) -> list[tuple[int, int]]:
    """ApproximateTimeSync's matching (``_match`` with all samples known) on two short sorted stamp lists."""
    i = j = 0
    out = []
    while i < len(f) and j < len(d):
        tf, td = f[i], d[j]
        if tf < td - slop:
            i += 1
        elif td < tf - slop:
            j += 1
        elif tf <= td and i + 1 < len(f) and abs(f[i + 1] - td) < td - tf:
            i += 1  # the next force sample is nearer to this displacement: this one is dominated
        elif tf > td and j + 1 < len(d) and abs(d[j + 1] - tf) < tf - td:
            j += 1
        else:
            out.append((i, j))
            i += 1
            j += 1
    return out


def pair_by_stamp(force_stamp: np.ndarray, force_log: np.ndarray, disp_stamp: np.ndarray, disp_log: np.ndarray,
                  slop: float, max_age: float) -> PairResult:
    """Pair two streams exactly as :class:`~crane_stiffness.estimation.sync.ApproximateTimeSync`, vectorized.

    Inputs are in arrival order (log time ascending) and already passed the input checks. Out-of-order samples
    (older than an earlier stamp of their stream) and stale ones (see :func:`_stale`) are dropped. Of the rest:

    1. mutual nearest neighbours within ``slop`` (ties to the earlier sample), found with ``np.searchsorted`` over
       the whole arrays. Every such pair is also a pair of the synchroniser, and when it forms, everything before
       it on both streams is settled: each is a point where the synchroniser's state is known.
    2. Between two consecutive such pairs the synchroniser's own matching rule is replayed on the few samples left
       over (none at all when both sensors sample on one clock, as on the rig; a handful around a dropout).

    The synchroniser's latency bound for a stalled stream (waiting at most ``max_age``) is not modelled: it matters
    only when a stream stops for longer than ``max_age``. The last pair is included even though the live
    synchroniser emits it only when a later sample arrives.
    """
    f_ok = _in_order(force_stamp)
    d_ok = _in_order(disp_stamp)
    f_stale = _stale(force_stamp, force_log, disp_stamp, disp_log, max_age) & f_ok
    d_stale = _stale(disp_stamp, disp_log, force_stamp, force_log, max_age) & d_ok
    f_idx = np.flatnonzero(f_ok & ~f_stale)
    d_idx = np.flatnonzero(d_ok & ~d_stale)
    counters = {'force_out_of_order': int((~f_ok).sum()), 'displacement_out_of_order': int((~d_ok).sum()),
                'force_stale': int(f_stale.sum()), 'displacement_stale': int(d_stale.sum())}
    if f_idx.size == 0 or d_idx.size == 0:
        counters.update(pairs=0, force_unmatched=int(f_idx.size), displacement_unmatched=int(d_idx.size),
                        replayed_stretches=0)
        return PairResult(np.zeros(0, np.int64), np.zeros(0, np.int64), counters)
    f = force_stamp[f_idx]
    d = disp_stamp[d_idx]
    nf = _nearest(f, d)
    nd = _nearest(d, f)
    mutual = (nd[nf] == np.arange(f.size)) & (np.abs(f - d[nf]) <= slop)
    af = np.flatnonzero(mutual)          # anchors: positions in f and d of the mutual pairs
    ad = nf[mutual]
    # Stretches with samples left over between anchors (and before the first / after the last).
    bf = np.concatenate([[-1], af, [f.size]])
    bd = np.concatenate([[-1], ad, [d.size]])
    gaps = np.flatnonzero((np.diff(bf) > 1) | (np.diff(bd) > 1))
    extra_f: list[int] = []
    extra_d: list[int] = []
    for g in gaps.tolist():
        f0, f1 = int(bf[g]) + 1, int(bf[g + 1])  # the stretch, and the closing anchor (if any) at f1/d1
        d0, d1 = int(bd[g]) + 1, int(bd[g + 1])
        fs = f[f0:min(f1 + 1, f.size)].tolist()
        ds = d[d0:min(d1 + 1, d.size)].tolist()
        for i, j in _greedy(fs, ds, slop):
            if f0 + i < f1 and d0 + j < d1:  # the closing anchor pairs as found above
                extra_f.append(f0 + i)
                extra_d.append(d0 + j)
    if extra_f:
        pf = np.concatenate([af, np.asarray(extra_f, dtype=np.int64)])
        pd = np.concatenate([ad, np.asarray(extra_d, dtype=np.int64)])
        order = np.argsort(pf, kind='stable')
        af, ad = pf[order], pd[order]
    fi = f_idx[af]
    di = d_idx[ad]
    counters.update(pairs=int(fi.size), force_unmatched=int(f_idx.size - fi.size),
                    displacement_unmatched=int(d_idx.size - fi.size), replayed_stretches=int(gaps.size))
    return PairResult(fi, di, counters)


def _first_switch(m: np.ndarray, start: int, loading: bool, threshold: float) -> int:
    """Index of the sample after ``start`` at which BranchTracker leaves its branch (len(m) if never)."""
    n = m.size
    extreme = m[start]
    pos = start + 1
    size = 4096
    while pos < n:
        stop = min(n, pos + size)
        seg = m[pos:stop]
        if loading:
            run = np.maximum(np.maximum.accumulate(seg), extreme)
            hit = run - seg > threshold
        else:
            run = np.minimum(np.minimum.accumulate(seg), extreme)
            hit = seg - run > threshold
        if hit.any():
            return pos + int(np.argmax(hit))
        extreme = run[-1]
        pos = stop
        size *= 2
    return n


def _labels_loop(m: list[float], threshold: float, loading: bool, extreme: float) -> list[bool]:
    """BranchTracker over a list, sample by sample (for loads that switch branch very often)."""
    out = []
    append = out.append
    for v in m:
        if loading:
            if v > extreme:
                extreme = v
            elif extreme - v > threshold:
                loading, extreme = False, v
        elif v < extreme:
            extreme = v
        elif v - extreme > threshold:
            loading, extreme = True, v
        append(loading)
    return out


def branch_labels(load: np.ndarray, threshold: float) -> np.ndarray:
    """Loading (True) / unloading (False) of each sample, exactly as
    :class:`~crane_stiffness.estimation.fit.BranchTracker` labels the sequence ``load`` (N or N·m), vectorized:
    one numpy search per branch switch (a noisy load that switches all the time goes sample by sample)."""
    m = np.abs(np.asarray(load, dtype=float))
    out = np.empty(m.size, bool)
    start, loading, switches = 0, True, 0
    while start < m.size:
        if switches > 2000 and start < 50 * switches:  # a switch every < 50 samples: numpy calls would dominate
            out[start] = loading
            out[start + 1:] = _labels_loop(m[start + 1:].tolist(), threshold, loading, float(m[start]))
            break
        switch = _first_switch(m, start, loading, threshold)
        out[start:switch] = loading
        start, loading = switch, not loading
        switches += 1
    return out


def hold_runs(stamp: np.ndarray, value: np.ndarray, min_hold_s: float = MIN_HOLD_S) -> list[tuple[int, int]]:
    """(first, last + 1) index ranges of runs of equal command values lasting at least ``min_hold_s``."""
    if value.size == 0:
        return []
    starts = np.concatenate([[0], np.flatnonzero(np.diff(value) != 0) + 1])
    ends = np.concatenate([starts[1:], [value.size]])
    out = []
    for a, b in zip(starts.tolist(), ends.tolist()):
        if b - a >= 2 and stamp[b - 1] - stamp[a] >= min_hold_s:
            out.append((a, b))
    return out


# -------------------------------------------------------------------------------------------- reading a bag --
@dataclass
class _Pairs:
    stamp: np.ndarray
    force: np.ndarray
    displacement: np.ndarray
    loading: np.ndarray
    fit_log: np.ndarray


@dataclass
class _Data:
    path: Path
    session: dict[str, Any]
    counts: dict[str, int]
    topic_types: dict[str, str]
    program: LoadProgram | None
    program_record: dict[str, Any] | None
    geometry_params: dict[str, Any] | None
    settings: LiveSettings
    sensors: dict[str, Any]
    force: np.ndarray | None = None
    disp: np.ndarray | None = None
    command: np.ndarray | None = None
    live_series: np.ndarray | None = None
    prediction: np.ndarray | None = None
    states: list[tuple[int, dict[str, Any]]] = field(default_factory=list)
    live_values: tuple[int, np.ndarray] | None = None
    live_inputs: list[tuple[int, dict[str, str]]] = field(default_factory=list)
    start_ns: int | None = None
    end_ns: int | None = None
    message_count: int = 0


def _program_from_record(record: Any, problems: list[str]) -> LoadProgram | None:
    if not isinstance(record, dict):
        return None
    try:
        return LoadProgram.from_params(record, strict=False)
    except (ValueError, TypeError) as exc:
        problems.append(f'recorded program is invalid ({exc}); steps come from the commands alone')
        return None


def _dominant_axis(program: LoadProgram | None) -> str | None:
    if program is None:
        return None
    axes = [s.axis for s in program.segments if s.kind != 'hold' or s.target != 0.0]
    return max(set(axes), key=axes.count) if axes else program.segments[0].axis


def _last_live_values(reader: BagReader, problems: list[str]) -> tuple[int, np.ndarray] | None:
    """(log time, rows) of the last recorded estimate with a finite stiffness, reading only the end of the bag."""
    end, start = reader.end_ns, reader.start_ns
    if end is None:
        return None
    span = 2_000_000_000
    width = len(VALUE_FIELDS)
    while True:
        lo = None if end - span <= start else end - span
        last = None
        for msg in reader.messages([topics.STIFFNESS_VALUES], start_ns=lo):
            try:
                dims, data = decode_float64_multiarray(msg.data)
            except CdrError as exc:
                problems.append(f'unreadable {topics.STIFFNESS_VALUES} message at {msg.log_time_ns}: {exc}')
                continue
            if data.size != 2 * width:
                problems.append(f'{topics.STIFFNESS_VALUES} has {data.size} values, expected 2 x {width} '
                                f'({", ".join(VALUE_FIELDS)}); live comparison skipped')
                return None
            rows = data.reshape(2, width)
            if np.isfinite(rows[:, 0]).any():
                last = (msg.log_time_ns, rows)
        if last is not None or lo is None:
            return last
        span *= 8


def _input_status(data: bytes) -> dict[str, str] | None:
    try:
        statuses = decode_diagnostic_array(data)
    except (CdrError, UnicodeDecodeError):
        return None
    for _, name, _, _, values in statuses:
        if name.endswith(': input') and 'pairs' in values:
            return values
    return None


def _live_input_reports(reader: BagReader) -> list[tuple[int, dict[str, str]]]:
    """The first and the last input status the estimator published (/stiffness/estimate), reading only the start
    and the end of the bag."""
    start, end = reader.start_ns, reader.end_ns
    if start is None or end is None:
        return []
    window = 10_000_000_000

    def reports(lo: int | None, hi: int | None) -> list[tuple[int, dict[str, str]]]:
        out = []
        for msg in reader.messages([topics.STIFFNESS_ESTIMATE], start_ns=lo, end_ns=hi):
            values = _input_status(msg.data)
            if values is not None:
                out.append((msg.log_time_ns, values))
        return out

    head = reports(None, start + window)
    tail = reports(max(start + window, end - window), None)
    if not head or not tail:
        head = tail = reports(None, None)
    found = sorted({t: (t, v) for t, v in head[:1] + tail[-1:]}.values(), key=lambda r: r[0])
    return found


def _read(path: Path, axis: str | None, problems: list[str], missing: list[str]) -> _Data:
    reader = BagReader(path)
    try:
        known = reader.topics
        for topic in REQUIRED_TOPICS:
            if topic not in known:
                present = ', '.join(f'{t} [{i.msg_type}]' for t, i in sorted(known.items())) or 'none'
                raise TopicNotFoundError(f'{path}: required topic {topic} is not in the bag (topics present: '
                                         f'{present})')
        for topic in OPTIONAL_TOPICS:
            if topic not in known or known[topic].count == 0:
                missing.append(topic)
        session = read_session(reader)
        nodes = read_node_parameters(reader)
        program_record = session.get('program') if isinstance(session.get('program'), dict) else None
        if 'segments.kind' in nodes.get('load_program', {}):  # what the load_program node actually ran
            program_record = {**nodes['load_program'], 'source': 'load_program node parameters'}
        program = _program_from_record(program_record, problems)
        sensors = dict(session.get('sensors')) if isinstance(session.get('sensors'), dict) else {}
        sensors.update(nodes)
        est_params = sensors.get('stiffness_estimator') or sensors.get('/stiffness_estimator') or {}
        try:
            settings = LiveSettings.from_params(est_params)
        except ValueError as exc:
            problems.append(f'recorded stiffness_estimator parameters are invalid ({exc}); using the defaults')
            settings = LiveSettings()
            est_params = {}
        chosen = axis or (est_params.get('force_axis') if 'force_axis' in est_params else None) \
            or _dominant_axis(program) or settings.force_axis
        if chosen not in AXES:
            raise SessionAnalysisError(f'axis = {chosen!r}: must be one of {", ".join(AXES)}')
        settings = replace(settings, force_axis=chosen)
        rig = session.get('rig') if isinstance(session.get('rig'), dict) else None
        geometry_params = rig.get('geometry') if rig and isinstance(rig.get('geometry'), dict) else None
        model_geometry = {k: v for k, v in nodes.get('crane_model', {}).items() if k.startswith('geometry.')}
        if model_geometry:  # the crane_model node's geometry, as it ran
            geometry_params = model_geometry
        if geometry_params is None:
            problems.append('no rig geometry recorded: no model curves')
        data = _Data(path=path, session=session, counts={t: i.count for t, i in known.items()},
                     topic_types={t: i.msg_type for t, i in known.items()}, program=program,
                     program_record=program_record, geometry_params=geometry_params, settings=settings,
                     sensors=sensors, start_ns=reader.start_ns, end_ns=reader.end_ns,
                     message_count=reader.message_count)
        if known[topics.LOAD_CELL_WRENCH].msg_type != 'geometry_msgs/msg/WrenchStamped':
            raise SessionAnalysisError(f'{topics.LOAD_CELL_WRENCH} has type {known[topics.LOAD_CELL_WRENCH].msg_type}'
                                       ', expected geometry_msgs/msg/WrenchStamped')
        if known[topics.LVDT_DISPLACEMENT].msg_type not in ('geometry_msgs/msg/PointStamped', 'std_msgs/msg/Float64'):
            raise SessionAnalysisError(f'{topics.LVDT_DISPLACEMENT} has type '
                                       f'{known[topics.LVDT_DISPLACEMENT].msg_type}, expected PointStamped or Float64')
        wanted = list(REQUIRED_TOPICS)
        for topic, msg_type in ((topics.WRENCH_COMMAND, 'geometry_msgs/msg/WrenchStamped'),
                                (topics.PREDICTED_AXIS_STIFFNESS, 'std_msgs/msg/Float64'),
                                (topics.STIFFNESS, 'std_msgs/msg/Float64')):
            if topic in known and known[topic].count and known[topic].msg_type == msg_type:
                wanted.append(topic)
        arrays = reader.decode_topics(wanted)
        data.force = arrays[topics.LOAD_CELL_WRENCH]
        data.disp = arrays[topics.LVDT_DISPLACEMENT]
        data.command = arrays.get(topics.WRENCH_COMMAND)
        data.prediction = arrays.get(topics.PREDICTED_AXIS_STIFFNESS)
        data.live_series = arrays.get(topics.STIFFNESS)
        if topics.PROGRAM_STATE in known and known[topics.PROGRAM_STATE].count:
            for msg in reader.messages([topics.PROGRAM_STATE]):
                try:
                    state = json.loads(decode_string(msg.data))
                except (CdrError, ValueError):
                    continue
                if isinstance(state, dict):
                    data.states.append((msg.log_time_ns, state))
        if topics.STIFFNESS_VALUES in known and known[topics.STIFFNESS_VALUES].count:
            data.live_values = _last_live_values(reader, problems)
        if topics.STIFFNESS_ESTIMATE in known and known[topics.STIFFNESS_ESTIMATE].count:
            data.live_inputs = _live_input_reports(reader)
        return data
    finally:
        reader.close()


# ------------------------------------------------------------------------------------------------ analysis --
def _inputs(data: _Data) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray], dict[str, int]]:
    """The live estimator's input checks on both streams: (force, displacement) dicts of stamp/log/value arrays."""
    s = data.settings
    f = data.force
    wrench = np.column_stack([f[k] for k in ('fx', 'fy', 'fz', 'mx', 'my', 'mz')]) if f.size else np.zeros((0, 6))
    f_value = wrench[:, s.axis_index] if f.size else np.zeros(0)
    f_stamp = f['stamp_s']
    finite = np.isfinite(wrench).all(axis=1) & np.isfinite(f_stamp)
    zero = finite & (f_stamp <= 0.0)
    absurd = finite & ~zero & (np.abs(f_value) > s.max_abs_force)
    f_keep = finite & ~zero & ~absurd
    d = data.disp
    if 'stamp_s' in d.dtype.names:
        d_stamp = d['stamp_s']
        d_value = d['x'].astype(float)
    else:  # std_msgs/Float64 in volts, stamped on arrival by the estimator
        d_stamp = d['log_time_ns'] * 1e-9
        d_value = s.displacement_gain * d['data'] + s.displacement_offset
    d_finite = np.isfinite(d_value) & np.isfinite(d_stamp)
    d_zero = d_finite & (d_stamp <= 0.0)
    d_absurd = d_finite & ~d_zero & (np.abs(d_value) > s.max_abs_displacement)
    d_keep = d_finite & ~d_zero & ~d_absurd
    counters = {'force_messages': int(f.size), 'displacement_messages': int(d.size),
                'dropped_non_finite': int((~finite).sum() + (~d_finite).sum()),
                'dropped_zero_stamp': int(zero.sum() + d_zero.sum()),
                'dropped_absurd': int(absurd.sum() + d_absurd.sum())}
    return ({'stamp': f_stamp[f_keep], 'log': f['log_time_ns'][f_keep], 'value': f_value[f_keep]},
            {'stamp': d_stamp[d_keep], 'log': d['log_time_ns'][d_keep], 'value': d_value[d_keep]}, counters)


def _commands(data: _Data) -> dict[str, np.ndarray] | None:
    c = data.command
    if c is None or c.size == 0:
        return None
    s = data.settings
    load = c[s.force_axis].astype(float)
    stamp = np.where(c['stamp_s'] > 0.0, c['stamp_s'], c['log_time_ns'] * 1e-9)
    ok = np.isfinite(load) & np.isfinite(stamp)
    if not ok.any():
        return None
    order = np.argsort(stamp[ok], kind='stable')
    return {'stamp': stamp[ok][order], 'log': c['log_time_ns'][ok][order], 'value': load[ok][order],
            'first_log': int(c['log_time_ns'][ok].min())}


def _pairs(data: _Data, force: dict, disp: dict, commands: dict | None) -> tuple[_Pairs, dict[str, int]]:
    s = data.settings
    result = pair_by_stamp(force['stamp'], force['log'], disp['stamp'], disp['log'], s.slop_s, s.max_age_s)
    fi, di = result.force_index, result.displacement_index
    stamp = 0.5 * (force['stamp'][fi] + disp['stamp'][di])
    fvalue = force['value'][fi]
    dvalue = disp['value'][di]
    fit_log = np.maximum(force['log'][fi], disp['log'][di])
    load = fvalue
    if commands is not None and s.branch_source == 'auto':
        k = np.searchsorted(commands['stamp'], stamp, side='right') - 1
        use = (k >= 0) & (fit_log >= commands['first_log'])
        load = np.where(use, commands['value'][np.maximum(k, 0)], fvalue)
    loading = branch_labels(load, s.hysteresis)
    return _Pairs(stamp, fvalue, dvalue, loading, fit_log), result.counters


def _steps(data: _Data, pairs: _Pairs, commands: dict | None, t0: float, settle_fraction: float,
           problems: list[str]) -> list[Step]:
    if commands is None:
        return []
    stamp, value = commands['stamp'], commands['value']
    runs = hold_runs(stamp, value)
    period = float(np.median(np.diff(stamp))) if stamp.size > 1 else 0.0
    holds = data.program.holds(data.settings.force_axis) if data.program is not None else []

    def fits_at(offset: int) -> bool:
        return all(math.isclose(h.level, value[a], rel_tol=1e-9, abs_tol=1e-12)
                   for h, (a, _) in zip(holds[offset:offset + len(runs)], runs))

    # The commanded holds are the program's, or a contiguous part of them when the recording (or the delivery of
    # the first commands) started late or the program was stopped early.
    offsets = [k for k in range(len(holds) - len(runs) + 1) if fits_at(k)] if runs else []
    matched = bool(offsets)
    if matched:
        holds = holds[offsets[0]:offsets[0] + len(runs)]
        if len(runs) != len(data.program.holds(data.settings.force_axis)):
            problems.append(f'the commands show {len(runs)} of the program\'s '
                            f'{len(data.program.holds(data.settings.force_axis))} holds on {data.settings.force_axis} '
                            f'(from hold {offsets[0] + 1}): the recording does not cover the whole program')
    elif data.program is not None:
        problems.append(f'the commands show {len(runs)} hold(s) on {data.settings.force_axis} that do not match the '
                        f'recorded program\'s {len(holds)}: steps are labelled from the commands alone')
    steps: list[Step] = []
    previous_level, approach = None, 'loading'
    for i, (a, b) in enumerate(runs):
        level = float(value[a])
        start = stamp[a]
        end = stamp[b] if b < stamp.size else stamp[b - 1] + period
        if matched:
            hold = holds[i]
            approach, repeat, segment = hold.approach, hold.repeat_index, hold.segment_index
        else:
            if previous_level is not None and abs(level) != abs(previous_level):
                approach = 'loading' if abs(level) > abs(previous_level) else 'unloading'
            repeat = segment = None
        previous_level = level
        lo = np.searchsorted(pairs.stamp, start + settle_fraction * (end - start), side='left')
        hi = np.searchsorted(pairs.stamp, end, side='left')
        f, d = pairs.force[lo:hi], pairs.displacement[lo:hi]
        n = int(hi - lo)
        steps.append(Step(index=i, level=level, approach=approach, repeat=repeat, segment=segment,
                          start_s=float(start - t0), end_s=float(end - t0), n=n,
                          force_mean=float(f.mean()) if n else math.nan,
                          force_std=float(f.std(ddof=1)) if n > 1 else math.nan,
                          displacement_mean=float(d.mean()) if n else math.nan,
                          displacement_std=float(d.std(ddof=1)) if n > 1 else math.nan))
    return steps


def _branch_fits(pairs: _Pairs, lo: int, hi: int) -> dict[str, FitSummary | None]:
    sel = slice(lo, hi)
    x, y, loading = pairs.displacement[sel], pairs.force[sel], pairs.loading[sel]
    return {LOADING: _fit(x[loading], y[loading]), UNLOADING: _fit(x[~loading], y[~loading])}


def _window_fit(pairs: _Pairs, cut: int, branch: str, window: int, forgetting: float) -> dict[str, float]:
    sel = np.flatnonzero(pairs.loading[:cut] == (branch == LOADING))
    nan = math.nan
    out = {k: nan for k in COMPARED_FIELDS}
    if sel.size < 3:
        return out
    last = sel[-window:]
    fit = _fit(pairs.displacement[last], pairs.force[last])
    if fit is not None:
        out.update(stiffness=fit.stiffness, intercept=fit.intercept, stderr=fit.stderr, ci95_low=fit.ci95_low,
                   ci95_high=fit.ci95_high, r2=fit.r2, n=float(fit.n), residual_rms=fit.residual_rms)
    rls = RecursiveLeastSquares(forgetting)
    tail = sel[-RLS_REPLAY_PAIRS:]
    for x, y in zip(pairs.displacement[tail].tolist(), pairs.force[tail].tolist()):
        rls.add(x, y)
    result = rls.result()
    out['rls_stiffness'] = nan if result is None else result.stiffness
    return out


def _live(data: _Data, pairs: _Pairs) -> LiveComparison | None:
    if data.live_values is None:
        return None
    log, rows = data.live_values
    s = data.settings
    index = {f: i for i, f in enumerate(VALUE_FIELDS)}
    stamp = float(rows[0, index['sample_stamp']])
    cut = int(np.searchsorted(pairs.stamp, stamp, side='right')) if math.isfinite(stamp) else pairs.stamp.size
    live, offline, worst = {}, {}, {}
    for b, branch in enumerate(BRANCHES):
        live[branch] = {f: float(rows[b, index[f]]) for f in COMPARED_FIELDS}
        offline[branch] = _window_fit(pairs, cut, branch, s.window, s.forgetting)
        diffs = []
        for f in COMPARED_FIELDS:
            if f == 'rls_stiffness':
                continue
            a, o = live[branch][f], offline[branch][f]
            if math.isfinite(a) and math.isfinite(o):
                diffs.append(abs(o - a) / max(abs(a), 1e-300) if f not in ('intercept',) else
                             abs(o - a) / max(abs(live[branch]['residual_rms']), abs(a), 1e-300))
        worst[branch] = max(diffs) if diffs else math.nan
    comparison = LiveComparison(sample_stamp_s=stamp, log_time_s=log * 1e-9, live=live, offline=offline,
                                max_rel_diff=worst)
    if len(data.live_inputs) == 2:
        (t_a, a), (t_b, b) = data.live_inputs
        try:
            received = int(b['force_received']) - int(a['force_received'])
            paired = int(b['pairs']) - int(a['pairs'])
        except (KeyError, ValueError):
            return comparison
        in_bag = int(((data.force['log_time_ns'] > t_a) & (data.force['log_time_ns'] <= t_b)).sum())
        offline_pairs = int(((pairs.fit_log > t_a) & (pairs.fit_log <= t_b)).sum())
        comparison.inputs = {'from_s': t_a * 1e-9, 'to_s': t_b * 1e-9, 'live_force_received': received,
                             'bag_force_messages': in_bag, 'live_pairs': paired, 'offline_pairs': offline_pairs}
    return comparison


def lvdt_scale(axis: str, lvdt: dict[str, Any] | None) -> float | None:
    """LVDT reading per unit displacement (m) or rotation (rad) along ``axis`` for small motions.

    The reading is ``a · (δu + δθ × p)`` for the unit measuring direction ``a`` and contact point ``p``; None when
    the LVDT parameters were not recorded.
    """
    if not lvdt or 'axis' not in lvdt:
        return None
    a = np.asarray(lvdt.get('axis'), dtype=float)
    if a.shape != (3,) or not np.isfinite(a).all() or not np.linalg.norm(a):
        return None
    a = a / np.linalg.norm(a)
    p = np.asarray(lvdt.get('contact_point', [0.0, 0.0, 0.0]), dtype=float)
    i = AXES.index(axis)
    return float(a[i]) if i < 3 else float(np.cross(p, a)[i - 3])


def _model(data: _Data, steps: list[Step], commands: dict | None, points: int,
           problems: list[str]) -> ModelSummary | None:
    if data.geometry_params is None:
        return None
    from crane_stiffness.analysis.sweep import force_displacement, unit
    from crane_stiffness.model import (ModelError, axis_stiffness, directional_stiffness, elastic_stiffness,
                                       paper_stiffness, rest_pose, single_wire_pendulum_stiffness,
                                       tangent_stiffness)
    axis = data.settings.force_axis
    try:
        g = geometry_from_params(data.geometry_params)
        d = unit(axis)
        tangent = axis_stiffness(tangent_stiffness(g, rest_pose(g)), axis)
        eq18 = directional_stiffness(paper_stiffness(g), d)
        elastic = directional_stiffness(elastic_stiffness(g), d)
        pendulum = single_wire_pendulum_stiffness(g) if axis in ('fx', 'fy') and g.weight > 0 else math.nan
    except (ModelError, ValueError) as exc:
        problems.append(f'model of the recorded geometry failed: {exc}')
        return None
    recorded = math.nan
    if data.prediction is not None and data.prediction.size:
        recorded = float(data.prediction['data'][0])
    levels = np.array([s.level for s in steps]) if steps else (commands['value'] if commands else np.zeros(0))
    peak = float(levels[np.argmax(np.abs(levels))]) if levels.size and np.abs(levels).max() > 0 else 0.0
    lvdt = data.sensors.get('lvdt') or data.sensors.get('/lvdt')
    scale = lvdt_scale(axis, lvdt)
    if scale is None:
        scale = 1.0
        if lvdt is not None:
            problems.append('the recorded LVDT parameters are incomplete: readings taken as displacement along '
                            f'{axis}')
    elif abs(scale) < 1e-9:
        problems.append(f'the LVDT (axis {lvdt.get("axis")}, contact point {lvdt.get("contact_point")}) does not see '
                        f'motion along {axis}: measured points are not comparable with the model curves')
    summary = ModelSummary(axis=axis, unit='N/m' if axis.startswith('f') else 'N·m/rad', tangent_at_rest=tangent,
                           eq18=eq18, elastic_w0=elastic, single_wire_w6=pendulum, recorded_prediction=recorded,
                           lvdt_scale=scale)
    if peak != 0.0:
        try:
            curves = force_displacement(g, axis, peak, points)
            summary.curves = {k: np.asarray(v, dtype=float).tolist() for k, v in curves.columns().items()}
            for step in steps:  # in LVDT reading units, comparable with displacement_mean
                same_side = step.level * peak >= 0
                step.model_displacement = float(np.interp(abs(step.level), np.abs(curves.load), curves.nonlinear)) \
                    * scale if same_side else math.nan
        except (ModelError, ValueError) as exc:
            problems.append(f'model curves up to {peak:g} on {axis} failed: {exc}')
    return summary


def _cycles(data: _Data, pairs: _Pairs, steps: list[Step], t0: float) -> list[CycleFits]:
    if data.program is None or data.program.repeats < 2 or not steps or steps[0].repeat is None:
        return []
    starts: dict[int, float] = {}
    for step in steps:
        starts.setdefault(step.repeat, step.start_s)
    order = sorted(starts)
    out = []
    for i, r in enumerate(order):
        start = starts[r] if i else 0.0
        end = starts[order[i + 1]] if i + 1 < len(order) else steps[-1].end_s
        lo, hi = np.searchsorted(pairs.stamp, [t0 + start, t0 + end], side='left')
        fits = _branch_fits(pairs, int(lo), int(hi))
        out.append(CycleFits(repeat=r, start_s=start, end_s=end, loading=fits[LOADING], unloading=fits[UNLOADING]))
    return out


# ----------------------------------------------------------------------------------------------- entry point --
class _Progress:
    def __init__(self, enabled: bool, total: int, desc: str) -> None:
        self.bar = None
        if enabled:
            from tqdm import tqdm
            self.bar = tqdm(total=total, desc=desc, unit='stage', leave=False)
        self.timings: dict[str, float] = {}
        self._t = time.perf_counter()

    def stage(self, name: str) -> None:
        now = time.perf_counter()
        if self.bar is not None:
            self.bar.set_postfix_str(name)
        self._name, self._t = name, now

    def done(self) -> None:
        now = time.perf_counter()
        self.timings[self._name] = round(now - self._t, 4)
        if self.bar is not None:
            self.bar.update(1)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def _default_out(bag: Path) -> Path:
    return Path('out') / 'analysis' / bag.name


def analyze_session(bag_path: str | Path, out_dir: str | Path | None = None, *, formats: Sequence[str] = ('png',),
                    reports: Sequence[str] = ('md',), write_json: bool = True, axis: str | None = None,
                    settle_fraction: float = 0.3, model_points: int = 41, progress: bool = False,
                    write_files: bool = True) -> SessionAnalysis:
    """Analyse one recorded session (see the module docstring) and write its figures, report and JSON.

    Args:
        bag_path: bag directory or .mcap file.
        out_dir: where the files go (default ``out/analysis/<bag name>``).
        formats: figure formats, 'png' and/or 'svg'.
        reports: 'md' and/or 'html'.
        write_json: also write ``analysis.json``.
        axis: load axis to analyse (default: the estimator's recorded ``force_axis``, else the program's axis).
        settle_fraction: part of each hold skipped before averaging (dynamics, settling), 0..1.
        model_points: points per model curve.
        progress: show a tqdm progress bar over the stages.
        write_files: False computes the results only (no figures, report or JSON).

    Returns:
        the :class:`SessionAnalysis` (its ``files`` lists what was written).

    Raises:
        BagNotFoundError / BagFormatError: no readable bag at ``bag_path``.
        TopicNotFoundError: a sensor topic is missing (named, with the topics present).
        SessionAnalysisError: nothing to pair or fit.
    """
    for fmt in formats:
        if fmt not in ('png', 'svg'):
            raise ValueError(f'format = {fmt!r}: must be png or svg')
    for kind in reports:
        if kind not in ('md', 'html'):
            raise ValueError(f'report = {kind!r}: must be md or html')
    if not 0.0 <= settle_fraction < 1.0:
        raise ValueError(f'settle_fraction = {settle_fraction!r}: must be in [0, 1)')
    path = Path(bag_path)
    problems: list[str] = []
    missing: list[str] = []
    bar = _Progress(progress, len(STAGES) if write_files else len(STAGES) - 2, f'analyze {path.name}')
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter('always', BagDamageWarning)
            bar.stage('open+decode')
            data = _read(path, axis, problems, missing)
            bar.done()
            bar.stage('pair')
            force, disp, input_counters = _inputs(data)
            commands = _commands(data)
            pairs, pair_counters = _pairs(data, force, disp, commands)
            if pairs.stamp.size < 3:
                raise SessionAnalysisError(
                    f'{path}: only {pairs.stamp.size} load-cell/LVDT pair(s) within slop_s = {data.settings.slop_s} s '
                    f'({force["stamp"].size} force and {disp["stamp"].size} displacement samples usable)')
            bar.done()
            bar.stage('steps')
            t0 = float(commands['stamp'][0]) if commands is not None else float(pairs.stamp[0])
            steps = _steps(data, pairs, commands, t0, settle_fraction, problems)
            bar.done()
            bar.stage('fits')
            if commands is not None:
                lo = np.searchsorted(pairs.stamp, commands['stamp'][0], side='left')
                hi = np.searchsorted(pairs.stamp, commands['stamp'][-1], side='right')
            else:
                lo, hi = 0, pairs.stamp.size
            branch_fits = _branch_fits(pairs, int(lo), int(hi))
            hold_fits = {}
            for approach in BRANCHES:
                sel = [s for s in steps if s.approach == approach and s.n > 0]
                hold_fits[approach] = _fit(np.array([s.displacement_mean for s in sel]),
                                           np.array([s.force_mean for s in sel]))
            cycles = _cycles(data, pairs, steps, t0)
            live = _live(data, pairs)
            if live is not None and live.inputs:
                got, kept = live.inputs['live_force_received'], live.inputs['bag_force_messages']
                # Samples seen by only one of them matter only if they were fitted (not before the program).
                reproduced = all(d <= 1e-6 for d in live.max_rel_diff.values())
                if abs(got - kept) > max(3, 0.002 * kept) and not reproduced:
                    problems.append(
                        f'over the {live.inputs["to_s"] - live.inputs["from_s"]:.1f} s the estimator reported on, it '
                        f'received {got} load-cell samples and the bag holds {kept}: one of them lost samples '
                        f'(best-effort delivery under load), so its live estimate cannot be reproduced exactly '
                        f'from the bag')

            bar.done()
            bar.stage('model')
            model = _model(data, steps, commands, model_points, problems)
            bar.done()
        damage = []
        for w in caught:
            if issubclass(w.category, BagDamageWarning):
                damage.append(str(w.message))
                warnings.warn(str(w.message), BagDamageWarning, stacklevel=2)
            else:
                warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        problems[:0] = damage
        for topic in missing:
            problems.append(f'topic {topic} is not in the bag' + {
                topics.WRENCH_COMMAND: ': no test steps; branches follow the measured force',
                topics.STIFFNESS_VALUES: ': no live estimate to compare with',
                topics.PROGRAM_STATE: ': program state unknown',
            }.get(topic, ''))
        session = data.session
        start_ns = int(session.get('start_time_ns') or data.start_ns or 0)
        program = None
        if data.program is not None:
            p = data.program
            program = {**p.to_params(), 'duration_s': p.duration_s,
                       'levels': p.levels(data.settings.force_axis).tolist(),
                       'source': (data.program_record or {}).get('source', '')}
            final = [s for _, s in data.states]
            program['final_state'] = final[-1].get('state') if final else None
        geometry = None
        if data.geometry_params is not None:
            try:
                g = geometry_from_params(data.geometry_params)
                geometry = {**g.to_dict(), 'l0': g.l0, 'k': g.k}
            except ValueError as exc:
                problems.append(f'recorded geometry invalid: {exc}')
        counters = {**input_counters, **pair_counters}
        result = SessionAnalysis(
            bag=str(path), session=str(session.get('session') or path.name), notes=str(session.get('notes', '')),
            recorded_with=str(session.get('software_version', '')), analysed_with=__version__,
            start_time_utc=datetime.fromtimestamp(start_ns / 1e9, tz=timezone.utc).isoformat() if start_ns else '',
            duration_s=((data.end_ns or 0) - (data.start_ns or 0)) * 1e-9, axis=data.settings.force_axis,
            unit=data.settings.stiffness_unit, program=program, geometry=geometry,
            settings=asdict(data.settings), counts=data.counts, pairing=counters, branch_fits=branch_fits,
            hold_fits=hold_fits, cycle_fits=cycles, steps=steps, live=live, model=model, problems=problems,
            missing_topics=missing)
        if write_files:
            out = Path(out_dir) if out_dir is not None else _default_out(path)
            out.mkdir(parents=True, exist_ok=True)
            bar.stage('figures')
            result.files += _figures(result, data, pairs, commands, t0, out, formats)
            bar.done()
            bar.stage('report')
            result.timings_s = dict(bar.timings)
            from crane_stiffness.analysis import session_report
            result.files += session_report.write_session_report(result, out, reports)
            if write_json:
                result.files.append(str(out / 'analysis.json'))
                (out / 'analysis.json').write_text(json.dumps(result.to_dict(), indent=1, allow_nan=False))
            bar.done()
        result.timings_s = dict(bar.timings)
        return result
    finally:
        bar.close()


def _decimate(n: int, limit: int = PLOT_POINTS) -> slice:
    return slice(None, None, max(1, math.ceil(n / limit)))


def _figures(result: SessionAnalysis, data: _Data, pairs: _Pairs, commands: dict | None, t0: float, out: Path,
             formats: Sequence[str]) -> list[str]:
    from crane_stiffness.analysis import figures
    written: list[str] = []
    scale = result.model.lvdt_scale if result.model is not None and abs(result.model.lvdt_scale) > 1e-9 else None
    step = _decimate(pairs.stamp.size)
    cloud = {LOADING: (pairs.displacement[step][pairs.loading[step]], pairs.force[step][pairs.loading[step]]),
             UNLOADING: (pairs.displacement[step][~pairs.loading[step]], pairs.force[step][~pairs.loading[step]])}
    holds = {a: (np.array([s.displacement_mean for s in result.steps if s.approach == a]),
                 np.array([s.force_mean for s in result.steps if s.approach == a])) for a in BRANCHES}
    title = f'{result.session}: {result.axis}' + (f', program {result.program["name"]}' if result.program else '')
    if result.geometry:
        title += f', W = {result.geometry["weight"]:g} N, l0 = {result.geometry["l0"]:.3f} m'
    for fmt in formats:
        path = out / f'force_displacement.{fmt}'
        figures.plot_session_force_displacement(
            path, result.axis, curves=result.model.curves if result.model is not None and scale else None,
            lvdt_scale=scale or 1.0, cloud=cloud, holds=holds,
            fits={b: (f.stiffness, f.intercept) for b, f in result.branch_fits.items() if f is not None},
            title=title)
        written.append(str(path))
        path = out / f'timeseries.{fmt}'
        f_step = _decimate(data.force.size)
        series = {'force': (data.force['stamp_s'][f_step] - t0, data.force[result.axis][f_step]),
                  'displacement': (pairs.stamp[step] - t0, pairs.displacement[step])}
        if commands is not None:
            series['command'] = (commands['stamp'] - t0, commands['value'])
        if data.live_series is not None and data.live_series.size:
            l_step = _decimate(data.live_series.size)
            series['live_stiffness'] = (data.live_series['log_time_ns'][l_step] * 1e-9 - t0,
                                        data.live_series['data'][l_step])
        figures.plot_session_timeseries(path, result.axis, series,
                                        holds=[(s.start_s, s.end_s, s.approach) for s in result.steps],
                                        title=f'{result.session}: command, load and displacement')
        written.append(str(path))
    return written


# ------------------------------------------------------------------------------------------------- compare --
@dataclass
class SessionComparison:
    """Sessions side by side: one row per session (see :func:`compare_sessions`)."""

    rows: list[dict[str, Any]]
    sessions: list[SessionAnalysis]
    files: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return _json_safe({'rows': self.rows, 'files': self.files})


def comparison_row(a: SessionAnalysis) -> dict[str, Any]:
    """The headline numbers of one session (a row of the comparison table)."""
    def k(fit: FitSummary | None, name: str = 'stiffness') -> float:
        return getattr(fit, name) if fit is not None else math.nan

    tangent = a.model.tangent_at_rest * a.model.lvdt_scale if a.model is not None and a.model.lvdt_scale else math.nan
    lk = k(a.branch_fits.get(LOADING))
    row = {
        'session': a.session, 'program': (a.program or {}).get('name', ''), 'axis': a.axis, 'unit': a.unit,
        'weight_N': (a.geometry or {}).get('weight', math.nan), 'height_m': (a.geometry or {}).get('height', math.nan),
        'l0_m': (a.geometry or {}).get('l0', math.nan),
        'loading_k': lk, 'loading_ci95_low': k(a.branch_fits.get(LOADING), 'ci95_low'),
        'loading_ci95_high': k(a.branch_fits.get(LOADING), 'ci95_high'),
        'unloading_k': k(a.branch_fits.get(UNLOADING)),
        'holds_loading_k': k(a.hold_fits.get(LOADING)), 'holds_unloading_k': k(a.hold_fits.get(UNLOADING)),
        'live_loading_k': a.live.live[LOADING]['stiffness'] if a.live is not None else math.nan,
        'model_tangent_k': tangent,
        'relative_error_loading': (lk - tangent) / tangent if math.isfinite(tangent) and tangent else math.nan,
        'nonlinearity_loading': k(a.branch_fits.get(LOADING), 'nonlinearity'),
        'steps': len(a.steps), 'problems': len(a.problems),
    }
    return row


def compare_sessions(bags: Iterable[str | Path], out_dir: str | Path | None = None, *,
                     formats: Sequence[str] = ('png',), reports: Sequence[str] = ('md',), write_json: bool = True,
                     axis: str | None = None, progress: bool = False) -> SessionComparison:
    """Analyse several sessions and set them side by side: a table (Markdown/HTML, JSON) and an overlay figure of
    their quasi-static force–displacement points with each session's nonlinear model curve.

    Raises what :func:`analyze_session` raises, naming the bag.
    """
    paths = [Path(b) for b in bags]
    if len(paths) < 1:
        raise ValueError('compare needs at least one bag')
    analyses = []
    iterator: Iterable[Path] = paths
    if progress:
        from tqdm import tqdm
        iterator = tqdm(paths, desc='compare', unit='session', leave=False)
    for p in iterator:
        analyses.append(analyze_session(p, axis=axis, write_files=False))
    comparison = SessionComparison(rows=[comparison_row(a) for a in analyses], sessions=analyses)
    out = Path(out_dir) if out_dir is not None else Path('out') / 'compare'
    out.mkdir(parents=True, exist_ok=True)
    from crane_stiffness.analysis import figures, session_report
    for fmt in formats:
        path = out / f'compare_force_displacement.{fmt}'
        series = []
        for a in analyses:
            holds = ([s.displacement_mean for s in a.steps], [s.force_mean for s in a.steps],
                     [s.approach for s in a.steps])
            curve = None
            if a.model is not None and a.model.curves and abs(a.model.lvdt_scale) > 1e-9:
                curve = (np.asarray(a.model.curves['nonlinear']) * a.model.lvdt_scale,
                         np.asarray(a.model.curves['load']))
            series.append((a.session, holds, curve))
        figures.plot_sessions_overlay(path, analyses[0].axis, series, title=f'{len(analyses)} session(s) compared')
        comparison.files.append(str(path))
    comparison.files += session_report.write_comparison_report(comparison, out, reports)
    if write_json:
        (out / 'compare.json').write_text(json.dumps(comparison.to_dict(), indent=1, allow_nan=False))
        comparison.files.append(str(out / 'compare.json'))
    return comparison
