"""The player's read-ahead (crane_stiffness.rosnode.replay_timing): every item in order, an error of the source where
it happened, stopping early; the interpreter settings restored after a
playback."""
from __future__ import annotations

import gc
import sys
import threading
import time

import pytest

from helpers import PATIENCE_S
from crane_stiffness.rosnode.replay_timing import ReadAhead, fine_timer_slack, quiet_interpreter


def _slow_source(n: int, fail_at: int | None = None):
    """0 .. n-1, a pause now and then (a chunk read), optionally raising at ``fail_at``."""
    for i in range(n):
        if i % 97 == 0:
            time.sleep(0.001)
        if i == fail_at:
            raise OSError(f'unreadable at {i}')
        yield i


def _take_all(ahead: ReadAhead) -> list:
    out = []
    while True:
        try:
            got, item = ahead.take(PATIENCE_S)
        except StopIteration:
            return out
        if got:
            out.append(item)


@pytest.mark.parametrize('high, low', [(10, 5), (1, 0), (1000, 999)])
def test_every_item_in_order_through_a_small_buffer(high, low):
    ahead = ReadAhead(_slow_source(2500), high=high, low=low)
    assert ahead.wait_filled(PATIENCE_S)
    assert _take_all(ahead) == list(range(2500))
    ahead.close()


def test_an_error_of_the_source_comes_where_it_happened():
    ahead = ReadAhead(_slow_source(300, fail_at=200), high=50, low=10)
    got = []
    with pytest.raises(OSError, match='unreadable at 200'):
        while True:
            ok, item = ahead.take(PATIENCE_S)
            if ok:
                got.append(item)
    assert got == list(range(200))
    ahead.close()


def test_close_stops_the_reader_early():
    produced = []

    def endless():
        i = 0
        while True:
            produced.append(i)
            yield i
            i += 1
    ahead = ReadAhead(endless(), high=100, low=50)
    assert ahead.wait_filled(PATIENCE_S)
    assert [ahead.take(PATIENCE_S)[1] for _ in range(10)] == list(range(10))
    ahead.close()
    assert not any(t.name == 'read_ahead' for t in threading.enumerate())
    assert len(produced) <= 101 + 1  # full buffer, then waiting; nothing read after close


def test_bad_levels_are_refused():
    with pytest.raises(ValueError, match='low = 5, high = 5'):
        ReadAhead([], high=5, low=5)


def test_the_interpreter_settings_come_back_after_a_playback():
    before = sys.getswitchinterval()
    with quiet_interpreter(0.0003):
        assert sys.getswitchinterval() == pytest.approx(0.0003)
        assert gc.get_freeze_count() > 0
    assert sys.getswitchinterval() == before and gc.get_freeze_count() == 0
    assert fine_timer_slack() in (True, False)  # available or not: never an error


