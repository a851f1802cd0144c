"""Tests of crane_stiffness.estimation.inputs: the live estimator's input checks and command hold, one sample at a
time (LiveStiffness) and vectorized over recorded streams (the offline analysis), pinned to each other."""
from __future__ import annotations

import math

import numpy as np
import pytest

from crane_stiffness.estimation.inputs import (INPUT_CHECKS, CommandHold, CommandSeries, checked_samples,
                                               command_inputs, input_faults)
from crane_stiffness.estimation.settings import LiveSettings
from crane_stiffness.estimation.live import LiveStiffness


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
    # Arrival 2 ms after the stamp, but some stamps an hour (or 0.2 s) ahead of it: a skewed sensor clock.
    arrival_ns = (np.nan_to_num(100.0 + np.arange(n) * 1e-3 + 0.002) * 1e9).astype(np.int64)
    stamp[rng.random(n) < 0.02] += 3600.0
    stamp[rng.random(n) < 0.02] += 0.2
    finite = np.isfinite(stamp) & np.isfinite(value)
    skew = 0.1
    faults = input_faults(finite, stamp, value, limit, arrival_ns * 1e-9, skew)
    for i in range(n):
        one = input_faults(bool(finite[i]), float(stamp[i]), float(value[i]), limit, float(arrival_ns[i] * 1e-9),
                           skew)
        assert tuple(bool(f) for f in one) == tuple(bool(f[i]) for f in faults)
        assert sum(one) <= 1
    kept, counts = checked_samples(stamp, arrival_ns, value, finite, limit, skew)
    # The live estimator counts the same drops, stream by stream.
    settings = LiveSettings(max_abs_force=limit, max_abs_displacement=limit, max_clock_skew_s=skew)
    live = LiveStiffness(settings)
    for t, v, a in zip(stamp.tolist(), value.tolist(), (arrival_ns * 1e-9).tolist()):
        live.add_force(t, (0.0, v, 0.0, 0.0, 0.0, 0.0), a)
    assert {name: getattr(live.counters, name) for name in INPUT_CHECKS} == counts
    assert live.sync_counters.force.received == kept.stamp.size
    assert all(counts.values())
    live = LiveStiffness(settings)
    for t, v, a in zip(stamp.tolist(), value.tolist(), (arrival_ns * 1e-9).tolist()):
        live.add_displacement(t, v, a)
    assert {name: getattr(live.counters, name) for name in INPUT_CHECKS} == counts
    # Without an arrival time (NaN) the skew is not judged.
    assert not input_faults(True, 1e9, 0.0, limit, math.nan, skew)[2]


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


def test_rejected_commands_held_alike_live_and_vectorized() -> None:
    """Absurd commands (crane_stiffness.contract.command_limits) and the model's rejections are held as rejected until
    the next
    accepted command, one by one and in bulk; a rejection of equal stamp wins over its command."""
    from crane_stiffness.contract.command_limits import command_faults
    rng = np.random.default_rng(8)
    n = 400
    stamp = 10.0 + np.arange(n) * 0.01
    wrench = np.zeros((n, 6))
    wrench[:, 1] = np.round(rng.normal(0.0, 2.0, n), 1)
    absurd_at = rng.random(n) < 0.05
    wrench[absurd_at, 1] = 1e30
    model_at = np.flatnonzero(rng.random(n) < 0.05)  # the model rejects these (same stamp), 5 ms after
    arrival = stamp + 0.001
    live = LiveStiffness(LiveSettings())
    for i in range(n):
        live.add_command(float(stamp[i]), wrench[i].tolist(), float(arrival[i]))
    for i in model_at.tolist():
        live.add_rejected(float(stamp[i]), wrench[i].tolist(), float(arrival[i] + 0.005))
    assert live.counters.command_rejected == absurd_at.sum()
    assert live.counters.command_used == n - absurd_at.sum()
    series = CommandSeries.of(stamp, (arrival * 1e9).astype(np.int64), wrench[:, 1], command_faults(wrench),
                              stamp[model_at], ((arrival[model_at] + 0.005) * 1e9).astype(np.int64))
    reads = np.sort(rng.uniform(10.0, 10.0 + n * 0.01, 3000))
    read_arrival_ns = ((reads + 0.05) * 1e9).astype(np.int64)
    got = series.rejected_at(reads, read_arrival_ns)
    expected = [live._commands.entry(float(t))[1] is not None for t in reads]
    assert got.tolist() == expected
    assert 0 < got.sum() < got.size


def test_stream_health_live_equals_vectorized() -> None:
    """Received fraction: samples lost at random (4 %), a few out of order; the streaming and bulk forms agree."""
    from crane_stiffness.estimation.inputs import StreamHealth, stream_health_of
    rng = np.random.default_rng(3)
    stamp = 5.0 + np.arange(20000) * 1e-3
    stamp = stamp[rng.random(stamp.size) > 0.04]
    stamp[rng.integers(0, stamp.size, 30)] -= 0.05
    for period in (None, 1e-3):
        health = StreamHealth(period)
        for t in stamp.tolist():
            health.add(t)
        bulk = stream_health_of(stamp, period)
        assert (health.count, health.first, health.newest) == (bulk.count, bulk.first, bulk.newest)
        assert health.period() == pytest.approx(bulk.period, rel=1e-12)
        assert health.received_fraction() == bulk.received_fraction
        assert bulk.received_fraction == pytest.approx(0.96, abs=0.005)
