"""The entry points of the node executables (``<prefix>/lib/crane_stiffness/<node>``): SIGINT and SIGTERM are held
from the first instant.

A node's module takes a second or more to import (rclpy, numpy, numba). ``ros2 launch`` starts every node at once
and Ctrl-C reaches all of them, so a signal often arrives during that import; with Python's default handler it would
end the node with a KeyboardInterrupt traceback. Here the signal is only noted, the import finishes, and
:class:`crane_stiffness.nodes.common.ShutdownRequest` takes it over: the node ends at once, cleanly, with status 0.
This module imports nothing heavy; each node's executable (``nodes_bin/<node>`` in the source tree) is three lines
calling one of its functions, so only the interpreter's own start-up (some 20 ms) comes before it.
"""
from __future__ import annotations

import importlib
import signal

#: The signals that arrived before the node's own handlers were installed, in order.
_PENDING: list[int] = []


def _note(signum: int, frame: object = None) -> None:
    _PENDING.append(signum)


def pending() -> list[int]:
    """Signals noted before :class:`~crane_stiffness.nodes.common.ShutdownRequest` was installed (then cleared)."""
    out = list(_PENDING)
    _PENDING.clear()
    return out


def _main(module: str) -> int:
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, _note)
    return importlib.import_module(f'crane_stiffness.nodes.{module}').main()


def load_program() -> int:
    return _main('load_program')


def crane_model() -> int:
    return _main('crane_model')


def load_cell() -> int:
    return _main('load_cell')


def lvdt() -> int:
    return _main('lvdt')


def stiffness_estimator() -> int:
    return _main('stiffness_estimator')


def session_recorder() -> int:
    return _main('session_recorder')


def session_player() -> int:
    return _main('session_player')


def netft() -> int:
    return _main('netft')


def modbus_lvdt() -> int:
    return _main('modbus_lvdt')


def rdt_emulator() -> int:
    return _main('rdt_emulator')


def modbus_emulator() -> int:
    return _main('modbus_emulator')
