"""Tests of crane_stiffness.estimation.live: the stiffness_estimator node's logic without ROS."""
from __future__ import annotations

import math

import numpy as np
import pytest

from crane_stiffness.estimation.branch import BranchTracker
from crane_stiffness.estimation.errors import ParameterError
from crane_stiffness.estimation.fit import fit_line
from crane_stiffness.estimation.live import VALUE_FIELDS, LiveStiffness
from crane_stiffness.estimation.lag import LagHistogram
from crane_stiffness.estimation.quality import noise_std
from crane_stiffness.estimation.settings import LiveSettings
from crane_stiffness.contract.status import OK, WAITING, WARN

K = 2000.0      # N/m
C = 0.1         # N
PERIOD = 0.002  # s
T0 = 1000.0     # s, a plausible header stamp


def _triangle(n: int, peak: float = 4.0) -> np.ndarray:
    half = n // 2
    return np.concatenate([np.linspace(0.0, peak, half), np.linspace(peak, 0.0, n - half)])


def _wrench(fy: float) -> tuple[float, ...]:
    return (0.0, fy, 0.0, 0.0, 0.0, 0.0)


def _row(values: list[float], branch: int) -> dict[str, float]:
    n = len(VALUE_FIELDS)
    return dict(zip(VALUE_FIELDS, values[branch * n:(branch + 1) * n]))


def _feed(live: LiveStiffness, force: np.ndarray, x: np.ndarray, t0: float = T0, command: np.ndarray | None = None):
    fitted = 0
    for i, (f, d) in enumerate(zip(force, x)):
        t = t0 + i * PERIOD
        if command is not None:
            live.add_command(t, _wrench(command[i]), t)
        fitted += live.add_force(t, _wrench(f))
        fitted += live.add_displacement(t, d)
    return fitted


def test_settings_validation_names_the_value() -> None:
    assert LiveSettings.from_params({}) == LiveSettings()
    for values, name in [({'force_axis': 'fq'}, 'force_axis'), ({'window': 2}, 'window'),
                         ({'slop_s': -1.0}, 'slop_s'), ({'slop_s': 0.2, 'max_age_s': 0.1}, 'max_age_s'),
                         ({'forgetting': 1.5}, 'forgetting'), ({'dropout_factor': 0.5}, 'dropout_factor'),
                         ({'displacement_gain': 0.0}, 'displacement_gain'), ({'hysteresis': math.nan}, 'hysteresis'),
                         ({'branch_source': 'psychic'}, 'branch_source'), ({'max_abs_force': 0.0}, 'max_abs_force'),
                         ({'pairing': 'closest'}, 'pairing'),
                         ({'max_interpolation_gap_s': 0.0}, 'max_interpolation_gap_s')]:
        with pytest.raises(ParameterError) as info:
            LiveSettings.from_params(values)
        assert info.value.field == name and repr(values[name]) in str(info.value)


def test_branches_match_batch_fits_of_the_same_pairs() -> None:
    rng = np.random.default_rng(5)
    n = 400
    command = _triangle(n)
    force = command + rng.normal(0.0, 0.02, n)
    x = (command - C) / K + rng.normal(0.0, 1e-7, n)
    live = LiveStiffness(LiveSettings(window=1000, hysteresis=0.05))
    fitted = _feed(live, force, x, command=command)
    assert fitted == n - 1 or fitted == n  # the newest pair may wait for its successor
    values = live.values()
    loading, unloading = _row(values, 0), _row(values, 1)
    # The branch follows the (noise-free) command, with the dead band's lag after the peak.
    tracker = BranchTracker(0.05)
    up = np.array([tracker.update(c) == 'loading' for c in command])
    assert n // 2 < up.sum() < n // 2 + 5
    # the fit counts the displacement noise estimated from the window (displacement_noise -1), as fit_line does with
    # the noise the row reports (errors in both variables); least squares alone comes out lower
    sigma = loading['x_noise']
    assert 0.5e-7 < sigma < 2e-7 and sigma == pytest.approx(noise_std(x[up]), rel=0.5)
    ref = fit_line(x[up], force[up], x_noise=sigma)
    assert loading['stiffness'] == pytest.approx(ref.stiffness, rel=1e-9)
    assert loading['stiffness'] > fit_line(x[up], force[up]).stiffness
    assert loading['ci95_low'] < K < loading['ci95_high']
    assert unloading['stiffness'] == pytest.approx(K, rel=0.02)
    assert unloading['current'] == 1.0 and loading['current'] == 0.0
    assert loading['sample_stamp'] == unloading['sample_stamp'] == pytest.approx(T0 + (fitted - 1) * PERIOD)
    assert math.isnan(loading['nonlinearity'])  # only after refresh()
    nl = live.refresh()
    assert abs(nl['loading']) < 0.05
    assert _row(live.values(), 0)['nonlinearity'] == nl['loading']
    # the noise is updated after a number of pairs, never by refresh() (a clock): a replay gives the same numbers
    assert live.loading_stiffness() == loading['stiffness']
    reports = live.report()
    assert [r.level for r in reports] == [OK, OK]
    assert 'N/m' in reports[0].message


def test_prediction_gives_relative_error() -> None:
    live = LiveStiffness()
    assert math.isnan(_row(live.values(), 0)['relative_error'])
    n = 200
    f = np.linspace(0.0, 2.0, n)
    _feed(live, f, f / K)
    assert live.set_prediction(1600.0)
    assert not live.set_prediction(math.inf)
    row = _row(live.values(), 0)
    assert row['prediction'] == 1600.0
    assert row['relative_error'] == pytest.approx((K - 1600.0) / 1600.0, rel=1e-6)


def test_bad_samples_are_dropped_and_counted_and_never_fitted() -> None:
    live = LiveStiffness(LiveSettings(max_abs_force=100.0, max_abs_displacement=0.01))
    assert live.add_force(T0, _wrench(math.nan)) == 0
    assert live.add_force(T0, (math.inf, 1.0, 0.0, 0.0, 0.0, 0.0)) == 0  # NaN/Inf anywhere in the wrench
    assert live.add_displacement(T0, math.inf) == 0
    assert live.add_force(T0, _wrench(1e6)) == 0
    assert live.add_displacement(T0, 5.0) == 0
    assert live.add_force(0.0, _wrench(1.0)) == 0
    c = live.counters
    assert (c.dropped_non_finite, c.dropped_absurd, c.dropped_zero_stamp) == (3, 2, 1)
    assert live.sync_counters.force.received == 0
    level, message, pairs = live.input_report()
    assert level == WARN and '6 dropped' in message
    level, message, _ = live.input_report()  # nothing new since; no usable sample yet: the inputs wait
    assert level == WAITING and message.startswith('waiting: no usable force or displacement sample yet'), message


def test_out_of_order_samples_are_counted_and_not_fitted() -> None:
    live = LiveStiffness()
    n = 100
    f = np.linspace(0.0, 2.0, n)
    _feed(live, f, f / K)
    before = live.counters.pairs_fitted
    # Late samples with wild values, stamped before what was already received.
    for i in range(5):
        live.add_force(T0 + i * PERIOD, _wrench(50.0))
        live.add_displacement(T0 + i * PERIOD, -0.005)
    assert live.sync_counters.total('out_of_order') == 10
    assert live.counters.pairs_fitted == before
    assert _row(live.values(), 0)['stiffness'] == pytest.approx(K, rel=1e-9)


def test_volts_channel_and_reset_and_restart_on_change() -> None:
    settings = LiveSettings(displacement_gain=0.002, displacement_offset=-0.001)
    live = LiveStiffness(settings)
    n = 100
    f = np.linspace(0.0, 2.0, n)
    volts = (f / K + 0.001) / 0.002
    for i in range(n):
        live.add_force(T0 + i * PERIOD, _wrench(f[i]))
        live.add_volts(T0 + i * PERIOD, volts[i])
    assert _row(live.values(), 0)['stiffness'] == pytest.approx(K, rel=1e-9)
    live.reset()
    assert math.isnan(_row(live.values(), 0)['stiffness'])
    assert live.report()[0].level == WAITING  # a fresh start: nothing stopped, the branch has not begun again
    # A threshold change keeps the fit; a fit setting restarts it.
    assert not live.configure(LiveSettings(displacement_gain=0.002, displacement_offset=-0.001,
                                           nonlinearity_warn=0.5))
    assert live.configure(LiveSettings(window=50))
    assert live.counters.fit_restarts == 2


def test_softening_curve_is_reported_nonlinear() -> None:
    live = LiveStiffness(LiveSettings(window=1000, nonlinearity_warn=0.2))
    n = 400
    f = np.linspace(0.0, 8.0, n)
    x = f / K + np.where(f > 4.0, (f - 4.0) / (0.3 * K), 0.0)  # stiffness drops to 23 % above 4 N (slack)
    _feed(live, f, x)
    nl = live.refresh()['loading']
    assert nl > 0.5
    report = live.report()[0]
    assert report.level == WARN and 'nonlinear' in report.message
    assert dict(report.values)['nonlinearity'] == f'{nl:.6g}'


def test_branch_follows_the_command_in_effect_at_each_pair_stamp() -> None:
    live = LiveStiffness(LiveSettings(hysteresis=0.05))
    n = 200
    f = np.concatenate([np.linspace(0.0, 2.0, n // 2), np.linspace(2.0, 0.0, n // 2)])
    # The command reverses at the peak; the measured force lags it by 20 samples (a slow actuator): the branch
    # must follow the command, so the unloading branch starts at the command's reversal.
    command_stamps = T0 + np.arange(n) * PERIOD
    command = np.concatenate([np.linspace(0.0, 2.0, n // 2 - 20), np.linspace(2.0, 0.0, n // 2 + 20)])
    for t, c in zip(command_stamps, command):
        live.add_command(t, _wrench(c), t)
    _feed(live, f, f / K)
    assert live.counters.command_received == n
    unloading = live.estimate('unloading')
    assert unloading is not None and unloading.n > n // 2 + 10


def test_lag_histogram_percentiles_match_numpy_to_a_bin() -> None:
    rng = np.random.default_rng(4)
    lags = rng.lognormal(mean=np.log(2e-3), sigma=0.6, size=20_000)  # s, a latency-like tail
    hist = LagHistogram(limit_s=0.05)
    assert math.isnan(hist.percentile(50)) and math.isnan(hist.max_s)
    for v in lags.tolist() + [math.nan, math.inf]:  # non-finite lags are not counted
        hist.add(v)
    assert hist.n == lags.size and hist.max_s == lags.max()
    for q in (1, 50, 90, 99, 99.9):
        exact = np.percentile(lags, q, method='inverted_cdf')
        assert exact <= hist.percentile(q) <= exact + LagHistogram.BIN_S, q
    over = LagHistogram(limit_s=0.01)
    over.add(5.0)  # beyond the range: counted in the last bin, max exact
    assert over.percentile(50) == pytest.approx(0.0101) and over.max_s == 5.0


def test_published_records_the_lag_of_the_newest_pair() -> None:
    live = LiveStiffness(LiveSettings(window=10, slop_s=1e-4))
    live.published(100.0)  # nothing fitted yet: no lag
    assert live.lag.n == 0
    for i in range(5):
        t = 100.0 + i * 1e-3
        live.add_force(t, (0.0, 2.0 * i, 0.0, 0.0, 0.0, 0.0))
        live.add_displacement(t, 1e-3 * i)
    live.published(live.newest_stamp + 0.0025)
    assert live.lag.n == 1 and live.lag.max_s == pytest.approx(0.0025)
    pairs = dict(live.input_report()[2])
    assert pairs['lag_n'] == '1' and float(pairs['lag_p50_ms']) == pytest.approx(2.6, abs=0.11)


@pytest.mark.parametrize('pairing', ['interpolate_force', 'interpolate_displacement'])
def test_interpolated_pairing_live_equals_the_vectorised_pairs(pairing) -> None:
    """A 1 kHz F/T sensor and a 100 Hz Modbus LVDT off its grid (or the other way round): LiveStiffness fits the
    pairs live_pairs finds (the slow stream's samples, the fast one interpolated), to the last bit of the fit;
    every message is accounted for."""
    from crane_stiffness.estimation.inputs import Samples
    from crane_stiffness.estimation.live_pairs import live_pairs

    rng = np.random.default_rng(9)
    fast_force = pairing == 'interpolate_force'
    t_fast = T0 + np.arange(4000) * 1e-3 + rng.normal(0, 2e-5, 4000)
    t_slow = T0 + 4.3e-3 + np.arange(400) * 1e-2 + rng.normal(0, 5e-5, 400)
    t_f, t_d = (t_fast, t_slow) if fast_force else (t_slow, t_fast)
    load = lambda t: np.interp(t, [T0, T0 + 2, T0 + 4], [0.0, 4.0, 0.0])  # noqa: E731  a 2 s ramp up and down
    force = load(t_f) + rng.normal(0, 0.01, t_f.size)
    x = (load(t_d) - C) / K + rng.normal(0, 1e-7, t_d.size)
    arrival_f = np.maximum.accumulate(t_f + rng.uniform(1e-4, 2e-3, t_f.size))
    arrival_d = np.maximum.accumulate(t_d + rng.uniform(1e-4, 2e-2, t_d.size))
    settings = LiveSettings(pairing=pairing, max_interpolation_gap_s=2e-3, window=5000, hysteresis=0.05)
    live = LiveStiffness(settings)
    arrivals = [(a, 0, i) for i, a in enumerate(arrival_f)] + [(a, 1, i) for i, a in enumerate(arrival_d)]
    for _, kind, i in sorted(arrivals):
        if kind == 0:
            live.add_force(t_f[i], _wrench(force[i]), arrival_f[i])
        else:
            live.add_displacement(t_d[i], x[i], arrival_d[i])
    ns = lambda a: np.round(a * 1e9).astype(np.int64)  # noqa: E731
    pairs = live_pairs(settings, Samples(t_f, ns(arrival_f), force), Samples(t_d, ns(arrival_d), x), None)
    n_slow = 400
    assert live.counters.pairs_fitted == pairs.stamp.size > 0.95 * n_slow
    values = live.values()
    for branch, sel in ((0, pairs.loading), (1, ~pairs.loading)):
        row = _row(values, branch)  # the fit with the displacement noise it reports counted (errors in both variables)
        ref = fit_line(pairs.displacement[sel], pairs.force[sel], x_noise=row['x_noise'])
        assert row['n'] == sel.sum()
        assert row['stiffness'] == pytest.approx(ref.stiffness, rel=1e-12)
        assert row['stiffness'] == pytest.approx(K, rel=0.01)
    acc = live.accounting()
    for stream in ('force', 'displacement'):
        parts = sum(acc[f'{stream}_{k}'] for k in ('paired', 'out_of_order', 'non_finite', 'stale', 'unmatched',
                                                  'discarded', 'pending'))
        assert acc[f'{stream}_passed_checks'] == parts == acc[f'{stream}_received'] - acc[f'{stream}_dropped']
    assert acc['pairs'] == acc['pairs_fitted']


def test_a_rejection_that_arrives_after_pairs_under_it_were_fitted_is_warned_until_they_leave_the_window() -> None:
    """A rejected command stamped before pairs already fitted (the sensor streams overtook it): those pairs are in
    the windows, so each branch is WARN, naming it, until ``window`` more of its pairs have pushed them out. One that
    arrives before any pair stamped under it changes nothing."""
    n, window = 300, 100
    command = _triangle(n)
    live = LiveStiffness(LiveSettings(window=window, hysteresis=0.05))
    _feed(live, command, (command - C) / K, command=command)
    assert all(r.level == OK for r in live.report())
    live.add_rejected(T0 + 250 * PERIOD, _wrench(2.0), T0 + n * PERIOD)  # stamped under fitted pairs
    assert live.counters.late_rejections == 1 and live.counters.segments == 1
    reports = live.report()
    assert all(r.level == WARN and 'reached the estimator after pairs stamped under it were fitted' in r.message
               for r in reports), [r.message for r in reports]
    assert live.estimate('loading') is not None  # the fits go on
    # window more pairs of each branch (a new triangle, after an accepted command): OK again.
    t1 = T0 + n * PERIOD
    _feed(live, _triangle(4 * window), (_triangle(4 * window) - C) / K, t0=t1, command=_triangle(4 * window))
    assert all(r.level == OK for r in live.report()), [r.message for r in live.report()]
    # Absurd, stamped in the past: the same; stamped after every fitted pair: nothing.
    live.add_command(t1 + 5 * PERIOD, _wrench(1e30), t1 + 4 * window * PERIOD)
    assert live.counters.late_rejections == 2
    live.add_rejected(T0 + 100.0, _wrench(2.0), T0 + 100.0)
    assert live.counters.late_rejections == 2


def test_in_a_six_axis_program_every_part_says_not_applicable_never_a_one_axis_verdict() -> None:
    """The same softening, multi-axis commands (fy with fz and mx beside it): a one-axis estimator is WARN 'combined
    loading' and 'nonlinear'; told the program is six-axis, every status is OK 'not applicable' pointing to the 6x6
    status, while the pairs are still fitted (the same numbers)."""
    n = 400
    f = np.linspace(0.0, 8.0, n)
    x = f / K + np.where(f > 4.0, (f - 4.0) / (0.3 * K), 0.0)
    reports = {}
    for six in (False, True):
        live = LiveStiffness(LiveSettings(window=1000, nonlinearity_warn=0.2, six_axis_program=six))
        for i, (fi, d) in enumerate(zip(f, x)):
            t = T0 + i * PERIOD
            live.add_command(t, (0.0, fi, 3.0 * fi, 0.2 * fi, 0.0, 0.0), t)
            live.add_force(t, _wrench(fi))
            live.add_displacement(t, d)
        live.refresh()
        reports[six] = (live.report(), live.input_report('test'), live.values(), live.headline_stiffness())
    one, six = reports[False], reports[True]
    assert one[0][0].level == WARN and 'nonlinear' in one[0][0].message
    assert one[1][0] == WARN and 'combined loading' in one[1][1]
    for report in six[0]:
        assert report.level == OK, report
        assert report.message == ('not applicable: six-axis program, a one-axis fit of fy means nothing under its '
                                  'multi-axis load; see /stiffness6/status')
    assert six[1][0] == OK and six[1][1].startswith('not applicable: six-axis program') and 'combined' not in six[1][1]
    assert six[2] == one[2]  # the same pairs fitted, the same numbers recorded
    assert one[3] > 0 and math.isnan(six[3])  # but no headline number (/stiffness/stiffness) for a six-axis program
