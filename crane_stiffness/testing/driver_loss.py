"""The rig on a hardware drivers file (config/drivers_ati_labjack.yaml) over the device emulators, every LVDT
reading counted: for the test that the shipped template loses nothing beside a busy process, and the benchmark of
the loss against the DAQ's poll rate (benchmarks/bench_driver_loss.py).

``transport:=drivers`` with the emulators (rdt_emulator, modbus_emulator: separate processes, as in a lab where the
devices are boxes on the network) and the drivers netft and modbus_lvdt reading the file as a lab copies it, only
pointed at the emulators' loopback ports. A reading is lost when the DAQ driver's timer skips a poll (its process was
busy past the next instant of its grid, counted exactly from the timer's next call time) and the driver could not
take that reading late at its next tick (``missed_polls``; those it took late are ``caught_up_polls``), when a poll
fails, or when the reading does not reach the recorder (the bag's readings within the program against the grid
instants it spans). No wall-clock rate is asserted anywhere: every instant of the grid is accounted for.
"""
from __future__ import annotations

import json
import subprocess
import sys
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Mapping

from crane_stiffness.contract import topics
from crane_stiffness.testing.lab_network import emulated_ports

#: The template a lab copies for an ATI Net F/T and a LabJack.
TEMPLATE = 'drivers_ati_labjack.yaml'


@dataclass(frozen=True)
class LossFigures:
    """What became of every LVDT reading of one run (counts, not rates)."""

    poll_rate_hz: float
    polls: int            # readings the DAQ driver took (successful polls)
    caught_up: int        # grid instants its timer skipped whose readings it took late, at the next tick
    missed_polls: int     # grid instants with no reading taken at all
    failures: int         # polls that got no reading
    published: int        # readings it published
    bag_readings: int     # readings in the bag from the program's first command to its last
    bag_missing: int      # grid instants of that span with no reading in the bag
    ft_received: int      # RDT records netft received
    ft_lost: int          # RDT records lost (from the records' sequence numbers)

    @property
    def skipped_share(self) -> float:
        """Grid instants the driver's timer skipped (caught up or missed), of all it passed over the whole run."""
        return (self.caught_up + self.missed_polls) / max(1, self.polls + self.missed_polls + self.failures)

    @property
    def lost_share(self) -> float:
        """Grid instants of the program's span with no reading in the bag (skipped, failed or not delivered), of
        all in that span: the readings the measurement lacks."""
        return self.bag_missing / max(1, self.bag_readings + self.bag_missing)

    def as_dict(self) -> dict[str, Any]:
        return {**asdict(self), 'skipped_share': self.skipped_share, 'lost_share': self.lost_share}


def busy_process() -> subprocess.Popen:
    """One process that keeps a core busy (the machine of a lab PC doing something else), until killed."""
    return subprocess.Popen([sys.executable, '-c', 'while True:\n    pass'], stdin=subprocess.DEVNULL)


def _final_counters(log: str, node: str) -> dict[str, Any]:
    start = f'FINAL_COUNTERS {node} '
    for line in reversed(log.splitlines()):
        if line.startswith(start):
            return json.loads(line.split(' ', 2)[2])
    raise RuntimeError(f'no FINAL_COUNTERS {node} in its log:\n{log[-2000:]}')


def bag_loss(bag: Path, period_ns: int) -> tuple[int, int]:
    """(readings, grid instants with none) of /lvdt/displacement in ``bag`` from the program's first command to its
    last. A reading is stamped at the middle of its request, within half a period of its instant on a machine that
    keeps up; the count is over the span, so a late stamp moves no reading out of it."""
    import numpy as np

    from crane_stiffness.bag import BagReader
    with BagReader(bag) as reader:
        data = reader.decode_topics([topics.WRENCH_COMMAND, topics.LVDT_DISPLACEMENT])
    commands = data[topics.WRENCH_COMMAND]
    readings = data[topics.LVDT_DISPLACEMENT]
    command_ns = commands['stamp_sec'].astype(np.int64) * 1_000_000_000 + commands['stamp_nanosec']
    stamps = readings['stamp_sec'].astype(np.int64) * 1_000_000_000 + readings['stamp_nanosec']
    inside = np.sort(stamps[(stamps >= command_ns.min()) & (stamps <= command_ns.max())])
    if inside.size == 0:
        return 0, int(round((command_ns.max() - command_ns.min()) / period_ns))
    spanned = int(round((inside[-1] - inside[0]) / period_ns)) + 1
    return int(inside.size), max(0, spanned - int(inside.size))


def run_template_rig(share: Path, env: Mapping[str, str], out: Path, drivers_file: Path | None = None,
                     poll_rate_hz: float | None = None, program: str = 'side_force',
                     busy: bool = True) -> LossFigures:
    """The side-force program on ``drivers_file`` (default: the installed template) over the emulators, beside one
    busy process when ``busy``; ``poll_rate_hz`` overrides the file's. Raises what the rig raises when it fails."""
    from crane_stiffness.launcher.rig import run_rig
    from crane_stiffness.params.files import load_params

    drivers_file = Path(drivers_file or share / TEMPLATE)
    rate = float(poll_rate_hz or load_params(drivers_file, 'modbus_lvdt')['poll_rate_hz'])
    overrides: dict[str, dict[str, Any]] = {name: dict(values) for name, values in emulated_ports().items()}
    # Every node of a launch starts at once: the drivers wait for the emulators as long as a loaded machine needs.
    for driver in ('netft', 'modbus_lvdt'):
        overrides[driver]['wait_for_device_s'] = 120.0
    overrides['modbus_lvdt']['poll_rate_hz'] = rate
    burner = busy_process() if busy else None
    try:
        summary, _, _, logs = run_rig(share, env, out, program, session='template', ready_timeout_s=180.0,
                                      overrides=overrides,
                                      arguments={'transport': 'drivers', 'drivers': str(drivers_file)})
    finally:
        if burner is not None:
            burner.kill()
            burner.wait()
    daq = _final_counters(logs['modbus_lvdt'], 'modbus_lvdt')
    ft = _final_counters(logs['netft'], 'netft')
    if not summary.get('bag'):
        raise RuntimeError(f'no bag recorded: {summary}')
    readings, missing = bag_loss(Path(summary['bag']), round(1e9 / rate))
    return LossFigures(rate, int(daq['received']), int(daq['caught_up_polls']), int(daq['missed_polls']),
                       int(daq['failures']),
                       int(daq['published']), readings, missing, int(ft['received']), int(ft['records_lost']))
