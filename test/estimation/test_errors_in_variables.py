"""The line fit with errors in both variables (crane_stiffness.estimation.fit): unbiased where least squares alone is
attenuated, an interval that covers the truth 95 % of the time, the streaming and batch forms pinned together, the
live estimator and its settings counting the displacement noise. Pure numpy, no ROS."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from crane_stiffness.errors import ParameterError as CraneParameterError
from crane_stiffness.estimation.errors import DataError, ParameterError
from crane_stiffness.estimation.fit import LineFit, WindowedLeastSquares, fit_line
from crane_stiffness.estimation.quality import noise_std
from crane_stiffness.estimation.settings import LiveSettings

K = 53_800.0      # N/m, the lab model's side stiffness
C = 0.3           # N, a tare error
SIGMA_X = 1e-6    # m: a 1 µm-noise LVDT
SIGMA_F = 0.01    # N: the load cell's noise
FITS = 1000


def _staircase(sd_x: float = 10e-6, hold: int = 150, ramp: int = 40) -> np.ndarray:
    """True displacements of a load program sampled in order, m: 9 levels up and back down, each held ``hold``
    samples with ``ramp`` samples of ramp between; the levels spread so that the standard deviation is ``sd_x``."""
    levels = np.r_[np.arange(9), np.arange(7, -1, -1)].astype(float)
    path = [np.full(hold, levels[0])]
    for a, b in zip(levels[:-1], levels[1:]):
        path += [np.linspace(a, b, ramp + 2)[1:-1], np.full(hold, b)]
    x = np.concatenate(path)
    return (x - x.mean()) / x.std() * sd_x + 20e-6


@pytest.fixture(scope='module')
def simulated() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """1,000 noisy records of one program: true x (n,), observed x and force (FITS, n)."""
    rng = np.random.default_rng(20261126)
    x_true = _staircase()
    x = x_true + rng.normal(0.0, SIGMA_X, (FITS, x_true.size))
    f = K * x_true + C + rng.normal(0.0, SIGMA_F, (FITS, x_true.size))
    return x_true, x, f


def _coverage(fit: LineFit) -> float:
    return float(np.mean((np.asarray(fit.ci95_low) <= K) & (K <= np.asarray(fit.ci95_high))))


def test_least_squares_alone_is_one_percent_low(simulated) -> None:
    x_true, x, f = simulated
    ols = fit_line(x, f)
    attenuation = SIGMA_X ** 2 / x_true.var()  # (σx / sd x)²: 1 %
    assert attenuation == pytest.approx(0.01, rel=0.01)
    bias = float(np.mean(ols.stiffness)) / K - 1.0
    assert bias == pytest.approx(-attenuation, abs=0.001)
    assert _coverage(ols) < 0.2  # its interval, blind to the displacement noise, rarely holds the truth


def test_known_noise_bias_within_a_tenth_of_a_percent_and_coverage_95(simulated) -> None:
    x_true, x, f = simulated
    eiv = fit_line(x, f, x_noise=SIGMA_X)
    bias = float(np.mean(eiv.stiffness)) / K - 1.0
    assert abs(bias) <= 0.001, f'bias {bias:.2e}'
    assert 0.93 <= _coverage(eiv) <= 0.97
    # the interval counts both noises: its standard error agrees with the fits' own spread
    assert float(np.median(eiv.stderr)) == pytest.approx(float(np.std(eiv.stiffness, ddof=1)), rel=0.1)
    assert np.all(np.asarray(eiv.x_noise) == SIGMA_X)


def test_noise_estimated_from_the_data_bias_and_coverage(simulated) -> None:
    """The live estimator's default (displacement_noise -1): σx from each record's own second differences."""
    x_true, x, f = simulated
    sigma = np.array([noise_std(row) for row in x])
    assert float(np.mean(sigma)) == pytest.approx(SIGMA_X, rel=0.02)  # the ramps do not count as noise
    eiv = fit_line(x, f, x_noise=sigma)
    bias = float(np.mean(eiv.stiffness)) / K - 1.0
    assert abs(bias) <= 0.001, f'bias {bias:.2e}'
    assert 0.93 <= _coverage(eiv) <= 0.97


def test_no_noise_is_ordinary_least_squares() -> None:
    rng = np.random.default_rng(3)
    x = rng.uniform(0.0, 1e-4, 50)
    y = K * x + rng.normal(0.0, 0.05, 50)
    ref = stats.linregress(x, y)
    fit = fit_line(x, y)
    assert fit.stiffness == pytest.approx(ref.slope, rel=1e-12)
    assert fit.stderr == pytest.approx(ref.stderr, rel=1e-9)
    assert fit.intercept_stderr == pytest.approx(ref.intercept_stderr, rel=1e-9)
    assert fit.x_noise == 0.0


@pytest.mark.parametrize('x_noise', [0.0, 2e-7, 1e-6])
def test_window_equals_the_batch_fit(x_noise: float) -> None:
    """The streaming form (the live estimator's window) and the batch form (analyze) give the same fit."""
    rng = np.random.default_rng(11)
    x_true = _staircase()
    x = x_true + rng.normal(0.0, 1e-6, x_true.size)
    f = K * x_true + C + rng.normal(0.0, SIGMA_F, x_true.size)
    window = WindowedLeastSquares(1000)
    for xi, fi in zip(x, f):
        window.add(xi, fi)
    live = window.result(nonlinearity=True, x_noise=x_noise)
    batch = fit_line(x[-1000:], f[-1000:], x_noise=x_noise)
    assert live is not None
    for name in ('stiffness', 'intercept', 'stderr', 'intercept_stderr', 'ci95_low', 'ci95_high', 'r2',
                 'residual_rms', 'nonlinearity', 'x_noise'):
        assert float(getattr(live, name)) == pytest.approx(float(getattr(batch, name)), rel=1e-8, abs=1e-12), name


def test_no_spread_beyond_the_noise() -> None:
    rng = np.random.default_rng(2)
    x = rng.normal(0.0, 1e-6, 200)  # nothing but noise
    y = rng.normal(0.0, 0.01, 200)
    with pytest.raises(DataError, match='no spread beyond its noise'):
        fit_line(x, y, x_noise=2e-6)
    window = WindowedLeastSquares(200)
    for xi, yi in zip(x, y):
        window.add(xi, yi)
    assert window.result(x_noise=2e-6) is None
    with pytest.raises(ParameterError, match='x_noise'):
        fit_line(x, y, x_noise=-1e-6)
    with pytest.raises(ParameterError, match='x_noise'):
        window.result(x_noise=math.nan)


def test_the_setting_names_the_bad_value_and_counts_a_fixed_noise_from_the_first_pair() -> None:
    with pytest.raises(CraneParameterError, match='displacement_noise'):
        LiveSettings.from_params({'displacement_noise': -0.5})
    assert LiveSettings.from_params({'displacement_noise': 0.0}).noise_text().startswith('ordinary least squares')
    fixed = LiveSettings.from_params({'displacement_noise': 1e-6, 'window': 5000})
    assert fixed.displacement_noise_of(np.zeros(10)) == 1e-6
    assert 'estimated' in LiveSettings().noise_text()
    estimator = fixed.make_estimator()
    rng = np.random.default_rng(4)
    x_true = _staircase()
    x = x_true + rng.normal(0.0, SIGMA_X, x_true.size)
    f = K * x_true + rng.normal(0.0, SIGMA_F, x_true.size)
    for i, (xi, fi) in enumerate(zip(x, f)):
        estimator.add(i * 1e-3, fi, xi, load=1.0)  # one branch: loading
    est = estimator.estimate('loading')
    assert est is not None and est.x_noise == 1e-6
    assert float(est.stiffness) == pytest.approx(float(fit_line(x, f, x_noise=1e-6).stiffness), rel=1e-9)


def test_no_nonlinearity_from_a_half_that_is_one_hold_split_by_its_noise():
    """The rig at rest before a program fills the window's start with one hold. Split at the median load, a half is
    then that hold divided by its displacement noise: no spread beyond the noise, so its corrected slope was anything
    (the live status once said 'nonlinear (slack wire?)', 0.80, at rest; here the old halves gave -295 .. +58). The
    half needs the full fit's own rule (SXX >= Sxx / 2), else there is no indicator; a straight window keeps it."""
    k, sx = 53_793.0, 1.8e-7
    for seed in range(10):
        rng = np.random.default_rng(seed)
        load = np.r_[np.zeros(2000), np.linspace(0.0, 0.3, 384)]
        x = load / k + rng.normal(0.0, sx, load.size)
        y = load + rng.normal(0.0, 0.01, load.size)
        assert np.isnan(fit_line(x, y, x_noise=sx).nonlinearity)
        ramp = np.linspace(0.0, 4.0, 2384)  # the same noise over a whole ramp: an indicator, near 0
        fit = fit_line(ramp / k + rng.normal(0.0, sx, ramp.size), ramp + rng.normal(0.0, 0.01, ramp.size),
                       x_noise=sx)
        assert abs(fit.nonlinearity) < 0.02
