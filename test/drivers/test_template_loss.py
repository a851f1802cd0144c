"""The shipped hardware template (config/drivers_ati_labjack.yaml) loses no LVDT reading on this machine beside a
busy process: the rig on the template over the device emulators (separate processes, the drivers pointed at their
loopback ports; crane_stiffness.testing.driver_loss), the side-force program, one process keeping a core busy.

Every reading is accounted for, no rate is timed: the DAQ driver's timer skipped no instant of its grid (counted from
the timer's own next call), every poll was answered, and the bag holds a reading for every grid instant from the
program's first command to its last. The F/T driver beside it lost no RDT record. The loss against the poll rate is
in docs/benchmarks.md (benchmarks/bench_driver_loss.py)."""
from __future__ import annotations

import pytest

from crane_stiffness.launcher.rosrun import installed_config
from crane_stiffness.params.files import load_params
from crane_stiffness.testing.driver_loss import TEMPLATE, run_template_rig

from helpers import REPO

pytestmark = pytest.mark.ros


def test_the_template_loses_no_lvdt_reading_beside_a_busy_process(install_tree, tmp_path):
    install, env = install_tree
    share = installed_config(install)
    rate = load_params(REPO / 'config' / TEMPLATE, 'modbus_lvdt')['poll_rate_hz']
    figures = run_template_rig(share, env, tmp_path, busy=True)
    print(figures.as_dict())
    assert figures.poll_rate_hz == rate
    # 21 s of program at the template's rate: the bag's span alone holds thousands of grid instants.
    assert figures.bag_readings >= 20 * rate, figures
    assert figures.missed_polls == 0 and figures.failures == 0, figures
    assert figures.published == figures.polls, figures
    assert figures.bag_missing == 0, figures
    assert figures.ft_lost == 0 and figures.ft_received > 0, figures
