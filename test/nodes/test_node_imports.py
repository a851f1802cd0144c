"""What a node process loads at start: only crane_model solves the model, so only it imports numba (the solver's
kernels; ~0.4 s of CPU in each process that imports it). A rig starts eight node processes, a campaign hundreds."""
from __future__ import annotations

import subprocess
import sys

import pytest

from helpers import REPO

#: Every node module of the package but crane_model, which solves the model at start.
WITHOUT_SOLVER = ('load_cell', 'lvdt', 'lvdt_array', 'pose_sensor', 'load_program', 'sim_clock', 'stiffness_estimator',
                  'stiffness6_estimator', 'session_recorder', 'session_player', 'live_view', 'netft', 'modbus_lvdt',
                  'rdt_emulator', 'modbus_emulator')


def test_every_node_module_is_listed():
    modules = {p.stem for p in (REPO / 'crane_stiffness' / 'nodes').glob('*.py')} - {'__init__'}
    assert modules == set(WITHOUT_SOLVER) | {'crane_model'}


@pytest.mark.parametrize('node', WITHOUT_SOLVER)
def test_a_node_that_does_not_solve_the_model_does_not_import_numba(node):
    code = (f'import sys\nimport crane_stiffness.nodes.{node}\n'
            'print(sorted({m.split(".")[0] for m in sys.modules} & {"numba", "llvmlite"}))\n')
    out = subprocess.run([sys.executable, '-c', code], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == '[]', f'crane_stiffness.nodes.{node} imports {out.stdout.strip()}'


def test_crane_model_does_import_it():
    """The check above can fail: the module that solves the model shows numba."""
    code = 'import sys\nimport crane_stiffness.nodes.crane_model\nprint("numba" in sys.modules)\n'
    out = subprocess.run([sys.executable, '-c', code], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == 'True'


#: The nodes that sample, command, keep time, record or drive hardware: none of them needs SciPy at start (its
#: signal package alone cost a sensor process ~2 s of CPU; coloured noise imports it when it filters).
WITHOUT_SCIPY = ('load_cell', 'lvdt', 'lvdt_array', 'pose_sensor', 'load_program', 'sim_clock', 'session_recorder',
                 'session_player', 'netft', 'modbus_lvdt', 'rdt_emulator', 'modbus_emulator')


@pytest.mark.parametrize('node', WITHOUT_SCIPY)
def test_a_node_that_only_samples_or_records_does_not_import_scipy(node):
    code = f'import sys\nimport crane_stiffness.nodes.{node}\nprint("scipy" in sys.modules)\n'
    out = subprocess.run([sys.executable, '-c', code], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == 'False', f'crane_stiffness.nodes.{node} imports scipy'
