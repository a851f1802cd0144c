"""The bounded end of a node whose DDS teardown hangs (crane_stiffness.rosnode.exit_watchdog, wired into run.run).

The hang it guards against (Fast DDS deleting a participant while a discovery callback is in flight) spins in C++
with the GIL held; here a C call that sleeps without releasing the GIL stands for it (``ctypes.PyDLL``), so no Python
thread could end the process: only the watchdog's C timer thread can.
"""
from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest

from helpers import PATIENCE_S, REPO  # a process that should end by itself: 600 s if the watchdog failed

#: A hang with the GIL held: ``sleep`` called through PyDLL, which keeps the GIL [s].
HANG = 'import ctypes; ctypes.PyDLL(None).sleep(600)'


def run_python(code: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, '-c', textwrap.dedent(code)], cwd=REPO, capture_output=True, text=True,
                          timeout=PATIENCE_S)


@pytest.mark.parametrize('status', [0, 7])
def test_a_step_hanging_with_the_gil_held_ends_with_the_status_and_the_message(status):
    done = run_python(f"""
        from crane_stiffness.rosnode.exit_watchdog import ExitWatchdog
        watchdog = ExitWatchdog()
        print(watchdog.arm(0.5, {status}, '[demo] stuck in the teardown'), flush=True)
        {HANG}
        print('not reached', flush=True)
        """)
    assert done.returncode == status, done
    assert done.stdout == 'True\n'
    assert done.stderr.startswith('[demo] stuck in the teardown'), done.stderr  # (then perror's ": Success")


def test_a_disarmed_watchdog_never_fires():
    done = run_python("""
        import sys, time
        from crane_stiffness.rosnode.exit_watchdog import ExitWatchdog
        watchdog = ExitWatchdog()
        assert watchdog.arm(0.2, 0, '[demo] stuck')
        watchdog.disarm()
        time.sleep(1.5)
        sys.exit(3)
        """)
    assert (done.returncode, done.stderr) == (3, '')


@pytest.mark.ros
def test_a_node_whose_dds_teardown_hangs_still_ends_with_its_status_after_its_final_counters():
    """run.run: the node's final counters first, then the teardown (here destroy_node hangs with the GIL held);
    the process ends with the node's exit status and says why."""
    done = run_python(f"""
        from types import SimpleNamespace
        from rclpy.node import Node
        from crane_stiffness.rosnode import run

        class Stuck(Node):
            def __init__(self):
                super().__init__('stuck')
                self.counters = SimpleNamespace(received=5)
                self.exit_status = 4
                self.exit_requested = True  # ends the spin at once

            def destroy_node(self):
                {HANG}

        run.TEARDOWN_LIMIT_S = 1.0
        raise SystemExit(run.run(Stuck, args=['stuck']))
        """)
    assert done.returncode == 4, done
    assert done.stdout.splitlines()[-1] == 'FINAL_COUNTERS stuck {"received": 5}', done.stdout
    assert '[stuck] the DDS teardown after the final counters did not end within 1 s' in done.stderr, done.stderr
