"""Offline analysis of a recorded test session: stiffness per load branch and test step, the paper's model beside
the measurements, the live estimate checked, figures, a report (Markdown, HTML) and JSON
(:mod:`crane_stiffness.analysis.results`). Pure: no ROS import.

:func:`analyze_session` reads a bag written by session_recorder (:mod:`crane_stiffness.analysis.load`, bulk numpy
decode):

1. **Pairing.** Load-cell and LVDT samples are paired by header stamp as the live estimator pairs them
   (crane_stiffness.estimation.live.LiveStiffness), by its own rules in their vectorized form
   (crane_stiffness.estimation.live_pairs.live_pairs): the same input checks (NaN/Inf, zero stamp, absurd values), then
   the synchroniser's pairing over the whole arrays (arrival = the recorded log time). The clock-skew check
   (a stamp more than ``max_clock_skew_s`` ahead of its arrival at the node) takes the recorder's log time of the
   message as the arrival: the recorder receives on the same clock, a few ms from the estimator. Pairs made while a
   rejected command was in force (absurd by :mod:`crane_stiffness.contract.command_limits`, or on
   /crane/rejected_command) are
   left out, and the fraction of each stream's samples received (from its own stamps) is reported, as live.
   The wrench is moved from the sensor's frame to the platform centre and the displacement stamps corrected by
   ``displacement_delay_s`` as live; the delay left between the streams is estimated over the whole recording
   (:func:`~crane_stiffness.estimation.stream_delay.stream_delay_of`, the live input status's stream_delay_*) and named
   among the problems above ``max_stream_delay_s``.
   Not reproduced offline: fit segments started by a sensor restart (the bag does not record publishers), nor by a
   re-zero or tare (/lvdt/zero, /load_cell/tare are recorded now, but the offline fit is one regression per step
   over whole streams; a session with a re-zero inside a step mixes the two zero points there). The estimator's
   parameters
   are those recorded with the session: read from the running node (``crane_stiffness/node_parameters``), else the
   ``stiffness_estimator`` section of its parameter file (:mod:`crane_stiffness.analysis.load`).
2. **Branches.** Each pair is labelled loading or unloading as the live estimator labels it (hysteresis on |load|,
   the commanded load in effect at the pair's stamp once a command was seen, else the measured force).
3. **Test steps.** Holds of the commanded load on the tested axis (runs of equal /crane/wrench_command values),
   matched to the recorded program's holds (level, loading/unloading approach, repeat); the mean load and
   displacement over the settled part of each hold (``settle_fraction``) are the quasi-static points.
4. **Fits** with :func:`crane_stiffness.estimation.fit.fit_line` (the live estimator's code): all pairs of each
   branch over the program, the hold means of each approach, each repeat's branches; and the live-equivalent window
   (the last ``window`` pairs of each branch up to the last recorded /stiffness/estimate_values) compared with that
   live estimate.
5. **Model** from the recorded geometry (crane_stiffness.analysis.sweep.force_displacement): the nonlinear model,
   the linearized eq. (18), the W = 0 elastic model and a single wire carrying W/6, as in the paper's Figs. 5–9.
6. **Uncertainty** (:mod:`crane_stiffness.analysis.stiffness_uncertainty`, the 'uncertainty' stage): each branch's
   k with its GUM budget (the hold means' fit as Type A, the sensors' declared calibrations as Type B) and E_n
   against the model's prediction with its own uncertainty; beside each, JCGM 101's Monte Carlo (``monte_carlo``,
   seeded). A branch with |E_n| > 1 is a problem naming its likely causes.
7. **Verdict** (:mod:`crane_stiffness.analysis.verdict`): NOT OK when a fit is not a stiffness, the fitted axis is
   not the loaded one, or a branch is far from the model; the budget figure (:mod:`crane_stiffness.analysis.
   budget_figure`) beside the others.

A damaged bag (truncated, bad chunk) is analysed from its readable part, with the damage listed in the report; a
missing sensor topic raises :class:`~crane_stiffness.bag.TopicNotFoundError` naming it and the topics present;
missing optional topics (commands, program state, live estimates) are named in the report.
"""
from __future__ import annotations

import json
import math
import warnings
from dataclasses import asdict
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from crane_stiffness import __version__

from crane_stiffness.contract import topics
from crane_stiffness.analysis import report
from crane_stiffness.analysis.errors import SessionAnalysisError
from crane_stiffness.analysis.live_check import live_comparison
from crane_stiffness.analysis.load import SessionData, load_session
from crane_stiffness.analysis.mapping import SensorMapping
from crane_stiffness.analysis.model_summary import accepted_commands, model_summary
from crane_stiffness.analysis.progress import Progress
from crane_stiffness.analysis.results import (CycleFits, SessionAnalysis, Step)
from crane_stiffness.analysis.stiffness_uncertainty import model_disagreements, session_uncertainty
from crane_stiffness.analysis.verdict import Verdict, fit_problem_line
from crane_stiffness.bag import BagDamageWarning
from crane_stiffness.contract.command_limits import command_faults
from crane_stiffness.params.geometry import geometry_from_params
from crane_stiffness.estimation.branch import BRANCHES, LOADING, UNLOADING
from crane_stiffness.estimation import quality
from crane_stiffness.estimation.fit import LineFit, fit_or_none
from crane_stiffness.estimation.inputs import INPUT_CHECKS, CommandSeries, Samples, checked_samples
from crane_stiffness.contract.axes import AXES
from crane_stiffness.estimation.live_pairs import LivePairs, live_pairs
from crane_stiffness.estimation.settings import LiveSettings
from crane_stiffness.estimation.stream_delay import stream_delay_of
from crane_stiffness.estimation.offset import correct_stamps

STAGES = ('open+decode', 'pair', 'stream delay', 'steps', 'fits', 'model', 'uncertainty', 'summary', 'figures',
          'budget figure', 'report')
#: Shortest run of equal commands taken as a hold [s].
MIN_HOLD_S = 0.2


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


def _inputs(data: SessionData) -> tuple[Samples, Samples, dict[str, int]]:
    """The live estimator's input checks on both streams: the (force, displacement) samples kept, and the counts."""
    s = data.settings
    f, d = data.force, data.disp
    assert f is not None and d is not None  # the required topics: load_session decoded both
    f_stamp = f['stamp_s']
    finite = np.isfinite(f_stamp)
    for k in AXES:  # a NaN/Inf anywhere in the wrench drops the sample, as live
        finite &= np.isfinite(f[k])
    if s.force_row() is None:  # the sensor at the platform centre, aligned: the component as recorded
        component = f[s.force_axis]
    else:
        component = s.force_component(np.column_stack([f[k] for k in AXES]) if f.size else np.zeros((0, 6)))
    # The clock-skew check: live, a stamp ahead of its arrival at the estimator; here, ahead of the recorder's log
    # time of the message (its arrival at the recorder, on the same clock; a few ms from the estimator's).
    # The wrench moved from the sensor's frame to the platform centre (sensor_rotation, _position, _reaction), the
    # live estimator's matrix, vectorised; as is when the sensor is at the centre.
    force, f_counts = checked_samples(f_stamp, f['log_time_ns'], component, finite, s.max_abs_force,
                                      s.max_clock_skew_s)
    if data.mapping is None or data.mapping.displacement_type == 'point_stamped':
        d_stamp = d['stamp_s']
        d_value = s.reading_to_displacement(d['x'].astype(float))
    else:  # std_msgs/Float64 in volts: no stamp, taken at its arrival as live (here the recorder's log time)
        d_stamp = d['log_time_ns'] * 1e-9
        d_value = s.reading_to_displacement(s.volts_to_displacement(d['data']))
    d_stamp = correct_stamps(d_stamp, s.displacement_delay_s)  # the instants the samples were taken, as live
    disp, d_counts = checked_samples(d_stamp, d['log_time_ns'], d_value, np.isfinite(d_value) & np.isfinite(d_stamp),
                                     s.max_abs_displacement, s.max_clock_skew_s)
    counters = {'force_messages': int(f.size), 'displacement_messages': int(d.size),
                **{name: f_counts[name] + d_counts[name] for name in INPUT_CHECKS}}
    return force, disp, counters


def _commands(data: SessionData) -> CommandSeries | None:
    """The commands as the live estimator holds them: absurd ones (command_limits, the model's own check)
    and the model's rejections (/crane/rejected_command, decoded with the other streams) held as rejected."""
    c = data.command
    if c is None or c.size == 0:
        return None
    wrench = np.column_stack([c[k].astype(float) for k in AXES])
    r_stamp = r_log = None
    rejected = data.rejected
    if rejected is not None and rejected.size:
        r_stamp, r_log = rejected['stamp_s'], rejected['log_time_ns']
    return CommandSeries.of(c['stamp_s'], c['log_time_ns'], c[data.settings.force_axis].astype(float),
                            command_faults(wrench), r_stamp, r_log)


def _steps(data: SessionData, pairs: LivePairs, commands: CommandSeries | None, t0: float, settle_fraction: float,
           problems: list[str]) -> list[Step]:
    if commands is None:
        return []
    stamp, value = accepted_commands(commands)
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
        assert data.program is not None  # matched holds are the program's
        if len(runs) != len(data.program.holds(data.settings.force_axis)):
            problems.append(f'the commands show {len(runs)} of the program\'s '
                            f'{len(data.program.holds(data.settings.force_axis))} holds on {data.settings.force_axis} '
                            f'(from hold {offsets[0] + 1}): the recording does not cover the whole program')
    elif data.program is not None:
        problems.append(f'the commands show {len(runs)} hold(s) on {data.settings.force_axis} that do not match the '
                        f'recorded program\'s {len(holds)}: steps are labelled from the commands alone')
    steps: list[Step] = []
    previous_level, approach = None, 'loading'
    repeat: int | None
    segment: int | None
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


def _branch_fits(settings: LiveSettings, pairs: LivePairs, lo: int, hi: int) -> dict[str, LineFit | None]:
    """Each branch's fit over the pairs ``lo:hi``, counting the displacement noise as the live estimator does
    (``displacement_noise``: declared, or estimated from the branch's displacements)."""
    sel = slice(lo, hi)
    x, y, loading = pairs.displacement[sel], pairs.force[sel], pairs.loading[sel]
    out: dict[str, LineFit | None] = {}
    for branch, chosen in ((LOADING, loading), (UNLOADING, ~loading)):
        xb = x[chosen]
        out[branch] = fit_or_none(xb, y[chosen], settings.displacement_noise_of(xb))
    return out


def _fit_quality(data: SessionData, pairs: LivePairs, lo: int, hi: int, fits: dict[str, LineFit | None],
                 problems: list[str], failures: list[str]) -> dict[str, float]:
    """The live estimator's trust rules (estimation.quality) on each branch fit and on the loaded axis: problems
    appended, to ``failures`` too (they make the verdict NOT OK); returns each branch's scatter ratio."""
    s = data.settings
    c = data.command
    if c is not None and c.size:
        wrench = np.column_stack([c[k].astype(float) for k in AXES])
        wrench = wrench[np.isfinite(wrench).all(axis=1) & ~command_faults(wrench)]
        if wrench.size:
            axis_problem = quality.axis_problem(s.force_axis, wrench.min(axis=0), wrench.max(axis=0))
            if axis_problem:
                problems.append(axis_problem)
                failures.append(axis_problem)
    scatter = {}
    loading = pairs.loading[lo:hi]
    for branch, fit in fits.items():
        scatter[branch] = math.nan
        if fit is None:
            continue
        chosen = loading if branch == LOADING else ~loading
        scatter[branch] = quality.scatter_ratio(pairs.displacement[lo:hi][chosen], pairs.force[lo:hi][chosen],
                                                float(fit.stiffness), float(fit.residual_rms))
        found = quality.fit_problems(float(fit.stiffness), float(fit.ci95_low), float(fit.ci95_high),
                                     scatter[branch], s.max_scatter_ratio)
        if found:
            line = fit_problem_line(branch, found, float(fit.stiffness))
            problems.append(line)
            failures.append(line)
    return scatter


def _cycles(data: SessionData, pairs: LivePairs, steps: list[Step], t0: float) -> list[CycleFits]:
    if data.program is None or data.program.repeats < 2 or not steps or steps[0].repeat is None:
        return []
    starts: dict[int, float] = {}
    for step in steps:
        assert step.repeat is not None  # matched to the program: every step has its repeat (checked on steps[0])
        starts.setdefault(step.repeat, step.start_s)
    order = sorted(starts)
    out = []
    for i, r in enumerate(order):
        start = starts[r] if i else 0.0
        end = starts[order[i + 1]] if i + 1 < len(order) else steps[-1].end_s
        lo, hi = np.searchsorted(pairs.stamp, [t0 + start, t0 + end], side='left')
        fits = _branch_fits(data.settings, pairs, int(lo), int(hi))
        out.append(CycleFits(repeat=r, start_s=start, end_s=end, loading=fits[LOADING], unloading=fits[UNLOADING]))
    return out


def _default_out(bag: Path) -> Path:
    return Path('out') / 'analysis' / bag.name


def analyze_session(bag_path: str | Path, out_dir: str | Path | None = None, *, formats: Sequence[str] = ('png',),
                    reports: Sequence[str] = ('md',), write_json: bool = True, axis: str | None = None,
                    settle_fraction: float = 0.3, model_points: int = 41, progress: bool = False,
                    write_files: bool = True, mapping: SensorMapping | None = None,
                    uncertainty_file: str | Path | None = None, monte_carlo: bool = True,
                    prediction_monte_carlo: bool | None = None) -> SessionAnalysis:
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
        mapping: the sensor topics, the displacement's type and conversion, estimator parameters from a file and
            the geometry (:class:`~crane_stiffness.analysis.mapping.SensorMapping`; default: the rig's topics, as
            recorded); the result's ``mapping`` says what was used.
        uncertainty_file: the crane inputs' uncertainties for the model's prediction and E_n (default
            config/uncertainty_lab.yaml; :mod:`crane_stiffness.analysis.stiffness_uncertainty`).
        monte_carlo: JCGM 101's Monte Carlo beside each GUM result (seeded; False: the GUM alone, ~0.4 s less).
        prediction_monte_carlo: the prediction's alone (None: as ``monte_carlo``); E_n's reference U follows it.

    Returns:
        the :class:`SessionAnalysis` (its ``files`` lists what was written).

    Raises:
        BagNotFoundError / BagFormatError: no readable bag at ``bag_path``.
        TopicNotFoundError: a sensor topic is missing (named, with the topics present).
        SessionAnalysisError: nothing to pair or fit; a sensor topic of another type than expected (both named).
        ParameterError / MappingError: a bad value of the mapping (named).
    """
    _check_options(formats, reports, settle_fraction)
    path = Path(bag_path)
    problems: list[str] = []
    failures: list[str] = []  # the problems that make the verdict NOT OK
    missing: list[str] = []
    bar = Progress(progress, len(STAGES) if write_files else len(STAGES) - 3, f'analyze {path.name}')
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter('always', BagDamageWarning)
            bar.stage('open+decode')
            data = load_session(path, axis, problems, missing, mapping)
            bar.done()
            bar.stage('pair')
            force, disp, input_counters = _inputs(data)
            commands = _commands(data)
            pairs = live_pairs(data.settings, force, disp, commands)
            if pairs.stamp.size < 3:
                raise SessionAnalysisError(
                    f'{path}: only {pairs.stamp.size} load-cell/LVDT pair(s) by {data.settings.pairing_text()} '
                    f'({force.stamp.size} force and {disp.stamp.size} displacement samples usable)')
            bar.done()
            bar.stage('stream delay')
            _, delay_problem, delay_values = stream_delay_of(data.settings, force, disp)
            bar.done()
            bar.stage('steps')
            t0 = float(commands.stamp[0]) if commands is not None else float(pairs.stamp[0])
            steps = _steps(data, pairs, commands, t0, settle_fraction, problems)
            bar.done()
            bar.stage('fits')
            fits = _fits(data, pairs, commands, steps, t0, problems, failures)
            bar.done()
            bar.stage('model')
            model = model_summary(data, steps, commands, model_points, problems)
            bar.done()
            bar.stage('uncertainty')
            uncertainty = session_uncertainty(data, pairs, *_program_span(pairs, commands), steps,
                                              fits['branch_fits'], fits['hold_fits'], model, problems,
                                              uncertainty_file, monte_carlo, prediction_monte_carlo)
            disagreements = model_disagreements(uncertainty, data.settings.stiffness_unit)
            bar.done()
        bar.stage('summary')
        problems[:0] = _rewarn(caught)
        counters = {**input_counters, **pairs.counters}
        problems += _missing_topic_problems(missing) + ([delay_problem] if delay_problem else [])
        problems += _input_problems(counters, data.settings) + disagreements
        result = SessionAnalysis(
            bag=str(path), session=str(data.session.get('session') or path.name),
            notes=str(data.session.get('notes', '')), recorded_with=str(data.session.get('software_version', '')),
            analysed_with=__version__, start_time_utc=_start_time_utc(data),
            duration_s=((data.end_ns or 0) - (data.start_ns or 0)) * 1e-9, axis=data.settings.force_axis,
            unit=data.settings.stiffness_unit, program=_program_summary(data),
            geometry=_geometry_summary(data, problems), settings=asdict(data.settings), counts=data.counts,
            pairing=counters, steps=steps, model=model, problems=problems, missing_topics=missing,
            stream_delay=dict(delay_values), mapping=data.mapping.to_dict() if data.mapping else {},
            uncertainty=uncertainty, model_disagreements=disagreements,
            verdict=Verdict(failures + disagreements).to_dict(), **fits)
        bar.done()
        if write_files:
            out = Path(out_dir) if out_dir is not None else _default_out(path)
            out.mkdir(parents=True, exist_ok=True)
            bar.stage('figures')
            from crane_stiffness.analysis import figures
            result.files += figures.write_session_figures(result, data, pairs, commands, t0, out, formats)
            bar.done()
            bar.stage('budget figure')
            from crane_stiffness.analysis.budget_figure import write_budget_figure
            result.files += write_budget_figure(result, out, formats)
            bar.done()
            bar.stage('report')
            result.timings_s = dict(bar.timings)
            result.files += report.write_session_report(result, out, reports)
            if write_json:
                result.files.append(str(out / 'analysis.json'))
                (out / 'analysis.json').write_text(json.dumps(result.to_dict(), indent=1, allow_nan=False))
            bar.done()
        result.timings_s = dict(bar.timings)
        return result
    finally:
        bar.close()


def _check_options(formats: Sequence[str], reports: Sequence[str], settle_fraction: float) -> None:
    for fmt in formats:
        if fmt not in ('png', 'svg'):
            raise ValueError(f'format = {fmt!r}: must be png or svg')
    for kind in reports:
        if kind not in ('md', 'html'):
            raise ValueError(f'report = {kind!r}: must be md or html')
    if not 0.0 <= settle_fraction < 1.0:
        raise ValueError(f'settle_fraction = {settle_fraction!r}: must be in [0, 1)')


def _program_span(pairs: LivePairs, commands: CommandSeries | None) -> tuple[int, int]:
    """The pairs fitted over the program: indices lo:hi from its first command to its last (all without commands)."""
    if commands is None:
        return 0, int(pairs.stamp.size)
    return (int(np.searchsorted(pairs.stamp, commands.stamp[0], side='left')),
            int(np.searchsorted(pairs.stamp, commands.stamp[-1], side='right')))


def _fits(data: SessionData, pairs: LivePairs, commands: CommandSeries | None, steps: list[Step], t0: float,
          problems: list[str], failures: list[str]) -> dict[str, Any]:
    """The 'fits' stage: each branch over the program, the hold means of each approach, each repeat's branches, and
    the live estimate checked (SessionAnalysis fields)."""
    lo, hi = _program_span(pairs, commands)
    branch_fits = _branch_fits(data.settings, pairs, lo, hi)
    _fit_quality(data, pairs, lo, hi, branch_fits, problems, failures)
    hold_fits = {}
    for approach in BRANCHES:
        sel = [s for s in steps if s.approach == approach and s.n > 0]
        hold_fits[approach] = fit_or_none(np.array([s.displacement_mean for s in sel]),
                                          np.array([s.force_mean for s in sel]))
    live = live_comparison(data, pairs)
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
    return {'branch_fits': branch_fits, 'hold_fits': hold_fits, 'cycle_fits': _cycles(data, pairs, steps, t0),
            'live': live}


def _rewarn(caught: list[warnings.WarningMessage]) -> list[str]:
    """Warnings caught while reading, raised again for the caller; the bag's damage, as problems."""
    damage = []
    for w in caught:
        if issubclass(w.category, BagDamageWarning):
            damage.append(str(w.message))
            warnings.warn(str(w.message), BagDamageWarning, stacklevel=3)
        else:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    return damage


def _missing_topic_problems(missing: list[str]) -> list[str]:
    return [f'topic {topic} is not in the bag' + {
        topics.WRENCH_COMMAND: ': no test steps; branches follow the measured force',
        topics.STIFFNESS_VALUES: ': no live estimate to compare with',
        topics.PROGRAM_STATE: ': program state unknown',
    }.get(topic, '') for topic in missing]


def _input_problems(counters: dict[str, Any], st: LiveSettings) -> list[str]:
    """The live estimator's warnings about its inputs, offline: what it would have said about these."""
    problems = []
    if counters.get('dropped_clock_skew'):
        problems.append(f'{counters["dropped_clock_skew"]} sensor sample(s) stamped more than max_clock_skew_s = '
                        f'{st.max_clock_skew_s:g} s ahead of their log time were dropped (a skewed sensor clock)')
    if counters.get('pairs_rejected_command'):
        problems.append(f'{counters["pairs_rejected_command"]} pair(s) made while a rejected command (absurd, or '
                        f'rejected by the crane model) was in force were not fitted')
    if counters.get('late_rejections'):
        problems.append(f'{counters["late_rejections"]} rejected command(s) reached the live estimator after pairs '
                        f'stamped under them were fitted: its estimate held them (WARN) until they left its window')
    for stream in ('force', 'displacement'):
        fraction = counters.get(f'{stream}_received_fraction', math.nan)
        if fraction < 1.0 - st.max_loss_fraction:
            problems.append(f'{stream}: the bag holds {fraction:.2%} of the samples its stamps say were sent '
                            f'(more than max_loss_fraction = {st.max_loss_fraction:.2%} lost)')
    return problems


def _start_time_utc(data: SessionData) -> str:
    start_ns = int(data.session.get('start_time_ns') or data.start_ns or 0)
    return datetime.fromtimestamp(start_ns / 1e9, tz=timezone.utc).isoformat() if start_ns else ''


def _program_summary(data: SessionData) -> dict[str, Any] | None:
    if data.program is None:
        return None
    p = data.program
    program = {**p.to_params(), 'duration_s': p.duration_s, 'levels': p.levels(data.settings.force_axis).tolist(),
               'source': (data.program_record or {}).get('source', '')}
    final = [s for _, s in data.states]
    program['final_state'] = final[-1].get('state') if final else None
    return program


def _geometry_summary(data: SessionData, problems: list[str]) -> dict[str, Any] | None:
    if data.geometry_params is None:
        return None
    try:
        g = geometry_from_params(data.geometry_params)
    except ValueError as exc:
        problems.append(f'recorded geometry invalid: {exc}')
        return None
    return {**g.to_dict(), 'l0': g.l0, 'k': g.k}
