"""Log times on simulated time (crane_stiffness.sim.log_times): each counted stream logged at its stamps, the rest at
the next watermark released, written in log-time order, the same whatever order the middleware delivered the topics
in and wherever the recorder's clock was when they arrived."""
from __future__ import annotations

import random

from crane_stiffness.sim.log_times import SimLogTimes

MS = 1_000_000
STEP = 50 * MS
T0 = 1000 * 1000 * MS
WRENCH, DISP, CLOCK, ESTIMATE = '/load_cell/wrench', '/lvdt/displacement', '/clock', '/stiffness/estimate'


def _step_messages(k: int) -> list[tuple[str, int | None]]:
    """What the recorder receives in step k: 50 wrenches and 50 displacements (1 kHz, stamped), the clock, one
    estimate stamped with an old sample."""
    start = T0 + k * STEP
    out: list[tuple[str, int | None]] = [(CLOCK, None), (ESTIMATE, start - 10 * MS)]
    for i in range(1, 51):
        out += [(WRENCH, start + i * MS), (DISP, start + i * MS)]
    return out


def _record(seed: int, steps: int = 20) -> list[tuple[int, str, object]]:
    """The written (log time, topic, item) of ``steps`` steps, each step's topics delivered interleaved at random
    (each topic in its own order)."""
    rng = random.Random(seed)
    times: SimLogTimes[tuple[str, int | None]] = SimLogTimes([WRENCH, DISP])
    written: list[tuple[int, str, object]] = []
    for k in range(steps):
        per_topic: dict[str, list[tuple[str, int | None]]] = {}
        for m in _step_messages(k):
            per_topic.setdefault(m[0], []).append(m)
        queues = list(per_topic.values())
        while any(queues):  # the topics interleaved at random, each in order
            q = rng.choice([q for q in queues if q])
            topic, stamp = q.pop(0)
            times.hold(topic, stamp, (topic, stamp))
        written += [(t, item[0], item) for t, item in times.release(T0 + (k + 1) * STEP)]
    written += [(t, item[0], item) for t, item in times.release_all()]
    return written


def test_counted_streams_keep_their_stamps_and_the_file_its_order():
    written = _record(seed=1)
    assert len(written) == 20 * 102
    logs = [t for t, _, _ in written]
    assert logs == sorted(logs)  # log times never go back in the file
    for topic in (WRENCH, DISP):
        mine = [(t, item) for t, name, item in written if name == topic]
        assert [t for t, _ in mine] == [stamp for _, (_, stamp) in mine]   # logged at their stamps
        assert [stamp for _, (_, stamp) in mine] == [T0 + i * MS for i in range(1, 20 * 50 + 1)]  # in order
        diffs = {b - a for (a, _), (b, _) in zip(mine, mine[1:])}
        assert diffs == {MS}  # the 1 kHz pacing: distinct log times 1 ms apart
    for topic in (CLOCK, ESTIMATE):  # not counted: at the watermark released after they came, their step's
        assert [t for t, name, _ in written if name == topic] == [T0 + (k + 1) * STEP for k in range(20)]


def test_the_same_log_times_and_order_whatever_the_delivery():
    assert _record(seed=1) == _record(seed=2)


def test_a_stamp_going_back_or_too_old_keeps_the_topic_in_order():
    times: SimLogTimes[int] = SimLogTimes([WRENCH])
    assert times.hold(WRENCH, T0 + 5 * MS, 1) == T0 + 5 * MS
    assert times.hold(WRENCH, T0 + 3 * MS, 2) == T0 + 5 * MS   # back in time: at the topic's last log time
    assert times.release(T0 + 50 * MS) == [(T0 + 5 * MS, 1), (T0 + 5 * MS, 2)]
    assert times.hold(WRENCH, T0 + 40 * MS, 3) is None  # at or before the released watermark: at the next one
    assert times.hold(WRENCH, None, 4) is None          # no stamp: the next watermark
    assert times.hold(CLOCK, T0 + 80 * MS, 5) is None   # not counted: the next watermark, whatever it says
    assert times.held == 3
    assert times.release(T0 + 100 * MS) == [(T0 + 100 * MS, 5), (T0 + 100 * MS, 3), (T0 + 100 * MS, 4)]
    assert times.hold(ESTIMATE, None, 6) is None
    assert times.release_all() == [(T0 + 100 * MS, 6)]  # the recording stops: at the last watermark released
    assert times.held == 0


def test_a_distinct_topic_is_logged_once_per_time_at_the_time_it_says():
    times: SimLogTimes[int] = SimLogTimes([WRENCH], distinct=[CLOCK])
    assert not times.repeat(CLOCK, T0) and times.repeat(CLOCK, T0)  # the clock saying its time again: left out
    assert times.hold(CLOCK, T0, 1) == T0                            # logged at the time it says
    assert not times.repeat(CLOCK, T0 + STEP) and times.repeat(CLOCK, T0)  # a later time; an earlier one again
    assert not times.repeat(WRENCH, T0) and not times.repeat(WRENCH, T0)   # other topics: never repeats


def test_nothing_is_logged_before_time_started():
    """The lock-step's joining reports carry a negative watermark: a latched message that arrives then (the load
    cell's tare) waits for the first real watermark; stopped before it, it is logged at 0, never at a negative
    time (which a bag refuses)."""
    log = SimLogTimes(paced=['/load_cell/wrench'])
    assert log.hold('/load_cell/tare', None, 'tare') is None
    assert log.release(-1) == [] and log.held == 1
    assert log.release(1_000_000) == [(1_000_000, 'tare')]
    early = SimLogTimes(paced=['/load_cell/wrench'])
    early.hold('/load_cell/tare', None, 'tare')
    assert early.release(-1) == [] and early.release_all() == [(0, 'tare')]
