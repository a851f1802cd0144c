"""CounterClock: stamps from a device's sample counter, anchored to the host clock on the lower envelope of the
arrival times, tracking a counter that runs 100 ppm fast under network jitter."""
from __future__ import annotations

import numpy as np
import pytest

from crane_stiffness.drivers.clock import CounterClock
from crane_stiffness.drivers.errors import ParameterError

RATE = 7000.0
T0 = 1_700_000_000_000_000_000  # ns, a realistic epoch time
BASE_DELAY_NS = 150_000         # constant part of the transport delay (not observable, carried by the stamps)


def simulate(seconds: float, ppm: float, seed: int = 1, batch: int = 7, start_counter: int = 2**32 - 50_000,
             spikes: float = 0.01):
    """Samples of a counter running ``ppm`` fast, with exponential jitter (mean 300 µs) and 1 % of 5 ms spikes,
    received in batches; returns (true instants + base delay, stamps)."""
    rng = np.random.default_rng(seed)
    n = int(RATE * seconds)
    k = np.arange(n)
    true = T0 + k * (1e9 / RATE) / (1.0 + ppm * 1e-6)
    delay = BASE_DELAY_NS + rng.exponential(300e3, n) + (rng.random(n) < spikes) * 5e6
    arrival = (true + delay).astype(np.int64)
    counter = (k + start_counter) % 2**32  # wraps 7 s in
    clock = CounterClock(RATE)
    stamps = np.concatenate([clock.update(counter[i:i + batch], arrival[i:i + batch]) for i in range(0, n, batch)])
    return clock, k, true + BASE_DELAY_NS, stamps, arrival


def test_counter_100_ppm_fast_with_jitter_is_stamped_within_10_us():
    clock, k, reference, stamps, arrival = simulate(60.0, ppm=100.0)
    err = np.abs(stamps - reference)
    settled = k >= 5 * RATE
    print(f'stamp error after 5 s: max {err[settled].max() / 1e3:.2f} µs; first second max '
          f'{err[k < RATE].max() / 1e3:.1f} µs; arrival-time stamps mean {np.mean(arrival - reference) / 1e3:.0f} µs '
          f'late, max {np.max(arrival - reference) / 1e3:.0f} µs; skew {clock.skew_ppm:.2f} ppm')
    assert clock.fitted
    assert clock.skew_ppm == pytest.approx(-100.0, abs=1.0)       # a fast counter: samples closer in host time
    assert err[settled].max() < 10_000                           # 10 µs, while the jitter is ~300 µs mean
    assert err[k < RATE].max() < 100_000                          # 100 µs from the first second on
    assert np.mean(arrival[settled] - reference[settled]) > 250_000  # arrival stamps would be far worse
    assert np.all(np.diff(stamps[settled]) > 0)
    assert clock.resets == 0                                      # the 32-bit wrap is not a restart


def test_drift_of_the_other_sign_and_a_device_restart():
    clock, k, reference, stamps, _ = simulate(20.0, ppm=-80.0, seed=2, spikes=0.0)
    assert clock.skew_ppm == pytest.approx(80.0, abs=1.0)
    assert np.abs(stamps - reference)[k >= 5 * RATE].max() < 10_000
    # The device restarts: its counter starts again at 0, 1 s later. The clock starts over on the new origin.
    n = int(RATE * 3)
    true = T0 + 21e9 + np.arange(n) * 1e9 / RATE
    stamps2 = clock.update(np.arange(n), (true + BASE_DELAY_NS).astype(np.int64))
    assert clock.resets == 1
    assert np.abs(stamps2 - (true + BASE_DELAY_NS)).max() < 1_000


def test_out_of_order_records_get_their_own_instants():
    clock = CounterClock(1000.0)
    arrival = T0 + np.arange(10) * 1_000_000 + 100_000
    s1 = clock.update(np.arange(10), arrival)
    # Counters 12 then 11 arrive together, late: each gets its own instant on the counter's grid.
    s2 = clock.update([12, 11], [T0 + 12_500_000] * 2)
    assert s2[0] - s2[1] == 1_000_000 and s2[1] - s1[-1] == 2_000_000


@pytest.mark.parametrize('kwargs, field', [({'rate_hz': 0.0}, 'rate_hz'), ({'rate_hz': 1000.0, 'bin_s': -1.0},
                         'bin_s'), ({'rate_hz': 1000.0, 'window_s': 1.0}, 'window_s')])
def test_bad_settings(kwargs, field):
    with pytest.raises(ParameterError, match=field):
        CounterClock(**kwargs)
