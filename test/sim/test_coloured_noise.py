"""Coloured noise and zero drift (crane_stiffness.sim.noise): the AR(1) autocorrelation, the mains line by FFT, the 1/f
slope, the random walk's growth, seeds, batching, and bad parameters named."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.signal import welch

from crane_stiffness.errors import ParameterError
from crane_stiffness.sim.noise import ColouredNoise, ar1_filter, noise_params

RATE_HZ = 1000.0


def times(n: int) -> np.ndarray:
    return np.arange(n) / RATE_HZ


def test_ar1_autocorrelation_at_lag_one_and_std_as_set():
    tau = 0.01
    phi = math.exp(-1.0 / (RATE_HZ * tau))  # 0.9048 at 1 kHz
    n = 400_000
    x = ColouredNoise(1, ar1_std=0.2, ar1_tau_s=tau, rng=7).sample(times(n))[:, 0]
    centred = x - x.mean()
    r1 = float(centred[1:] @ centred[:-1] / (centred @ centred))
    # Bartlett: the sample lag-1 autocorrelation of an AR(1) has variance (1 - phi²)/n.
    bound = 4.0 * math.sqrt((1.0 - phi ** 2) / n)
    print(f'lag-1 autocorrelation {r1:.5f}, set {phi:.5f}, 4 sigma {bound:.5f}')
    assert abs(r1 - phi) < bound
    # The std: the variance of an AR(1) sample variance is about 2 sigma^4 (1 + phi²)/(1 - phi²) / n.
    rel = 4.0 * math.sqrt((1.0 + phi ** 2) / (1.0 - phi ** 2) / (2.0 * n))
    assert abs(x.std() / 0.2 - 1.0) < rel
    # Lag 10: phi^10, within a looser bound of the same order.
    r10 = float(centred[10:] @ centred[:-10] / (centred @ centred))
    assert abs(r10 - phi ** 10) < 10 * bound


@pytest.mark.parametrize('hz', [50.0, 60.0])
def test_mains_line_amplitude_and_frequency_by_fft(hz):
    n = 20_000  # 20 s at 1 kHz: a whole number of cycles, the line falls on one bin
    e = ColouredNoise(2, mains_amplitude=[0.3, 0.05], mains_hz=hz, ar1_std=[0.01, 0.0], ar1_tau_s=0.002,
                      rng=3).sample(times(n))
    spectrum = np.abs(np.fft.rfft(e, axis=0)) * 2.0 / n
    freqs = np.fft.rfftfreq(n, 1.0 / RATE_HZ)
    peak = np.argmax(spectrum, axis=0)
    assert freqs[peak].tolist() == [hz, hz]
    # Channel 1 carries the line alone: its amplitude exactly; channel 0 also an AR(1) part whose share of one
    # bin is ~0.01 * sqrt(2 / n) * (its spectral shape): well below 1e-3.
    assert spectrum[peak[1], 1] == pytest.approx(0.05, rel=1e-9)
    assert spectrum[peak[0], 0] == pytest.approx(0.3, abs=1e-3)


def test_flicker_noise_falls_as_one_over_f():
    n = 400_000  # 400 s at 1 kHz
    x = ColouredNoise(1, flicker_std=1.0, rng=11).sample(times(n))[:, 0]
    f, p = welch(x, fs=RATE_HZ, nperseg=2 ** 16)
    band = (f >= 0.1) & (f <= 20.0)
    slope = np.polyfit(np.log10(f[band]), np.log10(p[band]), 1)[0]
    print(f'1/f noise: spectral slope {slope:.3f} between 0.1 and 20 Hz')
    assert -1.25 < slope < -0.75
    assert x.std() == pytest.approx(1.0, rel=0.3)  # the slow poles (10 s, 100 s) make the sample std scatter


def test_random_walk_variance_grows_linearly():
    channels = 4000
    walk = ColouredNoise(channels, random_walk=0.5, rng=5).sample(times(201))
    # After t = 0.2 s the walk's variance is 0.5² · 0.2 = 0.05: the sample variance over 4000 channels within its
    # chi-square 99.9 % interval.
    from scipy.stats import chi2
    var = walk[-1].var(ddof=1)
    low, high = chi2.ppf([0.0005, 0.9995], channels - 1) / (channels - 1) * 0.05
    assert low < var < high, (low, var, high)
    assert (walk[0] == 0.0).all()  # it starts from zero


def test_same_seed_same_series_however_batched_and_off_draws_nothing():
    def noise(seed):
        return ColouredNoise(6, ar1_std=0.1, ar1_tau_s=0.05, flicker_std=0.02, mains_amplitude=0.01,
                             random_walk=0.001, rng=seed)
    t = np.delete(times(5000), [100, 101, 2000])  # gaps: a batch not evenly spaced takes the loop
    whole = noise(1).sample(t)
    streamed = noise(1)
    cuts = [0, 1, 7, 100, 101, 2500, len(t)]
    parts = np.concatenate([streamed.sample(t[a:b]) for a, b in zip(cuts, cuts[1:])])
    assert np.array_equal(whole, parts)  # bit for bit: the live sensor's batches do not change the series
    assert not np.array_equal(whole, noise(2).sample(t))
    off = ColouredNoise(6, rng=1)
    assert not off.enabled and np.array_equal(off.sample(t), np.zeros((len(t), 6)))


def test_vectorised_and_loop_forms_of_the_recursion_agree_bit_for_bit():
    rng = np.random.default_rng(0)
    innovations = rng.standard_normal((500, 3))
    x0 = rng.standard_normal(3)
    phi = np.array([0.9, 0.5, 0.99])
    phis = np.tile(phi, (500, 1))
    phis[0] = 1.0  # a first sample at the instant of the state, and a gap: three runs of one spacing
    phis[300:] = phi ** 2
    vectorised = ar1_filter(phis, innovations, x0)  # lfilter over each run
    x, looped = x0.copy(), np.empty((500, 3))
    for i in range(500):
        x = phis[i] * x + innovations[i]
        looped[i] = x
    assert np.array_equal(vectorised, looped)


@pytest.mark.parametrize('kwargs, field, rule', [
    ({'ar1_std': -0.1}, 'ar1_std', '>= 0'),
    ({'ar1_tau_s': 0.0}, 'ar1_tau_s', '> 0'),
    ({'flicker_std': math.nan}, 'flicker_std', 'finite'),
    ({'mains_amplitude': [0.1, 0.2]}, 'mains_amplitude', '1 or 6 numbers'),
    ({'mains_hz': 0.0}, 'mains_hz', '> 0'),
    ({'random_walk': math.inf}, 'random_walk', 'finite'),
])
def test_bad_parameters_are_refused_naming_the_field(kwargs, field, rule):
    with pytest.raises(ParameterError) as err:
        ColouredNoise(6, **kwargs)
    assert err.value.field == field and rule in str(err.value)
    values = {s.name: s.default for s in noise_params('N', 6)}
    values['noise.' + field] = kwargs[field]
    with pytest.raises(ParameterError) as err:
        ColouredNoise.from_params(6, values)
    assert str(err.value).startswith(f'noise.{field} = ')
