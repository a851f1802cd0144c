"""The live stiffness estimate of the rig: input checks, stamp pairing, branch fits, outputs. Pure Python, no ROS.

:class:`LiveStiffness` is everything the ``stiffness_estimator`` node does between decoding a message and
publishing one:

1. Input checks. A force sample is the selected component (``force_axis``, N or N·m) of a wrench, moved first from
   the F/T sensor's frame to the platform centre in crane_base (``sensor_rotation``, ``sensor_position``,
   ``sensor_reaction``; :class:`~crane_stiffness.estimation.frames.SensorMount`: one row of its 6×6 matrix per
   sample, nothing when the sensor is at the centre, aligned); a displacement sample is a reading in m (or rad), or a
   voltage converted by ``x = displacement_gain · V + displacement_offset``, its stamp corrected to
   ``t − displacement_delay_s``. :class:`~crane_stiffness.estimation.stream_delay.StreamDelay` estimates the delay
   left between the streams from the recent
   data (:func:`~crane_stiffness.estimation.offset.estimate_delay`) and WARNs above ``max_stream_delay_s``.
   Dropped and counted (:class:`~crane_stiffness.estimation.inputs.InputCounters`): a NaN/Inf anywhere in the
   sample, a zero (or negative) stamp, a stamp more than ``max_clock_skew_s`` ahead of its arrival (node clock), a
   selected force above ``max_abs_force`` or a displacement above ``max_abs_displacement`` in magnitude
   (:func:`~crane_stiffness.estimation.inputs.input_faults`), and a message its reader could not decode
   (:meth:`LiveStiffness.add_malformed`). Each stream's health (:class:`~crane_stiffness.estimation.inputs.
   StreamHealth`): the fraction of its samples received (WARN above ``max_loss_fraction`` lost) and, given the node
   clock, silence (longer than ``dropout_factor`` delivery periods and ``min_silence_s``: ERROR, both branches STALE).
   A sensor publisher
   whose sequence numbers start again (a restart, which zeroes the sensor) starts a new fit segment
   (:meth:`LiveStiffness.new_segment`), and so does a re-zero or tare without a restart: a change of the sensor's
   zero epoch (:meth:`LiveStiffness.zero_epoch`, topics.LVDT_ZERO / LOAD_CELL_TARE).
2. Pairing by header stamp (``pairing``): by nearest stamp with :class:`~crane_stiffness.estimation.sync.
   ApproximateTimeSync` (``slop_s``), or each sample of the slower stream with the faster one interpolated at its
   stamp with :class:`~crane_stiffness.estimation.sync.InterpolatingSync` (``max_interpolation_gap_s``); both with
   ``max_age_s``, ``expected_period_s``, ``dropout_factor``: out-of-order and stale samples are counted there and
   never fitted; dropouts are counted.
3. Fitting each pair with :class:`~crane_stiffness.estimation.estimator.StiffnessEstimator` (windowed fit with
   errors in both variables and RLS with forgetting, loading and unloading branches apart; the displacement noise
   counted, ``displacement_noise``, is the sensor's specification or estimated from each branch's window at every
   :meth:`LiveStiffness.refresh`). The branch follows the commanded load (the
   ``force_axis`` component of the wrench command in effect at the pair's stamp) once a command has been seen and
   ``branch_source`` is ``'auto'``, else the measured force. A pair stamped while a rejected command is in force
   (absurd by :mod:`crane_stiffness.contract.command_limits`, the crane model's own rule, or republished by the model on
   /crane/rejected_command; from its stamp to the next accepted command) is not fitted, and the statuses say so
   (WARN, never OK).
4. Outputs. :meth:`LiveStiffness.values` is the cheap O(1) numeric estimate (rows ``BRANCHES`` × ``VALUE_FIELDS``)
   for publishing after every batch of new pairs; its ``nonlinearity`` is the value of the last
   :meth:`LiveStiffness.refresh`, which sorts the windows and is meant for a slow timer together with
   :meth:`LiveStiffness.report` (per-branch text for people, with a level: WAITING for a branch without an
   estimate yet, STALE for every branch once a stream that delivered goes silent;
   :mod:`crane_stiffness.contract.status`).

The model prediction (``set_prediction``) gives ``relative_error = (estimate − prediction) / prediction``.

:func:`live_pairs` is steps 1–3 up to the fit for whole recorded streams at once (numpy, the offline analysis of a
session): the pairs :class:`LiveStiffness` would fit and the branch of each, from the vectorized forms that sit beside
each streaming rule (:mod:`~crane_stiffness.estimation.inputs`, :func:`~crane_stiffness.estimation.sync.pair_by_stamp`,
:func:`~crane_stiffness.estimation.branch.branch_labels`).
"""
from __future__ import annotations

import math
from collections.abc import Sequence


from crane_stiffness.estimation.branch import BRANCHES, LOADING, Branch
from crane_stiffness.estimation.estimator import Estimate
from crane_stiffness.estimation.fit import t_quantile
from crane_stiffness.estimation.fit_lines import fit_line_rows
from crane_stiffness.estimation.quality import CommandRange
from crane_stiffness.estimation.settings import LiveSettings
from crane_stiffness.estimation.stream_delay import StreamDelay
from crane_stiffness.contract.command_limits import command_fault
from crane_stiffness.estimation import live_status
from crane_stiffness.estimation.live_status import VALUE_FIELDS, BranchReport
from crane_stiffness.estimation.live_uncertainty import BranchUncertainty, LiveBudget, cross_load_ratio
from crane_stiffness.estimation.lag import LagHistogram
from crane_stiffness.estimation.inputs import (CommandHold, InputCounters, StreamHealth,
                                               command_inputs, input_faults)
from crane_stiffness.contract.status import ERROR, OK, WARN
from crane_stiffness.estimation.sync import (DISPLACEMENT, FORCE, ApproximateTimeSync, InterpolatingSync, Pair,
                                             SyncCounters)

#: Columns of one row of :meth:`LiveStiffness.take_fitted_pairs`: stamp s, displacement m (rad), force N (N·m),
#: branch 0 loading / 1 unloading, fit segment number.
PAIR_FIELDS = ('stamp', 'displacement', 'force', 'branch', 'segment')

# Student-t quantiles computed ahead when a fit starts (t_quantile's cache holds 1024).
_T_CACHE = 1000



class LiveStiffness:
    """Streams in, live stiffness estimate out (see the module docstring)."""

    def __init__(self, settings: LiveSettings | None = None) -> None:
        self.counters = InputCounters()
        self.prediction = math.nan
        self.lag = LagHistogram()
        self._settings = settings or LiveSettings()
        self._zero_epochs: dict[str, float] = {}  # the last zero epoch seen per stream (see zero_epoch)
        #: Keep every fitted pair for :meth:`take_fitted_pairs` (the node's live view topic); off: nothing kept.
        self.record_pairs = False
        self._fitted_pairs: list[float] = []
        # The sensors' declared calibrations (their nodes' parameters; None: not read) and the model prediction's
        # U / value (NaN: unknown): what each branch's U and E_n are computed from at refresh (live_uncertainty).
        self.calibrations: tuple[dict | None, dict | None] = (None, None)
        self.prediction_relative_U = math.nan
        self._budget = LiveBudget()
        self._build(None)

    def _build(self, old: ApproximateTimeSync | InterpolatingSync | None) -> None:
        """(Re)build pairing and fitting from the settings; ``old``: the pairing being replaced (None at start)."""
        s = self._settings
        self._axis = s.axis_index
        self._force_row = s.force_row()  # None: the sensor is the platform centre's frame, take the component as is
        self._delay_correction = s.displacement_delay_s
        self._sync = s.make_sync()
        if old is not None:  # the counters go on across restarts: every message stays accounted
            self._sync.carry_counters(old)
        self._estimator = s.make_estimator()
        self._commands = CommandHold()
        self._command_range = CommandRange()
        for dof in range(1, min(s.window - 1, _T_CACHE)):  # fill scipy's t quantiles now, not one per pair later
            t_quantile(dof)
        self._last_report: dict[str, tuple[int, ...]] = {}  # input_report's previous problem counts per consumer
        self._new_health()
        self._segment_reason = 'start'
        self._clear_outputs()

    def _new_health(self) -> None:
        period = self._settings.expected_period_s or None
        self.health = {FORCE: StreamHealth(period), DISPLACEMENT: StreamHealth(period)}
        self._delay = StreamDelay(self._settings)
        self._rejection: tuple[str, float] | None = None  # (reason, stamp) of the rejected command now in force

    def _clear_outputs(self) -> None:
        self._nonlinearity = {b: math.nan for b in BRANCHES}
        self._scatter = {b: math.nan for b in BRANCHES}
        self._uncertainty: dict[Branch, BranchUncertainty | None] = {b: None for b in BRANCHES}
        self._rows: dict[Branch, list[float]] = {b: self._row(None) for b in BRANCHES}
        self._dirty: set[Branch] = set()
        self._current: Branch | None = None
        self._newest_stamp = math.nan
        self._suspect: dict[Branch, int] = {b: 0 for b in BRANCHES}  # pairs until a late rejection leaves the window
        self._noise_due: dict[Branch, int] = {b: 3 for b in BRANCHES}  # pairs until _update_noise
        self._suspect_reason = ''

    @property
    def settings(self) -> LiveSettings:
        return self._settings

    @property
    def sync_counters(self) -> SyncCounters:
        return self._sync.counters

    @property
    def segment_reason(self) -> str:
        """Why the current fit segment started ('start', '~/reset', 'force publisher restarted', ...)."""
        return self._segment_reason

    def configure(self, settings: LiveSettings) -> bool:
        """Take new settings; returns True if the change restarted pairing and fitting (counters are kept)."""
        restart = settings.fit_key() != self._settings.fit_key()
        self._settings = settings
        if restart:
            self.counters.fit_restarts += 1
            self.counters.segments += 1
            self._build(self._sync)
            self._segment_reason = 'parameters changed'
        return restart

    def reset(self) -> None:
        """Start afresh, as at start-up, but keep the counters: the fits of both branches, the branch tracker, the
        pairing's queues and timing, the commands held, the streams' health (~/reset)."""
        self.new_segment('~/reset', commands=True)

    def new_segment(self, reason: str, *, commands: bool = False) -> None:
        """Start a new fit segment (a sensor restarted or was re-zeroed: the old window must not mix with the new
        zero point): fits, branch tracker, pairing and stream health start afresh; with ``commands`` the commands
        held too. The reason is reported in every status until the next segment."""
        self._estimator.reset()
        self._sync.restart()
        if commands:
            self._commands = CommandHold()
        self._command_range.reset()
        self._new_health()
        self._clear_outputs()
        self.counters.fit_restarts += 1
        self.counters.segments += 1
        self._segment_reason = reason

    def zero_epoch(self, stream: str, epoch: float) -> bool:
        """The zero epoch of a sensor (``stream``: FORCE or DISPLACEMENT; the number of zero/tare operations since
        the sensor started, [-]). A change while this segment holds readings of that sensor starts a new segment
        ('lvdt re-zeroed' / 'load cell tared'): its readings stepped by the new zero. The first epoch seen, or a
        change before any reading (a sensor that zeroes at its first pose), starts none. Returns True if it did."""
        before = self._zero_epochs.get(stream)
        self._zero_epochs[stream] = epoch
        if before is None or epoch == before or not self.health[stream].count:
            return False
        self.new_segment('lvdt re-zeroed' if stream == DISPLACEMENT else 'load cell tared')
        return True

    # --- inputs ---
    def set_prediction(self, value: float) -> bool:
        """The model's predicted stiffness along the axis (N/m or N·m/rad); non-finite values are ignored."""
        value = float(value)
        if not math.isfinite(value):
            return False
        self.prediction = value
        for b in BRANCHES:
            self._dirty.add(b)
        return True

    def add_command(self, stamp_s: float, wrench: Sequence[float], arrival_s: float) -> bool:
        """A wrench command [N, N·m]; a zero stamp counts from ``arrival_s``. Returns False if dropped (NaN/Inf in
        its load along the axis or its times) or rejected (absurd by :mod:`crane_stiffness.contract.command_limits`:
        held as a
        rejected command, pairs are not fitted while it is in force)."""
        self.counters.command_received += 1
        load = float(wrench[self._axis])
        usable, stamp = command_inputs(stamp_s, arrival_s, load)
        if not usable:
            self.counters.command_dropped += 1
            return False
        reason = command_fault(wrench)
        if reason is not None:
            self.counters.command_rejected += 1
            self._commands.add(float(stamp), load, f'absurd command: {reason}')
            self._rejected_late(float(stamp), 'an absurd command')
            return False
        self.counters.command_used += 1
        self._commands.add(float(stamp), load)
        self._command_range.add(wrench)
        return True

    def add_rejected(self, stamp_s: float, wrench: Sequence[float], arrival_s: float) -> None:
        """A command the crane model rejected (/crane/rejected_command, the command with its own stamp): from its
        stamp until the next accepted command no pair is fitted."""
        self.counters.rejected_received += 1
        usable, stamp = command_inputs(stamp_s, arrival_s, 0.0)
        if not usable:
            return
        reason = command_fault(wrench) or 'no equilibrium'
        self._commands.add(float(stamp), math.nan, f'command rejected by the crane model ({reason})', from_model=True)
        self._rejected_late(float(stamp), 'a command rejected by the crane model')

    def _rejected_late(self, stamp_s: float, what: str) -> None:
        """A rejected command that arrived after pairs stamped under it were fitted (the sensor streams overtook it:
        the model answers after it has solved, a loaded machine delays a topic): those pairs, the newest of the
        windows, are in the fits against the rule that nothing stamped while a rejected command is in force is
        fitted. Each branch is WARN, naming it, until ``window`` more pairs of the branch have pushed them out of
        its window (the pairs themselves are usually sound: the sensors kept the load the model held). Offline:
        :func:`~crane_stiffness.estimation.live_pairs.late_rejections`."""
        if self._newest_stamp >= stamp_s:
            self.counters.late_rejections += 1
            self._suspect = {b: self._settings.window for b in BRANCHES}
            self._suspect_reason = (f'{what} (stamped {stamp_s:.6f} s) reached the estimator after pairs stamped '
                                    'under it were fitted')

    def add_force(self, stamp_s: float, wrench: Sequence[float], arrival_s: float = math.nan,
                  sequence: int | None = None) -> int:
        """A wrench sample [N, N·m] stamped ``stamp_s``, arrived at ``arrival_s`` (s, node clock; NaN: unknown), with
        its publisher's sequence number if known; returns the number of pairs it completed and fitted."""
        self.counters.force_received += 1
        finite = all(math.isfinite(v) for v in wrench) and math.isfinite(stamp_s)
        r = self._force_row
        if r is None:
            value = float(wrench[self._axis])
        else:  # moved to the platform centre in crane_base (frames.SensorMount), only the component fitted
            w0, w1, w2, w3, w4, w5 = wrench
            value = r[0] * w0 + r[1] * w1 + r[2] * w2 + r[3] * w3 + r[4] * w4 + r[5] * w5
        return self._sample(FORCE, finite, stamp_s, value, self._settings.max_abs_force, arrival_s, sequence)

    def add_malformed(self, stream: str) -> None:
        """Count a ``'force'`` or ``'displacement'`` message that could not be decoded (dropped)."""
        if stream == FORCE:
            self.counters.force_received += 1
            self.counters.force_dropped += 1
        else:
            self.counters.displacement_received += 1
            self.counters.displacement_dropped += 1
        self.counters.dropped_malformed += 1

    def add_displacement(self, stamp_s: float, value_m: float, arrival_s: float = math.nan,
                         sequence: int | None = None) -> int:
        """A displacement sample, m (or rad); returns the number of pairs it completed and fitted."""
        self.counters.displacement_received += 1
        value = self._settings.reading_to_displacement(float(value_m))
        finite = math.isfinite(value) and math.isfinite(stamp_s)
        stamp_s -= self._delay_correction  # displacement_delay_s: the instant the sample was taken
        return self._sample(DISPLACEMENT, finite, stamp_s, value, self._settings.max_abs_displacement, arrival_s,
                            sequence)

    def add_volts(self, stamp_s: float, volts: float, sequence: int | None = None) -> int:
        """A displacement sample in volts, converted with displacement_gain and displacement_offset, stamped on its
        arrival (``stamp_s`` is the arrival)."""
        self.counters.displacement_received += 1
        value = self._settings.reading_to_displacement(self._settings.volts_to_displacement(float(volts)))
        finite = math.isfinite(value) and math.isfinite(stamp_s)
        return self._sample(DISPLACEMENT, finite, stamp_s - self._delay_correction, value,
                            self._settings.max_abs_displacement, stamp_s, sequence)

    def _sample(self, stream: str, finite: bool, stamp_s: float, value: float, limit: float, arrival_s: float,
                sequence: int | None) -> int:
        if not self._accepted(stream, finite, stamp_s, value, limit, arrival_s):
            return 0
        health = self.health[stream]
        if sequence is not None:
            if health.sequence is not None and sequence < health.sequence and health.count:
                # A publisher numbers its messages from 1: a number that goes back is a new publisher, a restarted
                # sensor (which zeroes itself again): its readings must not share a window with the old ones.
                self.new_segment(f'{stream} publisher restarted (sequence number {health.sequence} -> {sequence})')
                health = self.health[stream]
            health.sequence = sequence
        health.add(stamp_s, arrival_s)
        self._delay.add(stream, stamp_s, value)
        return self._fit(self._sync.push(stream, stamp_s, value))

    def _accepted(self, stream: str, finite: bool, stamp_s: float, value: float, limit: float,
                  arrival_s: float) -> bool:
        """The input checks (:func:`~crane_stiffness.estimation.inputs.input_faults`); a dropped sample is counted."""
        non_finite, zero_stamp, skew, absurd = input_faults(finite, stamp_s, value, limit, arrival_s,
                                                            self._settings.max_clock_skew_s)
        c = self.counters
        if non_finite:
            c.dropped_non_finite += 1
        elif zero_stamp:
            c.dropped_zero_stamp += 1
        elif skew:
            c.dropped_clock_skew += 1
        elif absurd:
            c.dropped_absurd += 1
        else:
            return True
        if stream == FORCE:
            c.force_dropped += 1
        else:
            c.displacement_dropped += 1
        return False

    def _fit(self, pairs: list[Pair]) -> int:
        fitted = 0
        use_command = self._settings.branch_source == 'auto'
        commands = self._commands
        for pair in pairs:
            stamp = pair.stamp_s
            entry = commands.entry(stamp) if commands else None
            if entry is not None and entry[1] is not None:
                # A rejected command is in force: the sensors may show it (or not); either way not a load the model
                # holds, so not a point of the stiffness curve.
                self.counters.pairs_rejected_command += 1
                if self._rejection is None or self._rejection[0] != entry[1]:
                    self._rejection = (entry[1], stamp)
                continue
            self._rejection = None
            load = entry[0] if (entry is not None and use_command) else None
            branch = self._estimator.add(stamp, pair.force, pair.displacement, load)
            if branch is None:
                self.counters.pairs_non_finite += 1
                continue
            self._dirty.add(branch)
            self._current = branch
            self._newest_stamp = stamp
            self._noise_due[branch] -= 1
            if self._noise_due[branch] <= 0:
                self._update_noise(branch)
            if self._suspect[branch]:
                self._suspect[branch] -= 1
            fitted += 1
            if self.record_pairs:
                self._fitted_pairs += (stamp, pair.displacement, pair.force, 0.0 if branch == LOADING else 1.0,
                                       float(self.counters.segments))
        self.counters.pairs_fitted += fitted
        return fitted

    def _update_noise(self, branch: Branch) -> None:
        """Count the displacement noise of ``branch``'s window (``displacement_noise``: declared, or estimated from
        the window) in its fit from now on. Due after a number of the branch's pairs, never on a clock, so a replay of
        the same pairs gives the same estimates: when the window has doubled (from 3 pairs), then every tenth of
        ``window``."""
        held = self._estimator.window_len(branch)
        x_noise = self._settings.displacement_noise_of(self._estimator.window_data(branch)[0])
        self._estimator.set_displacement_noise(branch, x_noise)
        self._noise_due[branch] = max(3, min(held, self._settings.window // 10))

    # --- outputs ---
    def _row(self, est: Estimate | None, x_noise: float = math.nan) -> list[float]:
        nan = math.nan
        pred = self.prediction
        if est is None:  # no estimate; the noise it would have counted (analyze reproduces the "none" with it)
            row = [nan] * len(VALUE_FIELDS)
            row[VALUE_FIELDS.index('prediction')] = pred
            row[VALUE_FIELDS.index('x_noise')] = x_noise
            return row
        # One windowed fit: its LineFit fields (typed float or array) are floats; float() keeps them as they are.
        k, c, se, lo, hi, r2, rms = map(float, (est.stiffness, est.intercept, est.stderr, est.ci95_low, est.ci95_high,
                                                est.r2, est.residual_rms))
        rel = (k - pred) / pred if math.isfinite(pred) and pred != 0.0 else nan
        return [k, c, se, lo, hi, r2, float(est.n), rms, nan, est.rls_stiffness, est.rls_stderr, float(est.x_noise),
                pred, rel, 0.0, nan]

    def estimate(self, branch: Branch) -> Estimate | None:
        """The cheap windowed estimate of ``branch`` (its nonlinearity is NaN; see :meth:`refresh`)."""
        return self._estimator.estimate(branch)

    def values(self) -> list[float]:
        """Rows ``BRANCHES`` × ``VALUE_FIELDS``, row-major; O(1) (only branches with new pairs are recomputed)."""
        i_nl = VALUE_FIELDS.index('nonlinearity')
        self._update_rows()
        out: list[float] = []
        for branch in BRANCHES:
            row = self._rows[branch]
            row[i_nl] = self._nonlinearity[branch]
            row[-2] = 1.0 if branch == self._current else 0.0
            row[-1] = self._newest_stamp
            out.extend(row)
        return out

    def _update_rows(self) -> None:
        for branch in self._dirty:
            self._rows[branch] = self._row(self._estimator.estimate(branch), self._estimator.x_noise(branch))
        self._dirty.clear()

    def take_fitted_pairs(self) -> list[float]:
        """The pairs fitted since the previous call (with :attr:`record_pairs`), rows × PAIR_FIELDS, row-major."""
        out, self._fitted_pairs = self._fitted_pairs, []
        return out

    def fit_lines(self) -> list[float]:
        """Each branch's window as a line with its band (:func:`~.fit_lines.fit_line_rows`; O(window))."""
        return fit_line_rows(self._estimator)

    def published(self, now_s: float) -> None:
        """Note that :meth:`values` was published at ``now_s`` (s, the clock of the stamps): records the lag."""
        self.lag.add(now_s - self._newest_stamp)

    @property
    def newest_stamp(self) -> float:
        """Stamp of the newest fitted pair, s (NaN before the first)."""
        return self._newest_stamp

    def loading_stiffness(self) -> float:
        """Windowed stiffness of the loading branch, N/m or N·m/rad (NaN while there is none)."""
        self._update_rows()
        return self._rows[LOADING][0]

    def headline_stiffness(self) -> float:
        """The number /stiffness/stiffness carries: the loading branch's stiffness, NaN while there is none and in a
        six-axis program (a one-axis fit of a multi-axis load is no number to publish; the values for tools keep
        it, beside the 'not applicable' status)."""
        return math.nan if self._settings.six_axis_program else self.loading_stiffness()

    def refresh(self) -> dict[Branch, float]:
        """Recompute the nonlinearity indicator and scatter of each branch's window (each a pass over the window: call
        it slowly)."""
        for branch in BRANCHES:
            self._nonlinearity[branch] = self._estimator.nonlinearity(branch)
            self._scatter[branch] = self._estimator.scatter_ratio(branch)
            self._uncertainty[branch] = self._branch_uncertainty(branch)
        self._delay.update()
        return dict(self._nonlinearity)

    def _branch_uncertainty(self, branch: Branch) -> BranchUncertainty | None:
        """``branch``'s k with U and E_n now (:func:`~.live_uncertainty.branch_uncertainty`; a pass over its window
        for the spans the fit covers)."""
        est = self._estimator.estimate(branch)
        if est is None:
            return None
        s = self._settings
        x, y = self._estimator.window_data(branch)
        x_span = float(x.max() - x.min()) * (s.lever_arm_m if s.lever_arm_m > 0.0 else 1.0)  # as the LVDT reads
        return self._budget.branch(branch, s.force_axis, s.stiffness_unit, float(est.stiffness), float(est.stderr),
                                   int(est.n), float(y.max() - y.min()), x_span, calibrations=self.calibrations,
                                   cross_load=cross_load_ratio(s.force_axis, self._command_range.low,
                                                               self._command_range.high),
                                   prediction=self.prediction, prediction_relative_U=self.prediction_relative_U)

    def uncertainty(self, branch: Branch) -> BranchUncertainty | None:
        """``branch``'s k with U and E_n as of the last :meth:`refresh` (None without an estimate then)."""
        return self._uncertainty[branch]

    @property
    def stream_delay(self) -> StreamDelay:
        """The estimate of the delay between the streams (updated by :meth:`refresh`)."""
        return self._delay

    def input_problems(self, now_s: float = math.nan) -> tuple[int, list[str]]:
        """What makes the inputs invalid or doubtful now (``now_s``: the node clock, s; NaN: silence not judged):
        (worst level, reasons). ERROR: a stream silent for longer than ``dropout_factor`` delivery periods and
        ``min_silence_s`` (a dead sensor, not a busy machine's hiccup); WARN: a rejected command in force, a stream
        that lost more than ``max_loss_fraction``, and for a one-axis program a stream delay beyond
        ``max_stream_delay_s`` or commands moving other axes than the fitted one (neither judged in a six-axis
        program: both judge the one-axis fit)."""
        s = self._settings
        level, reasons = OK, []
        for stream, health in self.health.items():
            limit = health.silence_limit(s.dropout_factor)
            limit = max(limit, s.min_silence_s) if math.isfinite(limit) else limit
            silent = health.silent_for(now_s)
            if health.count and silent > limit:
                level = ERROR
                reasons.append(f'{stream} silent for {silent:.3g} s (> {limit:.3g} s: {s.dropout_factor:g} '
                               f'periods, at least min_silence_s): sensor dead or disconnected?')
        if self._rejection is not None:
            level = max(level, WARN)
            reasons.append(f'{self._rejection[0]} in force since stamp {self._rejection[1]:.6f} s: '
                           f'{self.counters.pairs_rejected_command} pair(s) not fitted so far')
        for stream, health in self.health.items():
            fraction = health.received_fraction()
            if fraction < 1.0 - s.max_loss_fraction:
                level = max(level, WARN)
                reasons.append(f'{stream}: received {fraction:.2%} of its samples (lost {1.0 - fraction:.2%} > '
                               f'max_loss_fraction {s.max_loss_fraction:.2%})')
        # (the delay is estimated from the fitted axis' force against its displacement: under a six-axis program's
        # combined loading that correlation judges the one-axis fit, not the sensors)
        delay_problem = '' if s.six_axis_program else self._delay.problem()
        if delay_problem:
            level = max(level, WARN)
            reasons.append(delay_problem)
        # (combined loading is what a six-axis program does: no problem there)
        axis_problem = '' if s.six_axis_program else self._command_range.problem(s.force_axis)
        if axis_problem:
            level = max(level, WARN)
            reasons.append(axis_problem)
        return level, reasons

    def report(self, now_s: float = math.nan) -> list[BranchReport]:
        """Per-branch status for people (:func:`~.live_status.branch_reports`); call after :meth:`refresh` and
        :meth:`values`. A branch without an estimate yet is WAITING; with ``now_s`` (the node clock, s) a dead
        input stream makes every branch STALE."""
        self._update_rows()
        return live_status.branch_reports(self, now_s)

    def accounting(self) -> dict[str, int]:
        """Every message accounted (the node's final counters; :func:`~.live_status.accounting`)."""
        return live_status.accounting(self)

    def input_report(self, consumer: str = '', now_s: float = math.nan) -> tuple[int, str, list[tuple[str, str]]]:
        """Input health: (level, message, key/values) (:func:`~.live_status.input_report`)."""
        return live_status.input_report(self, consumer, now_s)
