"""Tests of crane_stiffness.estimation.fit: accuracy, interval coverage, streaming fits, branches, nonlinearity."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from crane_stiffness.errors import CraneStiffnessError
from crane_stiffness.estimation import (BranchTracker, DataError, ParameterError, RecursiveLeastSquares,
                                        StiffnessEstimator, WindowedLeastSquares, fit_line)
from crane_stiffness.sim import LoadProgram, Segment

K_TRUE = 850.0  # N/m, of the order of the lab model's side stiffness
C_TRUE = 0.3  # N, a tare error
NOISE = 0.05  # N, load-cell noise


def _line_data(rng: np.random.Generator, shape: tuple[int, ...], n: int = 40) -> tuple[np.ndarray, np.ndarray]:
    x = np.broadcast_to(np.linspace(0.0, 0.012, n), shape + (n,))
    return x, K_TRUE * x + C_TRUE + rng.normal(0.0, NOISE, shape + (n,))


def test_fit_line_exact_line() -> None:
    x = np.array([0.0, 1e-3, 2e-3, 5e-3])
    fit = fit_line(x, 1200.0 * x - 0.7)
    assert fit.stiffness == pytest.approx(1200.0, rel=1e-12)
    assert fit.intercept == pytest.approx(-0.7, abs=1e-12)
    assert fit.stderr == pytest.approx(0.0, abs=1e-8)
    assert fit.r2 == pytest.approx(1.0)
    assert fit.n == 4
    assert isinstance(fit.stiffness, float)


def test_fit_line_matches_scipy_linregress() -> None:
    rng = np.random.default_rng(3)
    x, y = _line_data(rng, ())
    fit = fit_line(x, y)
    ref = stats.linregress(x, y)
    assert fit.stiffness == pytest.approx(ref.slope, rel=1e-12)
    assert fit.intercept == pytest.approx(ref.intercept, rel=1e-10)
    assert fit.stderr == pytest.approx(ref.stderr, rel=1e-10)
    assert fit.intercept_stderr == pytest.approx(ref.intercept_stderr, rel=1e-10)
    assert fit.r2 == pytest.approx(ref.rvalue ** 2, rel=1e-12)
    half = stats.t.ppf(0.975, len(x) - 2) * ref.stderr
    assert (fit.ci95_low, fit.ci95_high) == pytest.approx((ref.slope - half, ref.slope + half), rel=1e-12)
    assert fit.residual_rms == pytest.approx(NOISE, rel=0.3)


def test_fit_line_small_bias_and_95_percent_coverage() -> None:
    rng = np.random.default_rng(20240501)
    trials = 500
    x, y = _line_data(rng, (trials,), n=20)
    fit = fit_line(x, y)  # one vectorised call: 500 independent fits
    assert fit.stiffness.shape == (trials,)
    expected_se = NOISE / np.sqrt(((x[0] - x[0].mean()) ** 2).sum())
    # Bias: mean over 500 trials within 3 standard errors of the mean of the true value.
    assert abs(fit.stiffness.mean() - K_TRUE) < 3.0 * expected_se / math.sqrt(trials)
    assert fit.stiffness.std(ddof=1) == pytest.approx(expected_se, rel=0.1)
    assert np.median(fit.stderr) == pytest.approx(expected_se, rel=0.1)
    coverage = np.mean((fit.ci95_low <= K_TRUE) & (K_TRUE <= fit.ci95_high))
    assert 0.92 <= coverage <= 0.98


def test_fit_line_batch_equals_single_fits() -> None:
    rng = np.random.default_rng(5)
    x, y = _line_data(rng, (3, 2))
    batch = fit_line(x, y)
    for i in range(3):
        for j in range(2):
            single = fit_line(x[i, j], y[i, j])
            assert batch.stiffness[i, j] == pytest.approx(single.stiffness, rel=1e-12)
            assert batch.stderr[i, j] == pytest.approx(single.stderr, rel=1e-10)
            assert batch.nonlinearity[i, j] == pytest.approx(single.nonlinearity, rel=1e-9, abs=1e-12)


def test_fit_line_offset_data_keeps_precision() -> None:
    # An un-zeroed LVDT (1 m offset) and a 1 kN preload must not cost digits.
    x = 1.0 + np.linspace(0.0, 1e-3, 11)
    fit = fit_line(x, 1000.0 + 500.0 * (x - 1.0))
    assert fit.stiffness == pytest.approx(500.0, rel=1e-8)


@pytest.mark.parametrize(('x', 'y', 'match'), [
    ([0.0, 1.0], [0.0, 1.0], 'at least 3 points'),
    ([2.0, 2.0, 2.0, 2.0], [0.0, 1.0, 2.0, 3.0], 'zero spread'),
    ([0.0, 1.0, math.nan], [0.0, 1.0, 2.0], 'finite'),
])
def test_fit_line_errors(x: list[float], y: list[float], match: str) -> None:
    with pytest.raises(DataError, match=match) as info:
        fit_line(x, y)
    assert isinstance(info.value, ValueError)
    assert isinstance(info.value, CraneStiffnessError)


def test_nonlinearity_zero_for_line_positive_for_softening() -> None:
    rng = np.random.default_rng(11)
    force = np.linspace(0.0, 10.0, 60)  # N, side force as in Fig. 9
    k0 = 600.0
    linear = fit_line(force / k0 + rng.normal(0.0, 2e-6, force.size), force)
    # Softening: displacement grows faster than the load once wires approach zero tension.
    displacement = force / k0 * (1.0 + (force / 8.0) ** 2)
    softening = fit_line(displacement + rng.normal(0.0, 2e-6, force.size), force)
    stiffening = fit_line(force / k0 * (1.0 - 0.04 * force), force)
    assert abs(linear.nonlinearity) < 0.03
    assert softening.nonlinearity > 0.4
    assert stiffening.nonlinearity < -0.2


def test_nonlinearity_unbiased_over_noise() -> None:
    rng = np.random.default_rng(12)
    x, y = _line_data(rng, (400,), n=30)
    fit = fit_line(x, y)
    assert abs(np.mean(fit.nonlinearity)) < 0.005


def test_windowed_equals_batch_on_same_window() -> None:
    rng = np.random.default_rng(7)
    n, window = 2000, 137
    x = 0.5 + np.cumsum(rng.normal(0.0, 1e-4, n))  # a wandering displacement with an offset
    y = 850.0 * x + 12.0 + rng.normal(0.0, 0.05, n)
    wls = WindowedLeastSquares(window)
    for i, (xi, yi) in enumerate(zip(x, y)):
        wls.add(xi, yi)
        if i in (2, 50, 136, 137, 999, n - 1):
            lo = max(0, i + 1 - window)
            got, ref = wls.result(), fit_line(x[lo:i + 1], y[lo:i + 1])
            assert got is not None
            assert got.n == ref.n == min(i + 1, window)
            for name in ('stiffness', 'intercept', 'stderr', 'ci95_low', 'ci95_high', 'r2', 'residual_rms',
                         'nonlinearity'):
                assert getattr(got, name) == pytest.approx(getattr(ref, name), rel=1e-7, abs=1e-10), name


def test_windowed_none_until_fit_possible() -> None:
    wls = WindowedLeastSquares(5)
    assert wls.result() is None
    for _ in range(4):
        wls.add(1e-3, 2.0)
    assert wls.result() is None  # four points but no spread in x
    wls.add(2e-3, 3.0)
    assert wls.result() is not None
    with pytest.raises(ParameterError, match='window'):
        WindowedLeastSquares(2)
    with pytest.raises(DataError):
        wls.add(math.nan, 1.0)


def test_rls_converges_and_tracks_a_change() -> None:
    rng = np.random.default_rng(8)
    rls = RecursiveLeastSquares(forgetting=0.995)
    for _ in range(3000):
        xi = rng.uniform(0.0, 0.012)
        rls.add(xi, K_TRUE * xi + C_TRUE + rng.normal(0.0, NOISE))
    result = rls.result()
    assert result is not None
    assert result.stiffness == pytest.approx(K_TRUE, abs=4.0 * result.stderr)
    assert result.intercept == pytest.approx(C_TRUE, abs=0.03)
    assert result.effective_n == pytest.approx(200.0, rel=0.01)
    for _ in range(3000):  # the wires stiffen (more payload): forgetting follows
        xi = rng.uniform(0.0, 0.012)
        rls.add(xi, 1100.0 * xi + C_TRUE + rng.normal(0.0, NOISE))
    assert rls.result().stiffness == pytest.approx(1100.0, abs=4.0 * rls.result().stderr)


def test_rls_stderr_is_calibrated() -> None:
    estimates, stderrs = [], []
    for seed in range(60):
        rng = np.random.default_rng(seed)
        rls = RecursiveLeastSquares(forgetting=0.99)
        x = rng.uniform(0.0, 0.012, 800)
        y = K_TRUE * x + C_TRUE + rng.normal(0.0, NOISE, x.size)
        for xi, yi in zip(x, y):
            rls.add(xi, yi)
        estimates.append(rls.result().stiffness)
        stderrs.append(rls.result().stderr)
    ratio = np.std(estimates, ddof=1) / np.mean(stderrs)
    assert 0.75 < ratio < 1.33


def test_rls_without_forgetting_equals_ols() -> None:
    rng = np.random.default_rng(9)
    x, y = _line_data(rng, ())
    rls = RecursiveLeastSquares(forgetting=1.0)
    for xi, yi in zip(x, y):
        rls.add(xi, yi)
    ref = fit_line(x, y)
    assert rls.result().stiffness == pytest.approx(ref.stiffness, rel=1e-6)
    assert rls.result().stderr == pytest.approx(ref.stderr, rel=1e-4)


def test_rls_no_windup_during_long_hold() -> None:
    rng = np.random.default_rng(10)
    rls = RecursiveLeastSquares(forgetting=0.999)
    for _ in range(1000):
        xi = rng.uniform(0.0, 0.012)
        rls.add(xi, K_TRUE * xi + rng.normal(0.0, NOISE))
    for _ in range(100_000):  # 20 s hold at 5 kHz: x constant
        rls.add(0.006, K_TRUE * 0.006 + rng.normal(0.0, NOISE))
    xi = 0.012
    rls.add(xi, K_TRUE * xi + rng.normal(0.0, NOISE))
    result = rls.result()
    assert np.isfinite(result.stiffness)
    assert result.stiffness == pytest.approx(K_TRUE, rel=0.05)


def _hysteretic_run(program: LoadProgram, k_load: float, k_unload: float, rate_hz: float,
                    rng: np.random.Generator) -> StiffnessEstimator:
    """Feed a load-unload cycle whose unloading branch is stiffer (friction/hysteresis in the rig)."""
    estimator = StiffnessEstimator(hysteresis=1e-6, window=4000, forgetting=0.9995)
    t, wrench = program.sample(rate_hz)
    force = wrench[:, 1]
    peak_x = peak_f = 0.0
    x = 0.0
    tracker = BranchTracker(1e-9)
    for ti, fi in zip(t, force):
        if tracker.update(fi) == 'loading':
            x = fi / k_load
            peak_x, peak_f = x, fi
        else:
            x = peak_x - (peak_f - fi) / k_unload
        estimator.add(ti, fi + rng.normal(0.0, 0.02), x + rng.normal(0.0, 1e-6), load=fi)
    return estimator


def test_estimator_recovers_branch_stiffness() -> None:
    segments = [Segment('ramp', 'fy', 10.0, 4.0), Segment('hold', 'fy', 10.0, 0.5),
                Segment('ramp', 'fy', 0.0, 4.0)]
    program = LoadProgram(segments, name='cycle')
    estimator = _hysteretic_run(program, k_load=800.0, k_unload=1200.0, rate_hz=500.0,
                                rng=np.random.default_rng(13))
    loading, unloading = estimator.estimate('loading'), estimator.estimate('unloading')
    assert loading.stiffness == pytest.approx(800.0, rel=0.01)
    assert unloading.stiffness == pytest.approx(1200.0, rel=0.01)
    assert loading.ci95_low < 800.0 < loading.ci95_high
    assert unloading.ci95_low < 1200.0 < unloading.ci95_high
    assert loading.rls_stiffness == pytest.approx(800.0, rel=0.01)
    assert unloading.rls_stiffness == pytest.approx(1200.0, rel=0.01)
    assert abs(loading.nonlinearity) < 0.05
    assert loading.n == 2251 and unloading.n == 2000
    assert unloading.stamp_s == pytest.approx(8.5)
    assert estimator.branch == 'unloading'
    # A single fit over both branches would blur the two slopes.
    assert estimator.estimates()['loading'] == loading


def test_estimator_skips_non_finite_and_from_params() -> None:
    estimator = StiffnessEstimator.from_params({'hysteresis': 0.1, 'window': 10, 'forgetting': 0.99})
    assert estimator.add(0.0, math.nan, 1e-3) is None
    assert estimator.rejected == 1
    assert estimator.estimate() is None
    for i in range(5):
        estimator.add(i * 0.01, 100.0 * i * 1e-3, i * 1e-3)
    assert estimator.estimate().stiffness == pytest.approx(100.0)
    with pytest.raises(ParameterError, match='windw'):
        StiffnessEstimator.from_params({'hysteresis': 0.1, 'windw': 10})
    with pytest.raises(ParameterError, match='forgetting'):
        StiffnessEstimator(0.1, forgetting=1.5)


def test_t_quantile_matches_scipy_beyond_the_exact_range() -> None:
    from scipy import stats

    from crane_stiffness.estimation.fit import t_quantile
    for dof in (1, 2, 30, 1000, 1001, 2500, 30_000, 10 ** 6):
        for conf in (0.9, 0.95, 0.99):
            assert t_quantile(dof, conf) == pytest.approx(stats.t.ppf(0.5 + conf / 2, dof), rel=1e-9, abs=0)
