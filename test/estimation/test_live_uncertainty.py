"""The live estimate states U beside its statistical interval, and E_n against the model (estimation.live_uncertainty
through LiveStiffness): the budget is the offline one (uncertainty.measurement) fed with the window's fit and spans;
|E_n| > 1 is WARN, never OK."""
from __future__ import annotations

import math

import numpy as np
import pytest

from crane_stiffness.contract.status import OK, WARN
from crane_stiffness.estimation.live import LiveStiffness
from crane_stiffness.estimation.live_uncertainty import LiveBudget, cross_load_ratio
from crane_stiffness.estimation.settings import LiveSettings
from crane_stiffness.params.files import config_path, load_params
from crane_stiffness.uncertainty.measurement import SlopeStatistics, measured_stiffness

K = 50000.0     # N/m
PERIOD = 0.002  # s
T0 = 1000.0     # s


def _sensors() -> tuple[dict, dict]:
    """The load cell's and the LVDT's parameters as config/sensors.yaml declares them (what the node reads)."""
    path = str(config_path('sensors.yaml'))
    return load_params(path, 'load_cell'), load_params(path, 'lvdt')


def _live(prediction: float | None = None, relative_U: float = math.nan, calibrated: bool = True) -> LiveStiffness:
    rng = np.random.default_rng(3)
    n = 600
    command = np.concatenate([np.linspace(0.0, 4.0, n // 2), np.linspace(4.0, 0.0, n - n // 2)])
    force = command + rng.normal(0.0, 0.01, n)
    x = command / K + rng.normal(0.0, 2e-8, n)
    live = LiveStiffness(LiveSettings(window=1000, hysteresis=0.05))
    if calibrated:
        live.calibrations = _sensors()
    if prediction is not None:
        live.set_prediction(prediction)
    live.prediction_relative_U = relative_U
    for i, (f, d) in enumerate(zip(force, x)):
        t = T0 + i * PERIOD
        live.add_command(t, (0.0, command[i], 0.0, 0.0, 0.0, 0.0), t)
        live.add_force(t, (0.0, f, 0.0, 0.0, 0.0, 0.0))
        live.add_displacement(t, d)
    live.refresh()
    live.values()
    return live


def _status(live: LiveStiffness, branch: str):
    return next(r for r in live.report() if r.branch == branch)


def test_the_branch_U_is_the_offline_budget_of_the_window_fit() -> None:
    live = _live()
    est = live.estimate('loading')
    x, y = live._estimator.window_data('loading')
    load_cell, lvdt = _sensors()
    by_hand = measured_stiffness(SlopeStatistics(float(est.stiffness), float(est.stderr), float(est.n - 2), 's'),
                                 'fy', load_cell=load_cell, lvdt=lvdt, force_span=float(np.ptp(y)),
                                 displacement_span=float(np.ptp(x)))
    unc = live.uncertainty('loading')
    assert unc is not None and not unc.statistical_only
    assert unc.U == pytest.approx(by_hand.result.U, rel=1e-12)
    assert unc.k == pytest.approx(1.96, abs=0.01)
    # the calibrations make U: the load cell's 1 % (k = 2) alone is 0.5 % of k, the statistical interval far less
    assert 0.005 * K < unc.U < 0.05 * K
    status = _status(live, 'loading')
    values = dict(status.values)
    assert status.level == OK
    assert float(values['U']) == pytest.approx(unc.U, rel=1e-5)
    ci = float(values['ci95_high']) - float(values['ci95_low'])
    assert ci < unc.U  # the two intervals differ: repeatability inside U
    assert 'repeatability' in status.message and f'U = {unc.U:.4g} N/m (k = 1.96, 95 %)' in status.message
    assert 'load_cell_sensitivity' in values['calibration']
    assert values['En'] == 'nan'  # no prediction yet


def test_without_declarations_the_U_is_statistical_only_and_says_so() -> None:
    live = _live(calibrated=False)
    unc = live.uncertainty('loading')
    assert unc is not None and unc.statistical_only
    status = _status(live, 'loading')
    assert 'statistical only' in status.message
    assert dict(status.values)['statistical_only'] == 'true'
    # U is then the fit's: its standard error times the coverage factor
    est = live.estimate('loading')
    assert unc.U == pytest.approx(unc.k * float(est.stderr), rel=1e-9)


def test_near_the_model_E_n_is_small_and_the_status_stays_OK() -> None:
    live = _live(prediction=K * 1.01, relative_U=0.061)
    unc = live.uncertainty('loading')
    assert unc is not None and abs(unc.en) < 1.0
    assert unc.U_prediction == pytest.approx(K * 1.01 * 0.061)
    expected = (unc.value - K * 1.01) / math.hypot(unc.U, K * 1.01 * 0.061)
    assert unc.en == pytest.approx(expected, rel=1e-12)
    status = _status(live, 'loading')
    assert status.level == OK and f'E_n = {unc.en:+.2f}' in status.message


@pytest.mark.parametrize('factor', [1.5, 0.5, -1.0])
def test_far_from_the_model_beyond_its_uncertainty_is_WARN_naming_the_likely_causes(factor: float) -> None:
    # a wrong gain (x1.5 or x0.5) or sign: the measurement lies far outside both U
    live = _live(prediction=K * factor, relative_U=0.061)
    unc = live.uncertainty('loading')
    assert unc is not None and abs(unc.en) > 1.0
    status = _status(live, 'loading')
    assert status.level == WARN
    assert status.message.startswith('far from the model beyond its uncertainty')
    for cause in ('gain', 'sign', 'units', 'orientation', 'topics'):
        assert cause in status.message


def test_cross_load_ratio_from_the_commands_range() -> None:
    low, high = np.array([-1.0, 0.0, 0.0, 0, 0, 0]), np.array([0.5, 4.0, 2.0, 0.1, 0, 0])
    assert cross_load_ratio('fy', low, high) == pytest.approx(0.5)
    assert cross_load_ratio('mx', low, high) == 0.0  # mx alone among the moments
    assert cross_load_ratio('fy', np.full(6, np.inf), np.full(6, -np.inf)) == 0.0


@pytest.mark.parametrize('calibrated', [True, False])
def test_the_cached_type_B_gives_the_full_budget_s_numbers(calibrated: bool) -> None:
    """The refreshes between changes of the spans combine a new Type A with the cached relative Type B: the numbers
    of the full budget, whatever the slope, its standard error and n (down to few degrees of freedom)."""
    load_cell, lvdt = _sensors() if calibrated else (None, None)
    calibrations = (load_cell, lvdt)
    budget = LiveBudget()
    first = budget.branch('loading', 'fy', 'N/m', 53790.0, 3.0, 11000, 4.0, 7.4e-5, calibrations=calibrations)
    assert first is not None
    for k, se, n in [(53000.0, 5.0, 9000), (51000.0, 800.0, 8), (60000.0, 0.4, 400), (20000.0, 3000.0, 5)]:
        cached = budget.branch('loading', 'fy', 'N/m', k, se, n, 4.0, 7.4e-5, calibrations=calibrations)
        full = measured_stiffness(SlopeStatistics(k, se, float(n - 2), 's'), 'fy', load_cell=load_cell, lvdt=lvdt,
                                  force_span=4.0, displacement_span=7.4e-5).result
        assert cached is not None
        assert cached.U == pytest.approx(full.U, rel=1e-8)
        assert cached.u_c == pytest.approx(full.u_c, rel=1e-8)
        assert cached.k == pytest.approx(full.k, rel=1e-8)
        assert cached.nu_eff == pytest.approx(full.nu_eff, rel=1e-6)


def test_a_span_that_changes_the_type_B_recomputes_it() -> None:
    """Below the smooth-slope clamp the (non)linearities' bound is e/R: a narrower span, a larger U."""
    calibrations = _sensors()
    budget = LiveBudget()
    wide = budget.branch('loading', 'fy', 'N/m', 53790.0, 3.0, 11000, 30.0, 5e-3, calibrations=calibrations)
    narrow = budget.branch('loading', 'fy', 'N/m', 53790.0, 3.0, 11000, 20.0, 3e-3, calibrations=calibrations)
    full = measured_stiffness(SlopeStatistics(53790.0, 3.0, 10998.0, 's'), 'fy', load_cell=calibrations[0],
                              lvdt=calibrations[1], force_span=20.0, displacement_span=3e-3).result
    assert wide is not None and narrow is not None and narrow.U > wide.U
    assert narrow.U == pytest.approx(full.U, rel=1e-12)
