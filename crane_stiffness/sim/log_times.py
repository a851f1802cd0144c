"""Log times of a recording on simulated time that keep each stream's pacing, the same in every run (pure, no ROS).

On simulated time the clock moves in steps (``step_s``, 50 ms): a recorder that logged each message at the clock time
it received it at would give a 1 kHz stream 20 distinct log times a second, and every player (``session_player``,
``ros2 bag play``, Foxglove) would play it as bursts of 50. Instead the recorder gives each message a log time here:

- A message of a *paced* topic (one the lock-step counts: the load program's commands, the model's outputs, the
  sensor streams; ``SIM_INPUTS`` of the recorder; and /clock, at the time it says) with a header stamp not before
  the last released watermark is logged at its header stamp (at the watermark itself it still follows everything
  written, whose log times are at most that). The lock-step guarantees that every such message stamped up to a
  watermark is in before the recorder acts on that watermark, so its stamp lies in the step being recorded, and the
  log time is the same in every run at any speed and load.
- Any other message (the estimators' outputs, the program's state, a message without a stamp, one stamped before
  the last released watermark) is logged at the next watermark the recorder releases after it arrived. The recorder
  is the last stage and counts these too (``SIM_OUTPUTS``); with ``max_lead_s`` = ``step_s`` nothing of a later step
  is published before it has released this one, so that is the step the message was published in, in every run
  (the recorder's own clock reading would be wherever /clock happened to be when it arrived).
- Within a topic a log time never goes back (a stamp earlier than the topic's last log time is logged at that
  time): the messages of a topic keep the order they were received in.

Messages are held until a watermark at or past their log time is released (:meth:`SimLogTimes.release`): then they go
to the file sorted by (log time, topic, order received), so the log times in a file never decrease (its chunks'
start and end times and message indexes in order, as readers expect), whatever order the middleware delivered the
topics in. A message logged at or before a released watermark can no longer arrive on a paced topic (the lock-step's
rule), and any other is logged at the watermark or later, so nothing released is ever followed by an earlier log
time. :meth:`release_all` hands over what is held when the recording stops.

Times are integer nanoseconds of simulated time.
"""
from __future__ import annotations

import itertools
from collections.abc import Collection
from typing import Generic, TypeVar

Item = TypeVar('Item')


class SimLogTimes(Generic[Item]):
    """Log times for messages recorded on simulated time, and the order they are written in (module docstring).

    Args:
        paced: Topics logged at their header stamp (resolved names): those whose messages the lock-step counts.
        distinct: Of those, topics whose repeats of a time already logged are left out (:meth:`repeat`: /clock).
    """

    def __init__(self, paced: Collection[str], distinct: Collection[str] = ()) -> None:
        self.paced = frozenset(paced) | frozenset(distinct)
        self._distinct = {topic: -1 for topic in distinct}  # the last time logged of each
        self.released_ns = -1                 #: the last watermark released: nothing is logged before it any more
        self._last: dict[str, int] = {}       # the last log time per topic
        self._held: list[tuple[int, str, int, Item]] = []
        self._next: list[tuple[str, int, Item]] = []  # logged at the next watermark released
        self._order = itertools.count()

    def _at(self, topic: str, t: int) -> int:
        """``t``, or the topic's last log time if later (a topic's log times never go back); noted as its last."""
        t = max(t, self._last.get(topic, t))
        self._last[topic] = t
        return t

    def repeat(self, topic: str, stamp_ns: int | None) -> bool:
        """Whether a message of a *distinct* topic says no later time than the last one taken (the clock repeats its
        time for nodes that join late, as often as the wall clock lets it): left out, the bag is the same at any load.
        Else it is noted as the last."""
        last = self._distinct.get(topic)
        if last is None or stamp_ns is None:
            return False
        if stamp_ns <= last:
            return True
        self._distinct[topic] = stamp_ns
        return False

    def hold(self, topic: str, stamp_ns: int | None, item: Item) -> int | None:
        """Hold ``item`` (a message of ``topic`` with header stamp ``stamp_ns``, None: no stamp) until its log time
        is released; returns the log time [ns], or None when it is the next watermark released."""
        if topic in self.paced and stamp_ns is not None and stamp_ns >= self.released_ns:
            t = self._at(topic, stamp_ns)
            self._held.append((t, topic, next(self._order), item))
            return t
        self._next.append((topic, next(self._order), item))
        return None

    @property
    def held(self) -> int:
        """Messages held."""
        return len(self._held) + len(self._next)

    def release(self, watermark_ns: int) -> list[tuple[int, Item]]:
        """(log time, item) of the messages logged at or before ``watermark_ns``, in the order to write them: by log
        time, then topic name, then the order received. Nothing later is logged at or before ``watermark_ns``. A
        watermark before time started (negative: the lock-step's joining reports) releases nothing: what waits is
        logged at the first real one (a log time is never negative)."""
        if watermark_ns < 0:
            return []
        if watermark_ns > self.released_ns:
            self.released_ns = watermark_ns
        waiting, self._next = self._next, []
        self._held += [(self._at(topic, self.released_ns), topic, order, item) for topic, order, item in waiting]
        ready = [h for h in self._held if h[0] <= watermark_ns]
        if not ready:
            return []
        self._held = [h for h in self._held if h[0] > watermark_ns]
        ready.sort(key=lambda h: (h[0], h[1], h[2]))
        return [(t, item) for t, _, _, item in ready]

    def release_all(self) -> list[tuple[int, Item]]:
        """Everything held, in the order to write it (the recording stops; what waits for the next watermark is
        logged at the last one released)."""
        waiting, self._next = self._next, []
        at = max(self.released_ns, 0)  # (stopped before time started: at its start)
        self._held += [(self._at(topic, at), topic, order, item) for topic, order, item in waiting]
        ready = sorted(self._held, key=lambda h: (h[0], h[1], h[2]))
        self._held = []
        if ready:
            self.released_ns = max(self.released_ns, ready[-1][0])
        return [(t, item) for t, _, _, item in ready]
