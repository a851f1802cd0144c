"""Tests of crane_stiffness.estimation.inputs: the live estimator's input checks and command hold, one sample at a
time (LiveStiffness) and vectorized over recorded streams (the offline analysis), pinned to each other."""
from __future__ import annotations

import math

import numpy as np

from crane_stiffness.estimation.inputs import (INPUT_CHECKS, CommandHold, CommandSeries, checked_samples,
                                               command_inputs, input_faults)
from crane_stiffness.estimation.live import LiveSettings, LiveStiffness


def _samples(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Stamps and values with NaN/Inf, zero and negative stamps and absurd values sprinkled in."""
    stamp = 100.0 + np.arange(n) * 1e-3
    value = rng.normal(0.0, 1.0, n)
    for where, what in ((rng.random(n) < 0.05, math.nan), (rng.random(n) < 0.02, math.inf)):
        value[where] = what
    stamp[rng.random(n) < 0.03] = 0.0
    stamp[rng.random(n) < 0.02] = -1.0
    stamp[rng.random(n) < 0.02] = math.nan
    value[rng.random(n) < 0.05] *= 1e3
    return stamp, value


def test_vectorized_input_checks_equal_the_live_ones() -> None:
    rng = np.random.default_rng(11)
    n, limit = 5000, 50.0
    stamp, value = _samples(rng, n)
    finite = np.isfinite(stamp) & np.isfinite(value)
    faults = input_faults(finite, stamp, value, limit)
    for i in range(n):
        one = input_faults(bool(finite[i]), float(stamp[i]), float(value[i]), limit)
        assert tuple(bool(f) for f in one) == tuple(bool(f[i]) for f in faults)
        assert sum(one) <= 1
    kept, counts = checked_samples(stamp, np.arange(n) * 1000, value, finite, limit)
    # The live estimator counts the same drops, stream by stream.
    live = LiveStiffness(LiveSettings(max_abs_force=limit, max_abs_displacement=limit))
    for t, v in zip(stamp.tolist(), value.tolist()):
        live.add_force(t, (0.0, v, 0.0, 0.0, 0.0, 0.0))
    assert {name: getattr(live.counters, name) for name in INPUT_CHECKS} == counts
    assert live.sync_counters.force.received == kept.stamp.size
    assert all(counts.values())
    live = LiveStiffness(LiveSettings(max_abs_force=limit, max_abs_displacement=limit))
    for t, v in zip(stamp.tolist(), value.tolist()):
        live.add_displacement(t, v)
    assert {name: getattr(live.counters, name) for name in INPUT_CHECKS} == counts


def test_vectorized_command_hold_equals_the_live_one() -> None:
    rng = np.random.default_rng(4)
    n = 3000
    # Commands at 100 Hz, stamps a little out of order, some unstamped (zero), some NaN; each arrives 1 ms late.
    stamp = 50.0 + np.arange(n) * 0.01 + rng.normal(0.0, 0.004, n)
    arrival = 50.0 + np.arange(n) * 0.01 + 0.015
    stamp[rng.random(n) < 0.05] = 0.0
    load = np.round(rng.normal(0.0, 2.0, n), 1)
    load[rng.random(n) < 0.03] = math.nan
    # Reads (pairs to label) at increasing stamps, fitted 50 ms after their stamp: every command stamped before a
    # read has arrived by then.
    reads = np.sort(rng.uniform(49.9, 50.0 + n * 0.01, 4000))
    read_arrival = reads + 0.05

    hold = CommandHold()
    expected = []
    events = sorted([(a, 0, i) for i, a in enumerate(arrival)] + [(a, 1, i) for i, a in enumerate(read_arrival)])
    for _, kind, i in events:
        if kind == 0:
            usable, effective = command_inputs(float(stamp[i]), float(arrival[i]), float(load[i]))
            if usable:
                hold.add(float(effective), float(load[i]))
        else:
            expected.append(hold.at(float(reads[i])) if hold else None)

    series = CommandSeries.of(stamp, (arrival * 1e9).astype(np.int64), load)
    got, held = series.at(reads, (read_arrival * 1e9).astype(np.int64))
    assert [float(v) if h else None for v, h in zip(got, held)] == expected
    assert 0 < held.sum() < held.size


def test_volts_convert_alike_one_by_one_and_in_bulk() -> None:
    s = LiveSettings(displacement_gain=2e-3, displacement_offset=-1e-4)
    volts = np.array([-3.0, 0.0, 0.25, 4.5])
    assert s.volts_to_displacement(volts).tolist() == [s.volts_to_displacement(float(v)) for v in volts]
