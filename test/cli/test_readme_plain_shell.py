"""Every ``crane-stiffness`` line of the README that needs no ROS runs from a plain shell: the venv's console script
(``.venv/bin/crane-stiffness``, as the README says after ``make demo``) with nothing sourced (no AMENT_PREFIX_PATH,
no ROS_* variable, no PYTHONPATH), from a directory laid out as the repository root (its ``config/``), each line as
the README prints it but for what names a user's data: ``bags/<session>`` is a session bag this test writes, the
campaign directory a synthetic campaign, the workspace map's grid coarser. A line fails on a non-zero exit or a
traceback on stderr. ``campaign run`` starts the rig (ROS) and is the one line left out."""
from __future__ import annotations

import os
import re
import shlex
import subprocess
import sysconfig
from pathlib import Path

import pytest

from crane_stiffness.campaign.spec import load_campaign
from crane_stiffness.model.geometry import lab_model
from crane_stiffness.sim.program import LoadProgram, Segment
from crane_stiffness.testing.synthetic import write_synthetic_session
from crane_stiffness.testing.synthetic_campaign import write_synthetic_campaign
from helpers import REPO

#: README lines that need ROS (they start the rig): not run here.
NEEDS_ROS = ('crane-stiffness campaign run ',)


def readme_lines() -> list[str]:
    """The ``crane-stiffness …`` commands of the README's shell blocks, comments dropped, ``a && b`` split."""
    text = (REPO / 'README.md').read_text()
    lines = []
    for block in re.findall(r'```sh\n(.*?)```', text, re.S):
        for line in block.splitlines():
            for part in line.split('#', 1)[0].split('&&'):
                part = part.strip()
                if part.startswith('crane-stiffness '):
                    lines.append(part)
    return lines


def plain_environment() -> dict[str, str]:
    """This process's environment without anything ROS or Python path: a shell where nothing was sourced."""
    return {k: v for k, v in os.environ.items()
            if not (k.startswith(('ROS_', 'AMENT_', 'COLCON_', 'RMW_', 'PYTHON')) or k in ('LD_LIBRARY_PATH',
                                                                                               'CMAKE_PREFIX_PATH'))}


def _program() -> LoadProgram:
    segs = [Segment('hold', 'fy', 0.0, 0.4)]
    for level in (1.0, 2.0, 1.0, 0.0):
        segs += [Segment('ramp', 'fy', level, 0.3), Segment('hold', 'fy', level, 0.4)]
    return LoadProgram(segs, repeats=1, name='readme_steps', rate_hz=100.0)


#: The README lines this test runs, in the README's order.
RUNNABLE = [line for line in readme_lines() if not line.startswith(NEEDS_ROS)]


class Shell:
    """A plain shell in ``root``, running README lines the way a reader does: in order, each once."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self.done: dict[str, subprocess.CompletedProcess] = {}

    def run(self, line: str) -> subprocess.CompletedProcess:
        """``line``'s outcome, after every README line above it has run here (``calibrate out/paper`` reads what
        ``campaign analyze out/paper`` wrote; test processes side by side may each get some of the lines)."""
        for earlier in RUNNABLE[:RUNNABLE.index(line) + 1]:
            if earlier not in self.done:
                self.done[earlier] = self._exec(earlier)
        return self.done[line]

    def _exec(self, line: str) -> subprocess.CompletedProcess:
        exe = Path(sysconfig.get_path('scripts')) / 'crane-stiffness'
        argv = [str(exe), *shlex.split(_substituted(line))[1:]]
        return subprocess.run(argv, cwd=self.root, env=plain_environment(), capture_output=True, text=True,
                              timeout=600)


@pytest.fixture(scope='module')
def shell(tmp_path_factory) -> Shell:
    """A directory like the repository root: ``config/`` (a link to the repository's), two session bags under
    ``bags/`` and a synthetic campaign."""
    root = tmp_path_factory.mktemp('plain_shell')
    (root / 'config').symlink_to(REPO / 'config')
    for name, seed in (('a', 1), ('b', 2)):  # linear truth: the lab model's tangent along fy (analyze's verdict OK)
        write_synthetic_session(root / 'bags' / name, _program(), geometry=lab_model(0.5, 50.0), stiffness=53_793.5,
                                seed=seed)
    spec = root / 'campaign.yaml'
    spec.write_text('campaign:\n  ros__parameters:\n    name: readme\n    series: [fy, fz, mz]\n'
                    '    programs: [campaign_side_force, campaign_force_z, campaign_moment_z]\n'
                    '    weights: [50.0]\n    lengths: [0.5]\n')
    write_synthetic_campaign(root / 'out' / 'paper', load_campaign(spec), seed=5, sample_rate_hz=200)
    return Shell(root)


def _substituted(line: str) -> str:
    line = line.replace('bags/<session>', 'bags/a').replace('bags/<a>', 'bags/a').replace('bags/<b>', 'bags/b')
    return re.sub(r'(--grid \S+ \S+ \S+) 100', r'\1 8', line)  # the map's grid: 8 × 8 points, not 100 × 100


def test_the_readme_names_the_no_ros_commands():
    lines = readme_lines()
    commands = {' '.join(shlex.split(line)[1:3]) for line in lines}
    # the tour's lines: a command the README adds is run below as it is (or named in NEEDS_ROS)
    assert {'analyze bags/<session>', 'full6 design', 'compare bags/<a>', 'stiffness --config', 'sweep --out',
            'workspace map', 'campaign run', 'campaign analyze', 'calibrate out/paper'} <= commands, commands


@pytest.mark.parametrize('line', RUNNABLE)
def test_a_readme_line_runs_from_a_plain_shell(line, shell):
    out = shell.run(line)
    assert 'Traceback' not in out.stderr, f'{line}:\n{out.stderr[-4000:]}'
    assert out.returncode == 0, f'{line}: exit {out.returncode}\n{out.stderr[-4000:]}'
