"""A :class:`~crane_stiffness.launcher.rig_host.RigHost` in a process of its own, kept up for as many sessions as it
is given: what a campaign runs its sessions on (one per ROS domain, side by side).

The host process is a one-worker process pool (``spawn``: a clean interpreter, never a fork of a process that holds
threads or a DDS participant). The caller's thread hands it one session at a time and waits for the session's
outcome: the numbers of the run (:func:`outcome`), never the node objects. Meanwhile it reads the program's
progress from shared memory and, when asked to stop (Ctrl-C in the campaign), raises the host's stop flag: the
session then ends as a Ctrl-C'd rig ends (every node closed, its bag finished) and :class:`RigInterrupted` comes
back. The host process itself ignores SIGINT, which a terminal sends to the whole process group: the campaign
decides when its sessions stop.
"""
from __future__ import annotations

import os
import signal
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from multiprocessing import get_context
from typing import Any, Callable, Mapping

from crane_stiffness.launcher.rosrun import RosRunError

__all__ = ['HostProcess', 'outcome']

# --- in the host process -----------------------------------------------------------------------------------------
_HOST: Any = None
_STOP: Any = None
_PROGRESS: Any = None


def _start(domain: int, env: Mapping[str, str], stop: Any, progress: Any) -> None:
    global _HOST, _STOP, _PROGRESS
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the campaign stops the session (``stop``), not the terminal
    os.environ.update(env)
    os.environ['ROS_DOMAIN_ID'] = str(domain)
    from crane_stiffness.launcher.rig_host import RigHost
    _HOST, _STOP, _PROGRESS = RigHost(domain), stop, progress


def _session(kwargs: dict[str, Any]) -> dict[str, Any]:
    _PROGRESS.value = 0.0

    def follow(fraction: float) -> None:
        _PROGRESS.value = fraction
    summary, observer, started_after, _ = _HOST.run(**kwargs, progress=follow, should_stop=_STOP.is_set)
    return outcome(summary, observer, started_after)


def outcome(summary: dict[str, Any], observer: Any, started_after: float) -> dict[str, Any]:
    """What a session's result is made of, from a run of the rig (processes or host): its summary, the estimator's
    last values (``values``: the Float64MultiArray's data), the six-axis fit's last K and status, and the time from
    launch to the program's start [s]."""
    return {'summary': summary, 'values': None if observer.values is None else list(observer.values.data),
            'stiffness6': observer.stiffness6, 'status6': observer.status6, 'startup_s': started_after}


# --- in the caller -------------------------------------------------------------------------------------------------
class HostProcess:
    """One rig host in a process of its own in ROS domain ``domain``, up until :meth:`close`. ``env``: set in the
    host's environment (ROS_AUTOMATIC_DISCOVERY_RANGE, AMENT_PREFIX_PATH, ...)."""

    def __init__(self, domain: int, env: Mapping[str, str]) -> None:
        self._context = get_context('spawn')
        self.domain, self._env = domain, dict(env)
        self._stop = self._context.Event()
        self._progress = self._context.Value('d', 0.0, lock=False)
        self._pool = self._start_pool()

    def _start_pool(self) -> ProcessPoolExecutor:
        return ProcessPoolExecutor(1, mp_context=self._context, initializer=_start,
                                   initargs=(self.domain, self._env, self._stop, self._progress))

    def run(self, progress: Callable[[float], None] | None = None, should_stop: Callable[[], bool] | None = None,
            **kwargs: Any) -> dict[str, Any]:
        """One session: ``kwargs`` as :meth:`RigHost.run <crane_stiffness.launcher.rig_host.RigHost.run>` takes
        them (share, out, program, session, bags, overrides, arguments, ready_timeout_s); its :func:`outcome`.
        ``should_stop`` is asked while it runs (True: the session stops, RigInterrupted); Ctrl-C here stops it too,
        after which KeyboardInterrupt is raised again."""
        self._stop.clear()
        future = self._pool.submit(_session, kwargs)
        interrupted = False
        while True:
            try:
                done, _ = wait([future], timeout=0.2, return_when=FIRST_COMPLETED)
            except KeyboardInterrupt:
                interrupted = True
                self._stop.set()
                continue
            if progress is not None:
                progress(self._progress.value)
            if done:
                break
            if should_stop is not None and should_stop():
                self._stop.set()
        try:
            result = future.result()
        except RosRunError:
            if interrupted:
                raise KeyboardInterrupt from None
            raise
        except BrokenProcessPool as exc:  # the host process died: the next session gets a new one
            self._pool.shutdown(wait=False)
            self._pool = self._start_pool()
            raise RosRunError(f'the rig host of domain {self.domain} died during the session: {exc}') from exc
        except Exception as exc:  # an error outside the rig (a result that could not be sent back, ...)
            raise RosRunError(f'the rig host of domain {self.domain} failed: {type(exc).__name__}: {exc}') from exc
        if interrupted:
            raise KeyboardInterrupt
        return result

    def close(self) -> None:
        self._pool.shutdown(wait=True, cancel_futures=True)

    def __enter__(self) -> 'HostProcess':
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()
