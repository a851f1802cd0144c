"""The crane-stiffness command line: JSON contract, readable output, config files, exit codes, sweep output."""
from __future__ import annotations

import argparse
import csv
import json
import subprocess
import sysconfig
from pathlib import Path

import numpy as np
import pytest

from helpers import REPO
from crane_stiffness.cli.main import main
from crane_stiffness.model import lab_model, paper_stiffness, solve_equilibrium, tangent_stiffness

LAB = ['--lab-model', '--height', '0.5', '--weight', '50']


def run_json(capsys, *argv) -> dict:
    assert main(list(argv) + ['--json']) == 0
    return json.loads(capsys.readouterr().out)


def test_solve_json_contract_matches_the_library(capsys):
    res = run_json(capsys, 'solve', *LAB, '--force', '1', '2', '3', '--moment', '0.01', '0', '0.02')
    assert {'converged', 'displacement', 'rotation', 'euler_zxy', 'wire_lengths', 'wire_tensions',
            'slack'} <= set(res)
    eq = solve_equilibrium(lab_model(0.5, 50.0), [1, 2, 3], [0.01, 0, 0.02])
    assert res['converged'] is True
    assert np.allclose(res['displacement'], eq.displacement, atol=0, rtol=0)
    assert np.allclose(res['rotation'], eq.rotation, atol=1e-15)
    assert np.allclose(res['wire_tensions'], eq.wire_tensions, rtol=1e-12)
    assert len(res['slack']) == 6 and not any(res['slack'])


def test_stiffness_json_and_table(capsys):
    res = run_json(capsys, 'stiffness', *LAB, '--force', '0', '2', '0')
    g = lab_model(0.5, 50.0)
    assert np.allclose(res['paper'], paper_stiffness(g), rtol=1e-12)
    assert np.allclose(res['tangent'], tangent_stiffness(g, solve_equilibrium(g, [0, 2, 0])), rtol=1e-12)
    assert main(['stiffness', *LAB]) == 0
    out = capsys.readouterr().out
    assert 'K_j (eq. 19) = 53793.5 N/m' in out and 'u_x' in out


def test_negative_numbers_in_scientific_notation_are_values_not_options(capsys):
    a = run_json(capsys, 'solve', *LAB, '--force', '0', '-1.5e-01', '0', '--moment', '0', '0', '-2E-3')
    b = run_json(capsys, 'solve', *LAB, '--force', '0', '-0.15', '0', '--moment', '0', '0', '-0.002')
    assert a['displacement'] == b['displacement'] and a['displacement'][1] < 0


def test_config_file_and_flag_override(capsys, tmp_path):
    a = run_json(capsys, 'solve', '--config', str(REPO / 'config/crane_lab.yaml'), '--force', '0', '1', '0')
    b = run_json(capsys, 'solve', *LAB, '--force', '0', '1', '0')
    assert a['displacement'] == b['displacement']
    c = run_json(capsys, 'solve', '--config', str(REPO / 'config/crane_lab.yaml'), '--weight', '90',
                 '--force', '0', '1', '0')
    assert c['displacement'][1] < a['displacement'][1]  # heavier: stiffer
    cfg = tmp_path / 'k.yaml'
    cfg.write_text('crane_model:\n  ros__parameters:\n    geometry:\n      a: 0.2\n      b: 0.1\n'
                   '      height: 1.0\n      weight: 20.0\n      wire_stiffness: 5000.0\n')
    d = run_json(capsys, 'stiffness', '--config', str(cfg), '--node', 'crane_model')
    g = lab_model(1.0, 20.0).replace(a=0.2, b=0.1, wire_stiffness=5000.0, wire_diameter=None,
                                     youngs_modulus=None)
    assert np.allclose(d['paper'], paper_stiffness(g), rtol=1e-12)


@pytest.mark.parametrize('argv, code, message', [
    (['solve', *LAB, '--force', '0', '0', '-60'], 3, 'W + fz = 50 + -60'),
    (['solve', '--lab-model', '--height', '-1', '--weight', '5'], 2, 'height = -1.0: must be > 0'),
    (['solve', '--a', '0.1', '--height', '1', '--weight', '5'], 2, '--b is required'),
    (['solve', *LAB, '--wire-stiffness', '-5'], 2, 'wire_stiffness = -5.0: must be > 0'),
    (['solve', '--config', '/nonexistent.yaml'], 2, 'not a file'),
    (['solve', *LAB, '--height', '1', '--l0', '1'], 2, 'not both'),
])
def test_errors_exit_non_zero_with_the_reason_on_stderr(capsys, argv, code, message):
    assert main(argv) == code
    captured = capsys.readouterr()
    assert message in captured.err
    assert captured.out == ''


def test_console_script_is_installed_and_runs(tmp_path):
    exe = Path(sysconfig.get_path('scripts')) / 'crane-stiffness'
    out = subprocess.run([str(exe), 'solve', *LAB, '--force', '0', '0', '-99', '--json'], capture_output=True,
                         text=True, timeout=120)
    assert out.returncode == 3 and 'no equilibrium' in out.stderr and out.stdout == ''


def test_sweep_writes_the_paper_studies(tmp_path, capsys):
    out = tmp_path / 'sweep'
    assert main(['sweep', '--out', str(out), '--heights', '0.5', '1.5', '--weights', '5', '60',
                 '--weight-points', '4', '--points', '9', '--max-force', '2', '--quiet']) == 0
    names = {p.name for p in out.iterdir()}
    for fig in ('fig5', 'fig6', 'fig7', 'fig8', 'fig9'):
        assert f'{fig}_force_displacement.csv' in names and f'{fig}_force_displacement.png' in names
    assert {'fig10_stiffness_fy_vs_weight.png', 'fig13_stiffness_mz_vs_weight.csv'} <= names
    with open(out / 'fig10_stiffness_fy_vs_weight.csv') as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 8
    for r in rows:  # the exact tangent at rest is eq. (18)/(19)
        assert float(r['tangent']) == pytest.approx(float(r['paper_eq18']), rel=1e-8)
    # Fig. 10: stiffness grows with W; longer wires are softer.
    short = [float(r['tangent']) for r in rows if float(r['height_m']) == 0.5]
    long_ = [float(r['tangent']) for r in rows if float(r['height_m']) == 1.5]
    assert short == sorted(short) and all(s > t for s, t in zip(short, long_))
    with open(out / 'fig9_force_displacement.csv') as fh:
        fig9 = list(csv.DictReader(fh))
    assert int(fig9[-1]['slack_wires']) >= 2  # low W, long wires: slack at 2 N
    assert float(fig9[-1]['u_nonlinear_m']) > 1.5 * float(fig9[-1]['u_linear_m'])
    assert (out / 'fig5_force_displacement.png').stat().st_size > 10_000


def _parsers(parser: argparse.ArgumentParser) -> list[tuple[str, argparse.ArgumentParser]]:
    """``parser`` and every subcommand's parser under it, by their command line."""
    found = [(parser.prog, parser)]
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in dict.fromkeys(action.choices.values()):  # an alias maps to the same parser
                found += _parsers(sub)
    return found


def test_every_help_page_of_the_command_line_prints():
    """`crane-stiffness --help` and each subcommand's --help: argparse expands '%' in help strings, so a bare one
    (say '95 % intervals') breaks the page that lists it, not the subcommand's own."""
    from crane_stiffness.cli.main import build_parser
    pages = _parsers(build_parser())
    assert len(pages) > 15, [prog for prog, _ in pages]
    for prog, parser in pages:
        text = parser.format_help()
        assert text.startswith('usage: '), prog
    top = pages[0][1].format_help()
    assert '95 % intervals' in ' '.join(top.split()), top
