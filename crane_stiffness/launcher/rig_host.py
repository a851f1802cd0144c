"""The simulated rig's nodes in one process, on one executor, in a host that stays up between sessions.

ROS composition puts several nodes in one container process and loads and unloads them there; :class:`RigHost`
does the same for the simulated rig. It keeps, for as long as it lives, what a rig of separate processes pays for
at every session: the interpreter with rclpy, numpy and the model's compiled kernels imported and warmed, a DDS
participant in its ROS domain (the nodes of one process share it, so they need no discovery among themselves and
their messages never leave the process), and one executor. Each session then *loads* the rig's nodes into it:
the very nodes of ``ros2 run`` (each module's ``COMPONENT``), built with the command line the launch file would
give the process (:func:`crane_stiffness.launcher.rig.ros_args`: parameter files, ``-p`` values, remappings) as
node arguments, so every parameter is read, checked and refused as it is at ``ros2 run``. When the program is done
the nodes are taken down as SIGINT takes down a process (``crane_stiffness.rosnode.run``): each leaves simulated
time, closes its files (the recorder its bag), prints its final counters and is destroyed. The next session loads
new nodes: nothing of one session's state reaches the next, and on simulated time its bag and numbers are those
of a fresh rig of separate processes (test/launcher/test_rig_host.py compares them message by message).

A host runs the simulated rig only (``transport:=sim``): drivers and device emulators talk to devices and stay
processes of their own, as do the live view and the hardware. Each node is still its own executable for
``ros2 run`` and ``ros2 launch``. The campaign's workers each keep one host (crane_stiffness.campaign.distributed).
"""
from __future__ import annotations

import ctypes
import importlib
import os
import sys
import threading
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Callable, Iterator, Mapping

from crane_stiffness.launcher.domains import claim_domain
from crane_stiffness.launcher.rig_description import NodeStart, rig_nodes
from crane_stiffness.launcher.rosrun import RigStartError, RosRunError

__all__ = ['RigHost', 'component_class']

#: sim_clock's wall-time wait between every node having joined and time starting [s] (its ``settle_s``, 1 s for a
#: rig of processes, for DDS to match the readers across processes). Within one process a reader and a writer are
#: matched as they are created; the wait is kept short rather than nil. A session's own overrides win.
SETTLE_S = 0.1


def component_class(executable: str) -> type:
    """The node class a host loads for ``executable`` (its module's ``COMPONENT``); RosRunError for a node that
    has none (one that talks to a device, or serves a page: a process of its own)."""
    module = importlib.import_module(f'crane_stiffness.nodes.{executable}')
    cls = getattr(module, 'COMPONENT', None)
    if cls is None:
        raise RosRunError(f'node {executable!r} cannot run in a rig host (it has no COMPONENT): start it as a '
                          'process of its own (ros2 run)')
    return cls


#: Held while a session's output goes to its log: the file descriptors are the process's, so one session at a time.
_REDIRECT = threading.Lock()


@contextmanager
def _output_to(path: Path) -> Iterator[None]:
    """The process's stdout and stderr (file descriptors 1 and 2: rcutils' log lines, the final counters) go to
    ``path`` (appended) while the block runs. A host runs one session at a time, so a session's log holds its own;
    while another host of the same process has its output redirected (two hosts in one process: a Dask worker with
    more than one thread), this session's output stays on the process's own and its log says so."""
    path.parent.mkdir(parents=True, exist_ok=True)
    if not _REDIRECT.acquire(blocking=False):
        path.write_text('(this session ran beside another rig host of the same process: its output went to the '
                        "process's stderr)\n")
        yield
        return
    try:
        with _redirected(path):
            yield
    finally:
        _REDIRECT.release()


@contextmanager
def _redirected(path: Path) -> Iterator[None]:
    """File descriptors 1 and 2 to ``path``, and Python's sys.stdout and sys.stderr with them (they may be another
    object than the descriptors: pytest's capture, a Dask worker's)."""
    libc = ctypes.CDLL(None)
    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(1), os.dup(2)]
    streams = sys.stdout, sys.stderr
    with open(path, 'ab', buffering=0) as log:
        os.dup2(log.fileno(), 1)
        os.dup2(log.fileno(), 2)
        sys.stdout = sys.stderr = text = open(log.fileno(), 'w', buffering=1, closefd=False)
        try:
            yield
        finally:
            text.flush()
            sys.stdout, sys.stderr = streams
            libc.fflush(None)  # what C wrote (rcutils) into its buffers goes to this log, not the next one
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            for fd in saved:
                os.close(fd)


class RigHost:
    """A process's simulated rig: one rclpy context in ROS domain ``domain_id`` and one executor, up until
    :meth:`close`; :meth:`run` plays one session on it. Not thread-safe: one session at a time."""

    def __init__(self, domain_id: int) -> None:
        import rclpy
        from rclpy.signals import SignalHandlerOptions

        from crane_stiffness.rosnode.discovery import use_quick_discovery

        use_quick_discovery()
        # The domain claimed host-wide while the host is up (crane_stiffness.launcher.domains): one in use (another
        # worker's rig, any ROS program) is passed over for the next free one, so two hosts never mix their data.
        self.claim = claim_domain(int(domain_id), f'rig host {os.getpid()}')
        self.domain_id = self.claim.domain
        self.context = rclpy.Context()
        # args=[]: not sys.argv, whose NAME:=VALUE (campaign run --rig-arg) rcl reads as deprecated remap rules
        rclpy.init(args=[], context=self.context, domain_id=self.domain_id,
                   signal_handler_options=SignalHandlerOptions.NO)
        self.executor: Any = None  # a session's, while it runs
        self.sessions = 0

    def close(self) -> None:
        import rclpy
        rclpy.try_shutdown(context=self.context)
        self.claim.release()

    def __enter__(self) -> 'RigHost':
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def run(self, share: Path, out: Path, program: str, session: str = 'rig', record: bool = True,
            ready_timeout_s: float = 120.0, overrides: Mapping[str, Mapping[str, Any]] | None = None,
            bags: Path | None = None, progress: Callable[[float], None] | None = None,
            arguments: Mapping[str, str] | None = None, should_stop: Callable[[], bool] | None = None
            ) -> tuple[dict[str, Any], Any, float, dict[str, str]]:
        """One session, as :func:`crane_stiffness.launcher.rig.run_rig` runs it with processes and with the same
        result: (summary, observer, load-to-program-start [s], logs). The nodes' output goes to
        ``out/logs/rig_host.log`` (the logs returned: ``{'rig_host': text}``)."""
        from crane_stiffness.launcher.rig import Observer, ProgramWatch, config_files, start_overrides, summarize
        from crane_stiffness.sim.program import load_program_file

        bags = out / 'bags' if bags is None else bags
        given: dict[str, Any] = {**(arguments or {}), 'program': program, 'record': record, 'session': session}
        if str(given.get('transport', 'sim')) != 'sim':
            raise RosRunError(f"a rig host runs the simulated sensors only (transport:=sim), not "
                              f"transport:={given['transport']}")
        nodes = rig_nodes(share, given)
        classes = {node.name: component_class(node.executable) for node in nodes}  # refused before anything starts
        prog = load_program_file(config_files(share, program)['program'])
        if record:
            bags.mkdir(parents=True, exist_ok=True)
        log = out / 'logs' / 'rig_host.log'
        self.sessions += 1
        from crane_stiffness.rosnode.run import make_executor
        # An executor per session: rclpy's EventsExecutor does not take nodes removed and new ones added (a crash in
        # the next session's spin), and the last session's entities go with it.
        self.executor = make_executor('events', self.context)
        observer = Observer(f'rig_observer_{self.domain_id}', context=self.context, executor=self.executor)
        observer.should_stop = should_stop
        loaded: list[Any] = []
        codes: dict[str, int] = {}
        log.parent.mkdir(parents=True, exist_ok=True)
        with open(log, 'a') as f:
            f.write(f'[rig_host] session {self.sessions} of this host: {session} (program {program})\n')
        with _output_to(log):
            try:
                launched = time.monotonic()
                for node in nodes:
                    extra = dict((overrides or {}).get(node.name, {}))
                    if node.name == 'sim_clock':
                        extra.setdefault('settle_s', SETTLE_S)
                    loaded.append(self._load(node, classes[node.name],
                                             start_overrides(node, bags if record else None, ready_timeout_s, extra)))
                program_node = next(n for n, start in zip(loaded, nodes) if start.runs_program)
                self._wait_for_start(observer, program_node, ready_timeout_s + 30, log)
                assert observer.running_at is not None
                started_after = observer.running_at - launched
                watch = ProgramWatch(prog.duration_s)
                while not getattr(program_node, 'exit_requested', False) and not watch.expired(observer.progress):
                    observer.spin_once(0.1)
                    if progress is not None:
                        progress(observer.progress)
                if not getattr(program_node, 'exit_requested', False) or program_node.exit_status != 0:
                    stalled = f' ({watch.reason()})' if not getattr(program_node, 'exit_requested', False) else ''
                    raise RosRunError(f'load_program did not finish{stalled}: {_tail(log)}')
                observer.settle()
            finally:
                codes = self._unload(loaded)
                observer.drain()  # everything the nodes published (delivered within the process as they did)
                observer.destroy_node()
                self.executor.shutdown()
                self.executor = None
        logs = {'rig_host': log.read_text(errors='replace')}
        summary = summarize(share, program, session, bags, observer, codes)
        summary['ros_domain_id'] = self.domain_id
        return summary, observer, started_after, logs

    def _load(self, start: NodeStart, cls: type, extra: Mapping[str, Any]) -> Any:
        """``start``'s node built as ``ros2 run`` builds it, from the same arguments, and added to the executor."""
        from crane_stiffness.launcher.rig import ros_args
        from crane_stiffness.rosnode import parameters

        args = ros_args(start, extra)
        try:
            with parameters.started_with(args):
                node = cls(context=self.context, cli_args=args)
            try:
                parameters.check_command_line_params(args, node.get_name(), parameters.declared_names(node))
            except ValueError:
                node.destroy_node()
                raise
        except Exception as exc:
            raise RosRunError(f'{start.name} cannot start: {type(exc).__name__}: {exc}') from exc
        self.executor.add_node(node)
        return node

    def _wait_for_start(self, observer: Any, program_node: Any, timeout_s: float, log: Path) -> None:
        """Spin until the program runs (or has run: it may end before the observer's state arrives)."""
        def started() -> bool:
            if observer.running_at is None and getattr(program_node, 'exit_requested', False):
                if program_node.exit_status == 0:
                    observer.running_at = time.monotonic()
                    return True
                raise RosRunError(f'load_program ended with status {program_node.exit_status} before starting '
                                  f'the program: {_tail(log)}')
            return observer.running_at is not None
        observer.spin_until(started, timeout_s, 'the program to start', error=RigStartError)

    def _unload(self, nodes: list[Any]) -> dict[str, int]:
        """Every node taken down as ``run`` takes down its process at SIGINT: all leave simulated time first (the
        clock waits for none of them any more), then each closes its files, prints its counters and goes."""
        from crane_stiffness.rosnode.run import final_counters

        for node in nodes:
            sim = getattr(node, 'sim', None)
            if sim is not None:
                sim.leave()
        codes: dict[str, int] = {}
        for node in nodes:
            name = node.get_name()
            try:
                close = getattr(node, 'close', None)
                if close is not None:
                    close()
                codes[name] = int(getattr(node, 'exit_status', 0) or 0)
                final_counters(node)
            except Exception as exc:  # said, and the others are still taken down (a process would exit with 1)
                print(f'[rig_host] {name} failed while closing: {type(exc).__name__}: {exc}', file=sys.stderr,
                      flush=True)
                codes[name] = 1
            finally:
                self.executor.remove_node(node)
                node.destroy_node()
        return codes


def _tail(log: Path, chars: int = 3000) -> str:
    sys.stdout.flush()
    sys.stderr.flush()
    try:
        return log.read_text(errors='replace')[-chars:]
    except OSError:
        return ''
