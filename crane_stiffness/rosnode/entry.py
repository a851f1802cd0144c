"""The entry points of the node executables (``<prefix>/lib/crane_stiffness/<node>``): SIGINT and SIGTERM are held
from the first instant.

A node's module takes a second or more to import (rclpy, numpy, numba). ``ros2 launch`` starts every node at once
and Ctrl-C reaches all of them, so a signal often arrives during that import; with Python's default handler it would
end the node with a KeyboardInterrupt traceback. Here the signal is only noted, the import finishes, and
:class:`crane_stiffness.rosnode.run.ShutdownRequest` takes it over: the node ends at once, cleanly, with status 0.
This module imports nothing heavy; each node's executable (``nodes_bin/<node>`` in the source tree) is three lines
calling one of its entry points, so only the interpreter's own start-up comes before it.
"""
from __future__ import annotations

import importlib
import os
import signal
import sys
from typing import Callable

from crane_stiffness.nodes import NODES

#: The signals that arrived before the node's own handlers were installed, in order.
_PENDING: list[int] = []


def _note(signum: int, frame: object = None) -> None:
    _PENDING.append(signum)


def pending() -> list[int]:
    """Signals noted before :class:`~crane_stiffness.rosnode.run.ShutdownRequest` was installed (then cleared)."""
    out = list(_PENDING)
    _PENDING.clear()
    return out


def _main(module: str) -> int:
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, _note)
    from crane_stiffness.rosnode.discovery import use_quick_discovery
    use_quick_discovery()  # before rclpy makes the participant
    status = importlib.import_module(f'crane_stiffness.nodes.{module}').main()
    # The node has closed its files, printed its counters, destroyed itself and shut rclpy down: what is left is
    # the interpreter's finalization, which with numpy, numba and rclpy loaded can take seconds on a busy machine
    # (a Ctrl-C'd rig then looks hung after FINAL_COUNTERS). The process ends here, with its status.
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(int(status or 0))


def __getattr__(name: str) -> Callable[[], int]:
    """``from crane_stiffness.rosnode.entry import crane_model``: the entry point of the node of that name (one of
    :data:`crane_stiffness.nodes.NODES`; any other name is refused)."""
    if name not in NODES:
        raise AttributeError(f'module {__name__!r} has no attribute {name!r} (no node {name!r} in '
                             'crane_stiffness.nodes.NODES)')
    return lambda: _main(name)
