"""Keeping a replay on time: the bag read ahead on a thread of its own, and the interpreter kept out of the way.

``session_player`` publishes each message at its due time on one thread. What made messages late there was not the
sleep but the work between two messages: reading and decompressing the next chunk of the bag (a few milliseconds,
in the publishing thread, every ~0.5 s of a recording: the dozen messages after each chunk's start went out late)
and the garbage collector's full collections over every object of the process (rclpy's, numpy's, the bag reader's).

- :class:`ReadAhead` reads the bag's messages on a thread of its own into a buffer and refills it in batches (from
  ``low`` up to ``high`` messages), so that the publishing thread only takes messages out of memory and the reader
  runs seldom, between messages, not once per message; a bag of a few minutes is read whole before it plays.
- :func:`quiet_interpreter` (a context manager around the playback): the objects that exist before the playback are
  frozen out of the garbage collector's reach (``gc.freeze``: a collection then scans only what the playback made),
  and the interpreter's thread switch interval is short, so that the publishing thread, waking from its sleep, gets
  the interpreter within a fraction of a millisecond even while the read-ahead thread is parsing a chunk (the
  default, 5 ms, would let the reader hold it for that long).
- :func:`fine_timer_slack`: the publishing thread's timer slack (Linux's allowance for waking a sleeper late,
  50 µs by default) set to 1 µs.
- a message due within :data:`EARLY_NS` (0.1 ms) is published at once, not slept for. A bag recorded on the wall
  clock logs its messages at their receipt times, which come in bursts (dozens of messages within tens of µs after
  the recorder was held up); there the cost per message decides: at ~45 µs per message (a sleep call and its
  wake-up, plus the publish) the messages at the end of a burst go out 1–3 ms late, at ~20 µs none does (computed
  from the demo's wall-clock bag).
"""
from __future__ import annotations

import ctypes
import ctypes.util
import gc
import sys
import threading
from collections import deque
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from typing import Generic, TypeVar

T = TypeVar('T')

#: Messages the read-ahead buffer holds at most, and the level at which it is refilled (up to READ_AHEAD_HIGH):
#: at the rig's ~2,600 messages/s (every topic) about 190 s and 95 s of a recording, ~120 MB and ~60 MB (a message
#: in memory is ~240 bytes). A session bag of a few minutes is so read whole before its playback starts (about 8 µs
#: per message); the reader then never runs during the playback. Reading goes in runs of a whole chunk (~1,000
#: messages, a few ms that no pause can cut), and a run that overlaps a burst of the playback makes its messages
#: late: on the demo's wall-clock bag p99 1.3 ms with a buffer of 8,000, 0.34 ms read whole.
READ_AHEAD_HIGH = 500_000
READ_AHEAD_LOW = 250_000
#: The interpreter's thread switch interval during a playback [s] (Python's default is 0.005).
SWITCH_INTERVAL_S = 0.0002
_PR_SET_TIMERSLACK = 29
#: A message due within this [ns] is published at once, not slept for: a sleep and its wake-up cost tens of µs of
#: their own, which a burst of messages due tens of µs apart (a wall-clock bag's receipt times) would add up message
#: after message. (Spinning out the wait instead was tried: on a loaded machine the spinning thread then loses the
#: scheduler's favour for sleepers and whole time slices, p99 7x worse.)
EARLY_NS = 100_000


class ReadAhead(Generic[T]):
    """The items of ``source`` (an iterator that may take milliseconds per item now and then, as a bag reader does
    at each chunk), taken on a thread of its own into a buffer of at most ``high`` items, refilled once it is down
    to ``low``.

    :meth:`take` gives the next item from memory. An exception of ``source`` is raised by :meth:`take` where it
    occurred in the sequence. :meth:`close` stops the thread (call it before closing what ``source`` reads).
    """

    def __init__(self, source: Iterable[T], high: int = READ_AHEAD_HIGH, low: int = READ_AHEAD_LOW,
                 name: str = 'read_ahead') -> None:
        if not 0 <= low < high:
            raise ValueError(f'read-ahead levels low = {low}, high = {high}: need 0 <= low < high')
        self.high, self.low = high, low
        self._source = iter(source)
        self._buffer: deque[T] = deque()
        self._cond = threading.Condition()
        self._done = False
        self._closed = False
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._fill, name=name, daemon=True)
        self._thread.start()

    def _fill(self) -> None:
        buffer, cond = self._buffer, self._cond
        try:
            for item in self._source:
                if len(buffer) >= self.high:
                    with cond:
                        cond.notify_all()  # a full buffer: whoever waits for it to fill goes on
                        while len(buffer) > self.low and not self._closed:
                            cond.wait(0.5)
                if self._closed:
                    return
                buffer.append(item)
                if len(buffer) == 1:  # the taker may be waiting on an empty buffer
                    with cond:
                        cond.notify_all()
        except BaseException as exc:  # handed to the taker at this point of the sequence
            self._error = exc
        finally:
            with cond:
                self._done = True
                cond.notify_all()
            close = getattr(self._source, 'close', None)
            if close is not None:
                close()

    def wait_filled(self, timeout: float | None = None) -> bool:
        """Wait until the buffer is full or ``source`` is exhausted (True), or ``timeout`` [s] passed (False)."""
        with self._cond:
            return self._cond.wait_for(lambda: self._done or self._closed or len(self._buffer) >= self.high,
                                       timeout)

    def take(self, timeout: float) -> tuple[bool, T | None]:
        """(True, the next item), or (False, None) when none came within ``timeout`` [s]. Raises StopIteration when
        ``source`` is exhausted and everything was taken, or the exception ``source`` raised."""
        buffer = self._buffer
        while True:
            try:
                item = buffer.popleft()
            except IndexError:
                with self._cond:
                    if not buffer:
                        if self._done:
                            if self._error is not None:
                                error, self._error = self._error, None
                                raise error
                            raise StopIteration
                        if not self._cond.wait(timeout) and not buffer and not self._done:
                            return False, None
                continue
            if len(buffer) == self.low:  # the filler waits for this level
                with self._cond:
                    self._cond.notify_all()
            return True, item

    def close(self, timeout: float = 10.0) -> None:
        """Stop reading (the thread ends once the item it is reading is in) and drop what is buffered."""
        with self._cond:
            self._closed = True
            self._cond.notify_all()
        if self._thread is not threading.current_thread():
            self._thread.join(timeout)
        self._buffer.clear()

    def __iter__(self) -> Iterator[T]:
        while True:
            try:
                got, item = self.take(1.0)
            except StopIteration:
                return
            if got:
                yield item  # type: ignore[misc]  # an item of source


@contextmanager
def quiet_interpreter(switch_interval_s: float = SWITCH_INTERVAL_S) -> Iterator[None]:
    """For the time of a playback: the objects that exist now frozen out of the garbage collector's reach, and a
    short thread switch interval (restored after; the freeze is undone so they can be collected again)."""
    previous = sys.getswitchinterval()
    gc.collect()
    gc.freeze()
    sys.setswitchinterval(switch_interval_s)
    try:
        yield
    finally:
        sys.setswitchinterval(previous)
        gc.unfreeze()


def fine_timer_slack(slack_ns: int = 1000) -> bool:
    """Set the calling thread's timer slack to ``slack_ns`` (Linux ``prctl(PR_SET_TIMERSLACK)``): its sleeps end
    that close to their time, not up to 50 µs later. False where that is not available (the sleeps keep the
    system's slack)."""
    if not sys.platform.startswith('linux'):
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library('c') or 'libc.so.6', use_errno=True)
        return libc.prctl(_PR_SET_TIMERSLACK, ctypes.c_ulong(slack_ns), 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False
