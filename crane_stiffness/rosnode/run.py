"""``run``: the ``main`` of every node (start-up checks, the executor, signals, a clean shutdown, the final
counters)."""
from __future__ import annotations

import json
import os
import signal
import sys
import threading
from typing import Any, Callable, Protocol, Sequence, TypeVar

import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

from crane_stiffness.rosnode import entry
from crane_stiffness.rosnode.exit_watchdog import ExitWatchdog
from crane_stiffness.rosnode import parameters
from crane_stiffness.rosnode.sim_time import SimTimeParticipant
from crane_stiffness.params.files import params_files_from_args


#: How long the DDS teardown after a node's final counters may take before the process ends without it [s]
#: (normally well under a second; ``ros2 launch`` escalates to SIGTERM 5 s after Ctrl-C and SIGKILL 5 s later).
TEARDOWN_LIMIT_S = 5.0


def make_executor(kind: str, context: Any):
    """'events': rclpy's EventsExecutor (in C++, about a quarter of the CPU per message of the standard one, which
    matters at 1 kHz on two cores); 'single': SingleThreadedExecutor."""
    if kind == 'events':
        try:
            from rclpy.experimental import EventsExecutor
            return EventsExecutor(context=context)
        except ImportError:  # an rclpy without it
            pass
    return SingleThreadedExecutor(context=context)


class ShutdownRequest:
    """SIGINT/SIGTERM as a flag the spin loop of :func:`run` reads.

    rclpy's own handlers raise KeyboardInterrupt wherever the main thread is, also inside a callback that the C++
    EventsExecutor called (pybind11 then aborts the process: ``terminate called after throwing ...
    error_already_set``), and shut the context down under callbacks that are still running (``Exception in 'timers'
    callback``). Here the Python handler only sets :attr:`signum`, and the signal's number, written by Python to a
    wake-up pipe whichever thread the kernel chose, is read by a thread of its own that also wakes the executor
    (``wake``): a main thread waiting in C++ sees the flag at once. A signal, once or repeated (Ctrl-C reaches every
    node and ``ros2 launch`` forwards it once more), ends the spin loop after the running callback; the node closes
    its files and exits with status 0. :meth:`ignore` keeps a late signal from killing the finished process.

    The executor is reached only through :meth:`attach` / :meth:`detach`, under a lock: once the teardown has
    detached it, a signal arriving then (the second or third Ctrl-C) never calls into an executor that is being
    shut down, and the signal thread never holds the last reference to it (its C++ destructor would then run on
    that daemon thread, possibly while the interpreter finalizes).
    """

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self) -> None:
        self.signum: int | None = None
        self.count = 0
        self._wake: Callable[[], None] | None = None
        self._lock = threading.Lock()  # wake() never runs while the teardown detaches the executor

    def __bool__(self) -> bool:
        return self.signum is not None

    def attach(self, wake: Callable[[], None]) -> None:
        """A signal from now on also calls ``wake`` (the executor's), so a main thread waiting in C++ sees it."""
        with self._lock:
            self._wake = wake

    def detach(self) -> None:
        """No signal calls the executor any more; returns once a ``wake`` under way has returned."""
        with self._lock:
            self._wake = None

    def handle(self, signum: int, frame: Any = None) -> None:
        self.count += 1
        if self.signum is None:
            self.signum = signum
        with self._lock:
            if self._wake is not None:
                try:
                    self._wake()
                except Exception:  # the flag is enough
                    pass

    def install(self) -> bool:
        """Install the handlers and the wake-up thread (main thread only: Python runs signal handlers there);
        False if not possible."""
        if threading.current_thread() is not threading.main_thread():
            return False
        read_fd, write_fd = os.pipe()
        os.set_blocking(write_fd, False)
        # The pipe first, then the handlers: a signal in between still reaches the pipe.
        signal.set_wakeup_fd(write_fd, warn_on_full_buffer=False)
        for sig in self.SIGNALS:
            signal.signal(sig, lambda signum, frame: None)  # the flag is set by the thread; never an exception
        threading.Thread(target=self._wait, args=(read_fd,), name='shutdown_signals', daemon=True).start()
        for signum in entry.pending():  # arrived while the node's module was being imported
            self.handle(signum)
        return True

    def _wait(self, read_fd: int) -> None:
        while True:
            for signum in os.read(read_fd, 64):
                if signum in self.SIGNALS:
                    self.handle(signum)

    def ignore(self) -> None:
        """From now on SIGINT/SIGTERM do nothing: the process is ending, and Python's finalization would reset its
        handlers to the default (a signal then, e.g. launch forwarding Ctrl-C, would kill it with -2/-15)."""
        if threading.current_thread() is threading.main_thread():
            for sig in self.SIGNALS:
                signal.signal(sig, signal.SIG_IGN)


class RunnableNode(Protocol):
    """What :func:`run` reads of the node it runs, beyond rclpy's ``Node``. Every member is optional: a node without
    it gets the default shown, so a plain ``Node`` runs too (``run`` reads each with ``getattr``)."""

    #: True ends the spin loop as SIGINT would (a node that has finished its work) [False].
    exit_requested: bool
    #: The process's exit status, read after :meth:`close` [0].
    exit_status: int
    #: The message counters printed once at exit (``FINAL_COUNTERS``, :func:`final_counters`): an object whose
    #: ``__dict__`` or a mapping, numbers and strings only [None: nothing printed].
    counters: Any
    #: The node's part in simulated time: left first, so simulated time waits for it no more [None].
    sim: SimTimeParticipant | None

    def close(self) -> None:
        """Close the node's files and devices, after the spin loop and before the node is destroyed [nothing]."""


NodeT = TypeVar('NodeT', bound=Node)


def run(node_factory: Callable[[], NodeT], args: Sequence[str] | None = None,
        executor: str | Callable[[NodeT], str] = 'events') -> int:
    """The ``main`` of every node: init, build, spin until SIGINT (Ctrl-C), SIGTERM or ``node.exit_requested``,
    clean up; returns the exit status (``node.exit_status``, default 0). What it reads of the node:
    :class:`RunnableNode`.

    Signals only set a flag (:class:`ShutdownRequest`; rclpy's handlers are not installed), so every exit takes
    the same path: the spin loop ends, ``close()`` (if the node has one) runs, the node's final counters are
    printed, the node is destroyed and rclpy shut down. A node that cannot start (bad parameter) exits with
    status 2 and the reason on stderr. It is a process's main: SIGINT and SIGTERM are ignored after it returns.
    """
    name = getattr(node_factory, '__name__', 'node')
    request = ShutdownRequest()
    request.install()
    argv = list(sys.argv if args is None else args)
    # A missing or malformed --params-file would make rclpy.init raise (RCLError): say which file and why.
    reason = next(filter(None, map(parameters.params_file_problem, params_files_from_args(argv))), None)
    if reason is None:
        try:
            rclpy.init(args=None if args is None else argv, signal_handler_options=SignalHandlerOptions.NO)
        except Exception as exc:  # e.g. a parameter file rcl reads differently
            reason = parameters.one_line(f'{type(exc).__name__}: {exc}')
    if reason is not None:
        print(f'[{name}] cannot start: {reason}', file=sys.stderr)
        return 2
    try:
        with parameters.started_with(argv):
            node = node_factory()
        try:  # a misspelt -p name would be ignored by rclpy: the node would run with the default
            parameters.check_command_line_params(argv, node.get_name(), parameters.declared_names(node))
        except ValueError:
            node.destroy_node()
            raise
    except (ValueError, TypeError) as exc:
        print(f'[{name}] cannot start: {exc}', file=sys.stderr)
        rclpy.try_shutdown()
        return 2
    except Exception as exc:  # e.g. rclpy's InvalidParameterTypeException from a params file
        print(f'[{name}] cannot start: {type(exc).__name__}: {exc}', file=sys.stderr)
        rclpy.try_shutdown()
        return 2
    ex = make_executor(executor(node) if callable(executor) else executor, node.context)
    ex.add_node(node)
    request.attach(ex.wake)
    try:
        while not request and rclpy.ok(context=node.context) and not getattr(node, 'exit_requested', False):
            ex.spin_once(timeout_sec=0.1)
    except ExternalShutdownException:
        pass
    finally:
        request.detach()  # first: a later signal must not call into the executor being shut down
        # What follows reads the optional members of RunnableNode.
        sim = getattr(node, 'sim', None)  # simulated time waits for this node no more
        if sim is not None:
            sim.leave()
        close = getattr(node, 'close', None)
        if close is not None:
            close()
        status = int(getattr(node, 'exit_status', 0) or 0)
        final_counters(node)
        # The node's work is done; what follows only says goodbye to DDS, and can deadlock in Fast DDS with the
        # GIL held (exit_watchdog): then the process ends after TEARDOWN_LIMIT_S with its status and a message.
        watchdog = ExitWatchdog()
        watchdog.arm(TEARDOWN_LIMIT_S, status, f'[{node.get_name()}] the DDS teardown after the final counters did '
                     f'not end within {TEARDOWN_LIMIT_S:g} s (Fast DDS deadlock deleting the participant, '
                     'eProsima/Fast-DDS#6513): exiting with the node\'s status without it')
        ex.remove_node(node)
        ex.shutdown()
        del ex  # its C++ destructor runs here, on the main thread, not later in the interpreter's finalization
        node.destroy_node()
        rclpy.try_shutdown()
        watchdog.disarm()
        request.ignore()
    return status


def final_counters(node: Node) -> None:
    """Print the node's message counters once at exit (``FINAL_COUNTERS <node> {json}``): the totals a benchmark or
    an engineer reads after a run, when /diagnostics has stopped."""
    counters = getattr(node, 'counters', None)
    if counters is None:
        return
    values = counters.__dict__ if hasattr(counters, '__dict__') else counters
    try:
        text = json.dumps({k: v for k, v in dict(values).items() if isinstance(v, (int, float, str))})
    except (TypeError, ValueError):
        return
    print(f'FINAL_COUNTERS {node.get_name()} {text}', flush=True)
