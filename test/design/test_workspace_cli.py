"""``crane-stiffness workspace``: pose JSON against the library, margins and maps written and read back by
independent readers (csv, json, matplotlib's PNG reader), a map resumed after an interruption, bad input."""
from __future__ import annotations

import csv
import json
import subprocess
import sys
import sysconfig
from pathlib import Path

import matplotlib.image
import numpy as np
import pytest

from crane_stiffness.analysis.sweep import slack_threshold
from crane_stiffness.cli.main import main
from crane_stiffness.design.pose import at_pose
from crane_stiffness.model import lab_model

LAB = ['--lab-model', '--height', '0.5', '--weight', '50']


def test_pose_json_is_the_librarys(capsys):
    assert main(['workspace', 'pose', *LAB, '--position', '0.01', '-0.02', '0.0001', '--rotation', '0.03', '0',
                 '0.01', '--json']) == 0
    res = json.loads(capsys.readouterr().out)
    report = at_pose(lab_model(0.5, 50.0), (0.01, -0.02, 0.0001), (0.03, 0.0, 0.01))
    assert res['force_stiffness_min_N_per_m'] == pytest.approx(report.split.force_min, rel=1e-12)
    assert res['moment_stiffness_min_Nm_per_rad'] == pytest.approx(report.split.moment_min, rel=1e-12)
    assert list(res['tensions_N'].values()) == pytest.approx(report.equilibrium.wire_tensions.tolist(), rel=1e-12)
    assert res['tension_min_wire'] == f'wire_{int(np.argmin(report.equilibrium.wire_tensions)) + 1}'
    assert np.abs(res['residual']).max() < 1e-9
    assert main(['workspace', 'pose', *LAB]) == 0
    out = capsys.readouterr().out
    assert 'smallest force stiffness  53793.5 N/m' in out and 'smallest tension 8.61874 N' in out


def test_margins_write_csv_json_and_figures(tmp_path, capsys):
    out = tmp_path / 'm'
    assert main(['workspace', 'margins', *LAB, '--directions', '22', '--moment-directions', '13',
                 '--polar-points', '24', '--out', str(out)]) == 0
    printed = capsys.readouterr().out
    summary = json.loads((out / 'margins.json').read_text())
    assert summary['force_+y'] == pytest.approx(slack_threshold(lab_model(0.5, 50.0), 'fy', rtol=1e-8), rel=1e-7)
    assert 'slack margin along +x' in printed
    with (out / 'margins_force.csv').open(newline='') as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 22
    finite = [float(r['margin_N']) for r in rows if r['margin_N'] != 'inf']
    assert min(finite) == pytest.approx(summary['force']['smallest'], rel=1e-12)
    with (out / 'margins_moment_horizontal.csv').open(newline='') as fh:
        assert len(list(csv.DictReader(fh))) == 24
    for name in ('margins_polar.png', 'margins_sphere_force.png', 'margins_sphere_moment.png'):
        img = matplotlib.image.imread(out / name)
        assert img.ndim == 3 and img.shape[0] > 200 and img.std() > 0.05


def _read_csv(path: Path) -> list[list[str]]:
    with path.open(newline='') as fh:
        return list(csv.reader(fh))


def test_map_writes_and_resumes_after_an_interruption(tmp_path, capsys):
    argv = ['workspace', 'map', *LAB, '--grid', 'x', '-0.04', '0.04', '9', '--grid', 'W', '20', '80', '5',
            '--directions', '10', '--usable-load', '1.5', '--quiet']
    full, part = tmp_path / 'full', tmp_path / 'part'
    assert main(argv + ['--out', str(full)]) == 0
    printed = capsys.readouterr().out
    rows = _read_csv(full / 'map.csv')
    assert rows[0][:3] == ['x', 'W', 'status'] and len(rows) == 1 + 9 * 5
    meta = json.loads((full / 'map.json').read_text())
    assert meta['axis1'] == {'name': 'x', 'lo': -0.04, 'hi': 0.04, 'n': 9} and meta['directions'] == 10
    assert 'usable (margin > 1.5 N' in printed
    # The centre column of W = 50 N: the lab model's side stiffness.
    centre = [r for r in rows[1:] if float(r[0]) == 0.0 and float(r[1]) == 50.0]
    assert float(centre[0][3]) == pytest.approx(53793.5, rel=1e-5)
    for name in ('map_force_stiffness.png', 'map_slack_margin.png', 'map_tension.png'):
        assert matplotlib.image.imread(full / name).std() > 0.05
    # Interrupted after three and a half rows of x: the rerun keeps the finished rows and redoes the rest.
    assert main(argv + ['--out', str(part)]) == 0
    capsys.readouterr()
    partial = _read_csv(part / 'map.csv')[:1 + 3 * 5 + 2]
    with (part / 'map.csv').open('w', newline='') as fh:
        csv.writer(fh).writerows(partial)
    stamp = [r[:2] for r in partial]
    assert main(argv + ['--out', str(part)]) == 0
    capsys.readouterr()
    resumed = _read_csv(part / 'map.csv')
    assert [r[:2] for r in resumed[:len(stamp)]] == stamp
    assert resumed == rows
    # Another definition in the same directory is refused (exit 2), unless --fresh.
    other = ['workspace', 'map', *LAB, '--grid', 'x', '-0.04', '0.04', '3', '--grid', 'y', '-0.01', '0.01', '2',
             '--directions', '4', '--quiet', '--out', str(part)]
    assert main(other) == 2
    assert 'holds a map of another definition' in capsys.readouterr().err
    assert main(other + ['--fresh']) == 0
    assert len(_read_csv(part / 'map.csv')) == 1 + 6


@pytest.mark.parametrize('argv, message', [
    (['workspace', 'pose', *LAB, '--position', '0.3', '0', '0'], 'can only pull (tension > 0)'),
    (['workspace', 'pose', '--a', '-0.1', '--b', '0.1', '--height', '1', '--weight', '5', '--wire-stiffness',
      '1e5'], 'a = -0.1: must be > 0 (the platform triangle cannot be inverted)'),
    (['workspace', 'margins', '--lab-model', '--height', '0.5', '--weight', '0'], 'weight = 0.0: must be > 0'),
    (['workspace', 'map', '--lab-model', '--height', '0.5', '--weight', '-3', '--grid', 'x', '0', '1', '2',
      '--grid', 'y', '0', '1', '2'], 'weight = -3.0: must be > 0'),
    (['workspace', 'map', *LAB, '--grid', 'x', '-1', '1', '100000', '--grid', 'y', '-1', '1', '10000'],
     'grid points = 1000000000: must be <= 1,000,000'),
    (['workspace', 'map', *LAB, '--grid', 'W', '-5', '50', '10', '--grid', 'x', '0', '1', '2'],
     'W lo = -5.0: must be > 0'),
    (['workspace', 'map', *LAB, '--grid', 'q', '0', '1', '3', '--grid', 'x', '0', '1', '2'],
     "grid variable = 'q': must be one of"),
])
def test_bad_input_exits_2_with_one_line_naming_the_value_and_rule(capsys, argv, message):
    assert main(argv) == 2
    captured = capsys.readouterr()
    assert message in captured.err and captured.out == ''
    assert len(captured.err.strip().splitlines()) == 1


def test_the_installed_command_runs_workspace(tmp_path):
    exe = Path(sysconfig.get_path('scripts')) / 'crane-stiffness'
    out = subprocess.run([str(exe), 'workspace', 'pose', *LAB, '--position', '0', '0', '-0.4'], capture_output=True,
                         text=True, timeout=300)
    assert out.returncode == 2 and out.stdout == '' and 'pose = ' in out.stderr


def test_workspace_compiles_nothing_at_run_time(tmp_path):
    """The design kernels are compiled into their cache at install time (model/kernel_cache.py) like the model's:
    a fresh process running every workspace command and the parallel batch loads them all from the cache."""
    code = ('import json, sys, numpy as np\n'
            'from crane_stiffness.cli.main import main\n'
            'from crane_stiffness.model import lab_model\n'
            'from crane_stiffness.model.batch import solve_batch_parallel\n'
            'from crane_stiffness.model.kernel_cache import cache_report\n'
            f'out = {str(tmp_path)!r}\n'
            'assert main(["workspace", "pose", "--position", "0.01", "0", "0"]) == 0\n'
            'assert main(["workspace", "margins", "--directions", "5", "--moment-directions", "4", '
            '"--polar-points", "6", "--out", out + "/m"]) == 0\n'
            'assert main(["workspace", "map", "--grid", "b", "0.1", "0.2", "2", "--grid", "com_y", "0", "0.01", '
            '"2", "--directions", "3", "--quiet", "--out", out + "/map"]) == 0\n'
            'solve_batch_parallel(lab_model(0.5, 50.0), np.array([[0, 1.0, 0, 0, 0, 0], [0, 30.0, 0, 0, 0, 0]]))\n'
            'print(json.dumps(cache_report()))\n')
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, timeout=600, cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    report = json.loads(out.stdout.strip().splitlines()[-1])
    assert sum(r['misses'] for r in report.values()) == 0, {k: v for k, v in report.items() if v['misses']}
    assert report['_pose_kernels.map_points']['hits'] >= 1 and report['_batch_kernels.batch_solve_parallel']['hits']
