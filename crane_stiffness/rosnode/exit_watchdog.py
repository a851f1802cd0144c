"""A bounded end for a node whose DDS teardown hangs: ``ExitWatchdog``.

A node that has closed its files and printed its final counters still destroys its rclpy node, and with the last
node rmw_fastrtps deletes the DDS participant. Fast DDS 2.14 (the ROS wheels') can deadlock there: deleting the
participant first waits, holding the participant's listener mutex, for discovery callbacks in flight to end; its
wait for "forever" (``time_point::max``) overflows into a deadline in the past and spins without sleeping, and a
callback in flight (another node of the rig leaving at the same moment: Ctrl-C reaches every node) needs that
mutex to finish (eProsima/Fast-DDS#6513). The main thread spins in C++ holding the GIL, so no Python code runs again
in that process: seen about once in 30 Ctrl-C'd rigs on a loaded 2-core machine, a node hanging after its
FINAL_COUNTERS until ``ros2 launch`` killed it.

The watchdog is a POSIX timer whose expiry runs C functions on a thread of libc's own (``SIGEV_THREAD``), which
needs no GIL: after ``limit_s`` it writes its message to stderr (``perror``: the line ends with the C library's
text for errno, "Success"), and a moment later ends the process with the node's exit status (``_exit``). What is
skipped then is only DDS's goodbye: the other participants notice this one's end by its lease, as after a crash.
Linux (glibc) only; elsewhere :meth:`ExitWatchdog.arm` returns False and the teardown runs unguarded.
"""
from __future__ import annotations

import ctypes
import sys

#: ``struct sigevent`` notification by a new thread, and the monotonic clock (Linux).
SIGEV_THREAD = 2
CLOCK_MONOTONIC = 1
#: The pause between the message and the exit [s]: stderr is unbuffered, this only orders the two threads.
MESSAGE_LEAD_S = 0.1


class _Sigevent(ctypes.Structure):
    """``struct sigevent`` of glibc on Linux (64 bytes): value, signal, notify, then the SIGEV_THREAD function."""

    _fields_ = [('value', ctypes.c_void_p), ('signo', ctypes.c_int), ('notify', ctypes.c_int),
                ('function', ctypes.c_void_p), ('attribute', ctypes.c_void_p), ('_pad', ctypes.c_int * 8)]


class _Itimerspec(ctypes.Structure):
    _fields_ = [('interval_s', ctypes.c_long), ('interval_ns', ctypes.c_long),
                ('value_s', ctypes.c_long), ('value_ns', ctypes.c_long)]


def _libc() -> ctypes.CDLL | None:
    """The process's C library with ``timer_create`` (glibc 2.34+ has it in libc, older ones in librt)."""
    if not sys.platform.startswith('linux'):
        return None
    for name in (None, 'librt.so.1'):
        try:
            lib = ctypes.CDLL(name, use_errno=True)
            lib.timer_create  # noqa: B018 (present?)
            return lib
        except (OSError, AttributeError):
            continue
    return None


class ExitWatchdog:
    """``arm(limit_s, status, message)`` before a step that may hang with the GIL held; ``disarm()`` after it.

    If the step has not returned ``limit_s`` seconds (monotonic) after ``arm``, ``message`` goes to stderr and the
    process ends with exit status ``status``, whatever its threads are doing. Its buffers live as long as the object:
    keep it until ``disarm``.
    """

    def __init__(self) -> None:
        self._libc = _libc()
        self._timers: list[ctypes.c_void_p] = []
        self._message: ctypes.Array[ctypes.c_char] | None = None

    def arm(self, limit_s: float, status: int, message: str) -> bool:
        """Start the timers; False (nothing armed) where POSIX timers by thread are not available."""
        libc = self._libc
        if libc is None or self._timers:
            return False
        self._message = ctypes.create_string_buffer(message.encode('utf-8', 'replace'))
        steps = ((limit_s, ctypes.cast(libc.perror, ctypes.c_void_p).value, ctypes.addressof(self._message)),
                 (limit_s + MESSAGE_LEAD_S, ctypes.cast(libc._exit, ctypes.c_void_p).value, int(status) & 0xFF))
        for after_s, function, value in steps:
            event = _Sigevent(value=value or None, notify=SIGEV_THREAD, function=function)
            timer = ctypes.c_void_p()
            if libc.timer_create(CLOCK_MONOTONIC, ctypes.byref(event), ctypes.byref(timer)) != 0:
                self.disarm()
                return False
            self._timers.append(timer)
            seconds, nanoseconds = divmod(round(after_s * 1e9), 1_000_000_000)
            spec = _Itimerspec(value_s=seconds, value_ns=nanoseconds)
            if libc.timer_settime(timer, 0, ctypes.byref(spec), None) != 0:
                self.disarm()
                return False
        return True

    def disarm(self) -> None:
        """Delete the timers (a timer that has not expired never will); the message buffer may go."""
        libc = self._libc
        while self._timers:
            timer = self._timers.pop()
            if libc is not None:
                libc.timer_delete(timer)
