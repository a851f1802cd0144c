"""Tests of crane_stiffness.sim.sampling: the burst sample clock and the stamped zero-order hold (no ROS)."""
from __future__ import annotations

import numpy as np
import pytest

from crane_stiffness.sim.errors import ParameterError
from crane_stiffness.sim.sampling import NS_PER_S, SampleClock, StampedHold

MS = 1_000_000


def test_clock_delivers_grid_instants_in_bursts_without_gaps_or_repeats() -> None:
    clock = SampleClock(1000.0)
    start = 1_700_000_000 * NS_PER_S + 123_456_789
    assert clock.due(start).size == 0  # the first call starts the clock
    got = []
    now = start
    for step in (10_300_000, 9_700_000, 10_000_000, 0, 25_000_001):
        now += step
        got.append(clock.due(now))
    stamps = np.concatenate(got)
    assert np.all(stamps % MS == 0)  # on the grid k·1 ms: two sensors at the same rate have equal stamps
    assert np.all(np.diff(stamps) == MS)
    assert stamps[0] == (start // MS + 1) * MS
    assert stamps[-1] == now // MS * MS
    assert got[3].size == 0
    assert clock.skipped == 0


def test_clock_skips_a_stall_and_counts_it() -> None:
    clock = SampleClock(1000.0, max_backlog_s=0.05)
    clock.due(0)
    stamps = clock.due(2 * NS_PER_S)  # a 2 s stall: only the newest 50 ms are delivered
    assert stamps.size == 50 and stamps[-1] == 2 * NS_PER_S
    assert clock.skipped == 2000 - 50


def test_clock_continues_after_a_replacement_and_restarts_when_time_goes_back() -> None:
    old = SampleClock(1000.0)
    old.due(0)
    old.due(7 * MS)
    new = SampleClock(500.0, start_after_ns=old.last_ns)
    assert new.due(12 * MS).tolist() == [8 * MS, 10 * MS, 12 * MS]
    assert new.due(1 * MS).size == 0  # simulated time restarted
    assert new.due(5 * MS).tolist() == [2 * MS, 4 * MS]
    assert SampleClock(3.0).period_ns == 333_333_333


@pytest.mark.parametrize('rate', [0.0, -5.0, float('nan'), float('inf'), True])
def test_clock_rejects_bad_rates(rate) -> None:
    with pytest.raises(ParameterError, match='rate_hz'):
        SampleClock(rate)


def test_hold_applies_updates_at_their_stamps() -> None:
    hold = StampedHold(2, initial=[0.0, 0.0])
    hold.update([1.0, 10.0], stamp_ns=5 * MS, now_ns=6 * MS)
    hold.update([2.0, 20.0], stamp_ns=8 * MS, now_ns=9 * MS)
    values, valid = hold.read(np.arange(1, 11) * MS)
    assert valid.all()
    assert values[:, 0].tolist() == [0, 0, 0, 0, 1, 1, 1, 2, 2, 2]
    assert values[:, 1].tolist() == [0, 0, 0, 0, 10, 10, 10, 20, 20, 20]


def test_hold_never_rewrites_published_history_and_clamps_future_or_zero_stamps() -> None:
    hold = StampedHold(1)
    assert not hold.has_value and hold.latest is None
    values, valid = hold.read([1 * MS, 2 * MS])
    assert not valid.any() and np.isnan(values).all()
    # Stamped in the past of what was already read: takes effect just after it.
    assert hold.update([1.0], stamp_ns=1 * MS, now_ns=3 * MS) == 2 * MS + 1
    # A zero stamp, or one in the future of the node clock, takes effect on arrival.
    assert hold.update([2.0], stamp_ns=0, now_ns=5 * MS) == 5 * MS
    assert hold.update([3.0], stamp_ns=99 * NS_PER_S, now_ns=7 * MS) == 7 * MS
    values, valid = hold.read(np.arange(3, 9) * MS)
    assert valid.all()
    assert values[:, 0].tolist() == [1, 1, 2, 2, 3, 3]
    assert hold.latest.tolist() == [3.0]


def test_hold_out_of_order_stamps_take_their_place() -> None:
    hold = StampedHold(1)
    hold.update([2.0], stamp_ns=4 * MS, now_ns=5 * MS)
    hold.update([1.0], stamp_ns=2 * MS, now_ns=5 * MS)  # older stamp, arrived later
    values, _ = hold.read(np.arange(1, 6) * MS)
    assert np.isnan(values[0, 0]) and values[1:, 0].tolist() == [1, 1, 2, 2]


def test_hold_checks_sizes() -> None:
    with pytest.raises(ParameterError, match='size'):
        StampedHold(0)
    hold = StampedHold(3)
    with pytest.raises(ParameterError, match='value'):
        hold.update([1.0, 2.0], 1, 1)
