"""What the live estimator puts out: the columns of its numeric estimate, each branch's status for people, every
message accounted (the node's final counters) and the input status of /stiffness/estimate. Functions of a
:class:`~crane_stiffness.estimation.live.LiveStiffness` (its private state: they are its own reports, kept apart for
the module's size). Pure Python, no ROS."""
from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import Protocol

from crane_stiffness.estimation.sync import DISPLACEMENT, FORCE, ApproximateTimeSync, InterpolatingSync
from crane_stiffness.estimation.branch import BRANCHES, Branch
from crane_stiffness.estimation.estimator import StiffnessEstimator
from crane_stiffness.estimation.inputs import InputCounters, StreamHealth
from crane_stiffness.estimation.lag import LagHistogram
from crane_stiffness.estimation.live_uncertainty import BranchUncertainty, far_message, statement
from crane_stiffness.estimation.quality import fit_problems
from crane_stiffness.estimation.settings import LiveSettings
from crane_stiffness.estimation.stream_delay import StreamDelay
from crane_stiffness.contract import topics
from crane_stiffness.contract.status import (ERROR, NOT_APPLICABLE_PREFIX, OK, STALE, WAITING, WAITING_PREFIX, WARN,
                                             status_value)


class LiveStiffness(Protocol):
    """What these reports read of a :class:`~crane_stiffness.estimation.live.LiveStiffness` (its own state, private
    ones included: they are its reports)."""

    counters: InputCounters
    prediction: float
    lag: LagHistogram
    health: dict[str, StreamHealth]
    _settings: LiveSettings
    _sync: ApproximateTimeSync | InterpolatingSync
    _estimator: StiffnessEstimator
    _delay: StreamDelay
    _last_report: dict[str, tuple[int, ...]]
    _segment_reason: str
    _nonlinearity: dict[Branch, float]
    _scatter: dict[Branch, float]
    _uncertainty: dict[Branch, BranchUncertainty | None]
    _rows: dict[Branch, list[float]]
    _current: Branch | None
    _newest_stamp: float
    _suspect: dict[Branch, int]
    _suspect_reason: str

    def input_problems(self, now_s: float = math.nan) -> tuple[int, list[str]]: ...


#: Columns of one row of :meth:`~crane_stiffness.estimation.live.LiveStiffness.values` (one row per branch, in the
#: order of ``BRANCHES``).
#: Units: stiffness, ci95_*, stderr, rls_* and prediction in N/m (N·m/rad for a moment axis); intercept and
#: residual_rms in N (N·m); r2, nonlinearity, relative_error without unit; n in pairs; x_noise (the displacement
#: noise counted in the fit, 0: ordinary least squares) in m (rad); current is 1.0 for the branch of the newest pair,
#: else 0.0; sample_stamp is the newest paired sample's stamp, s (the same in both rows).
VALUE_FIELDS = ('stiffness', 'intercept', 'stderr', 'ci95_low', 'ci95_high', 'r2', 'n', 'residual_rms',
                'nonlinearity', 'rls_stiffness', 'rls_stderr', 'x_noise', 'prediction', 'relative_error', 'current',
                'sample_stamp')


@dataclass(frozen=True)
class BranchReport:
    """One branch's status for people: level (WAITING/OK/WARN/STALE, :mod:`crane_stiffness.contract.status`), a one-line
    message and key/value strings."""

    branch: Branch
    level: int
    message: str
    values: list[tuple[str, str]] = field(default_factory=list)


def accounting(live: LiveStiffness) -> dict[str, int]:
    """Every message accounted (the node's final counters): per stream received = dropped (input checks) +
    passed_checks, and passed_checks = out_of_order + non_finite + stale + unmatched + discarded + pending +
    paired; pairs = fitted + rejected_command + non_finite; commands received = used + rejected + dropped."""
    out = {f.name: getattr(live.counters, f.name) for f in fields(live.counters)}
    sc = live._sync.counters
    out['pairs'] = sc.pairs
    for stream, counters in ((FORCE, sc.force), (DISPLACEMENT, sc.displacement)):
        for f in fields(counters):
            # the pairing's 'received' are the samples that passed the input checks (not the messages received)
            key = f'{stream}_passed_checks' if f.name == 'received' else f'{stream}_{f.name}'
            out[key] = getattr(counters, f.name)
        out[f'{stream}_pending'] = live._sync.pending(stream)
    return out


def input_report(live: LiveStiffness, consumer: str = '', now_s: float = math.nan
             ) -> tuple[int, str, list[tuple[str, str]]]:
    """Input health: (level, message, key/values); ERROR if a stream is silent (``now_s``: node clock, s), WARN
    if a rejected command is in force, a stream lost too many samples, or samples were dropped, out of order,
    stale or lost in a dropout since this ``consumer``'s previous call; else WAITING while a stream has not
    delivered its first sample, then OK."""
    c = live.counters
    sc = live._sync.counters
    problems = {
        'dropped': c.dropped,
        'out_of_order': sc.total('out_of_order'),
        'stale': sc.total('stale'),
        'dropouts': sc.total('dropouts'),
    }
    snapshot = tuple(problems.values())
    previous = live._last_report.get(consumer, (0,) * len(snapshot))
    live._last_report[consumer] = snapshot
    new = {k: now - before for (k, now), before in zip(problems.items(), previous) if now > before}
    pairs = [(f.name, str(getattr(c, f.name))) for f in fields(c)]
    pairs += [('pairs', str(sc.pairs))]
    for stream, counters in ((FORCE, sc.force), (DISPLACEMENT, sc.displacement)):
        pairs += [(f'{stream}.{f.name}', str(getattr(counters, f.name))) for f in fields(counters)]
    for stream, health in live.health.items():
        pairs += [(f'{stream}.received_fraction', status_value(health.received_fraction())),
                  (f'{stream}.silent_s', status_value(health.silent_for(now_s)))]
    pairs += [('segment', str(c.segments)), ('segment_reason', live._segment_reason)]
    pairs += [('newest_pair_stamp', status_value(live._newest_stamp))]
    pairs += [(f'lag_{name}_ms', status_value(value * 1e3)) for name, value in (
        ('p50', live.lag.percentile(50)), ('p99', live.lag.percentile(99)), ('max', live.lag.max_s))]
    pairs += [('lag_n', str(live.lag.n))]
    pairs += live._delay.values()
    level, reasons = live.input_problems(now_s)
    if new:
        level = max(level, WARN)
        reasons.append('since last report: ' + ', '.join(f'{v} {k}' for k, v in new.items()))
    if reasons:
        return level, '; '.join(reasons), pairs
    summary = f'{sc.pairs} pairs, {c.pairs_fitted} fitted'
    if live._settings.six_axis_program:  # the sensors' health counts (above); the one-axis fit does not
        return OK, not_applicable_message(live._settings.force_axis) + f' ({summary})', pairs
    missing = [stream for stream, health in live.health.items() if not health.count]
    if missing:  # a stream that has not begun: nothing wrong yet, nothing to stand by either
        return WAITING, f'{WAITING_PREFIX}no usable {" or ".join(missing)} sample yet; {summary}', pairs
    return OK, summary, pairs


def not_applicable_message(force_axis: str) -> str:
    """The status message of every part of the one-axis estimate in a six-axis program (level OK)."""
    return (f'{NOT_APPLICABLE_PREFIX}six-axis program, a one-axis fit of {force_axis} means nothing under its '
            f'multi-axis load; see {topics.STIFFNESS6_STATUS}')


def branch_reports(live: LiveStiffness, now_s: float = math.nan) -> list[BranchReport]:
    """Per-branch status for people (:meth:`LiveStiffness.report <crane_stiffness.estimation.live.LiveStiffness.
    report>`, its rows up to date). A branch without an estimate is WAITING (it has not begun: the unloading branch
    during the first loading ramp), WARN with an input problem. With ``now_s`` (the node clock, s) a stream that
    delivered and went silent makes every branch STALE: never OK nor WAITING while its inputs are invalid."""
    s = live._settings
    unit = s.stiffness_unit
    problem_level, problems = live.input_problems(now_s)
    names = ('stiffness', 'intercept', 'stderr', 'ci95_low', 'ci95_high', 'r2', 'n', 'nonlinearity',
             'rls_stiffness', 'x_noise', 'prediction', 'relative_error')
    segment = f'segment {live.counters.segments} (started by {live._segment_reason})'
    out = []
    for branch in BRANCHES:
        row = dict(zip(VALUE_FIELDS, live._rows[branch]))
        row['nonlinearity'] = nl = live._nonlinearity[branch]
        pairs = [(k, status_value(row[k])) for k in names]
        pairs.append(('scatter_ratio', status_value(live._scatter[branch])))
        if math.isnan(row['stiffness']):
            level = WAITING
            message = (f'no estimate yet (needs 3 pairs with spread in displacement beyond its noise; '
                       f'{live._estimator.window_len(branch)} pairs in its window)')
            pairs = [(k, 'nan') for k in names] + [('scatter_ratio', 'nan')]
            pairs[names.index('prediction')] = ('prediction', status_value(live.prediction))
        else:
            message = (f'k = {row["stiffness"]:.6g} {unit} (95 %: {row["ci95_low"]:.6g} .. '
                       f'{row["ci95_high"]:.6g}, repeatability), n = {int(row["n"])}')
            level = OK
            unc = live._uncertainty[branch]
            if unc is not None:  # U beside the statistical interval (the repeatability), E_n against the model
                message += '; ' + statement(unc, unit)
                pairs += [(k, status_value(v)) for k, v in unc.values()]
                pairs += [('statistical_only', str(unc.statistical_only).lower()), ('calibration', unc.calibration)]
                if unc.far_from_model:
                    level = WARN
                    message = far_message(unc, unit) + '; ' + message
            if nl > s.nonlinearity_warn:
                level = WARN
                message = f'nonlinear (slack wire?): nonlinearity {nl:.3g} > {s.nonlinearity_warn:g}; ' + message
            meaningless = fit_problems(row['stiffness'], row['ci95_low'], row['ci95_high'],
                                       live._scatter[branch], s.max_scatter_ratio)
            if meaningless:
                level = WARN
                message = 'fit not trusted: ' + '; '.join(meaningless) + '; ' + message
            if live._suspect[branch]:
                level = WARN
                message = (f'the window holds pairs fitted under a rejected command: {live._suspect_reason} '
                           f'({live._suspect[branch]} more pairs until they leave it); ' + message)
        if problem_level == ERROR:
            frozen, last = ('nothing to estimate from', '') if level == WAITING else ('estimate frozen', 'last ')
            level = STALE
            message = f'inputs invalid, {frozen}: ' + '; '.join(problems) + f'; {last}' + message
        elif problem_level == WARN:
            level = max(level, WARN) if level != STALE else STALE
            message = '; '.join(problems) + '; ' + message
        elif level == WAITING:
            message = WAITING_PREFIX + message
        if live.counters.segments > 1:
            message += f'; new fit {segment}'
        if s.six_axis_program:  # a one-axis verdict on a multi-axis load means nothing: said, not judged
            level, message = OK, not_applicable_message(s.force_axis)
        pairs += [('unit', unit), ('axis', s.force_axis), ('current', str(branch == live._current).lower()),
                  ('segment', str(live.counters.segments)), ('segment_reason', live._segment_reason)]
        out.append(BranchReport(branch, level, message, pairs))
    return out


__all__ = ['VALUE_FIELDS', 'BranchReport', 'accounting', 'branch_reports', 'input_report', 'not_applicable_message']
