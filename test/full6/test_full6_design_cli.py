"""``crane-stiffness full6 design``: the program it writes loads back and keeps the slack rule, its predicted
precision is printed against the naive program's, and peaks beyond the slack margin are refused naming the wire."""
from __future__ import annotations

import numpy as np
import pytest

from helpers import REPO
from crane_stiffness.cli.main import main as cli_main
from crane_stiffness.full6.admissible import axis_peaks, check_steps
from crane_stiffness.full6.design import d_optimal_design, naive_design
from crane_stiffness.full6.precision import compare_designs
from crane_stiffness.full6.program import held_steps
from crane_stiffness.model import lab_model
from crane_stiffness.params.files import load_params
from crane_stiffness.params.geometry import geometry_from_params
from crane_stiffness.sim.program import load_program_file

CRANE = str(REPO / 'config' / 'crane_lab.yaml')


def test_design_writes_a_program_that_loads_back_and_keeps_the_rule(tmp_path, capsys):
    out = tmp_path / 'program.yaml'
    assert cli_main(['full6', 'design', '--crane', CRANE, '--out', str(out)]) == 0
    printed = capsys.readouterr().out
    program = load_program_file(out)
    steps = np.array([s.wrench for s in held_steps(program)])
    assert steps.shape == (26, 6) and not steps[0].any() and not steps[-1].any()  # 24 steps between baselines
    geometry = lab_model(0.5, 50.0)
    held = check_steps(geometry, steps[1:-1], 2.0)  # raises SlackDesignError on a step or transition
    assert held.factor.min() >= 2.0
    peaks = 0.98 * axis_peaks(geometry, 2.0)
    assert np.all(np.abs(steps) <= peaks + 1e-4)  # the file's loads are rounded to 0.1 mN, 0.1 mN·m
    assert program.duration_s == pytest.approx(100.0)
    # What it printed is the design's predicted precision against the naive program's.
    design = d_optimal_design(geometry, peaks)
    np.testing.assert_allclose(steps[1:-1], np.round(design.steps, 4), atol=1e-12)
    c = compare_designs(design, naive_design(geometry, peaks))
    assert f'geometric mean over the 36 entries: C {c.compliance_mean_ratio:.3f}, K {c.stiffness_mean_ratio:.3f}' \
        in printed
    assert c.stiffness_mean_ratio > 1.3 and c.compliance_mean_ratio > 1.15  # the design is worth it
    line = next(ln for ln in printed.splitlines() if ln.strip().startswith('K2 '))
    assert line.split()[-1] == f'{c.k2_ratio:.3f}' and c.k2_ratio > 1.5
    assert f'D-efficiency {design.efficiency:.3f}' in printed and f'wrote {out}' in printed


def test_design_takes_weight_and_length_flags(tmp_path, capsys):
    out = tmp_path / 'light.yaml'
    assert cli_main(['full6', 'design', '--crane', CRANE, '--weight', '30', '--l0', '1.0', '--steps', '12',
                     '--hold', '3', '--safety-factor', '3', '--out', str(out)]) == 0
    params = {k: v for k, v in load_params(CRANE, None).items() if k != 'geometry.height'}
    geometry = geometry_from_params({**params, 'geometry.weight': 30.0, 'geometry.l0': 1.0})
    assert geometry.l0 == pytest.approx(1.0) and geometry.weight == 30.0
    steps = np.array([s.wrench for s in held_steps(load_program_file(out))])[1:-1]
    assert steps.shape == (12, 6)
    assert check_steps(geometry, steps, 3.0).factor.min() >= 3.0
    printed = capsys.readouterr().out
    assert 'safety factor 3' in printed and 'naive/designed' in printed


@pytest.mark.parametrize('fy, why', [(8.0, 'it would slacken wire_4 (CE)'),
                                     (4.0, 'it comes too close to slack: along its direction wire_4 (CE)')])
def test_peaks_beyond_the_margin_are_refused_naming_the_wire(tmp_path, capsys, fy, why):
    out = tmp_path / 'refused.yaml'
    code = cli_main(['full6', 'design', '--crane', CRANE, '--peaks', '2.8', str(fy), '24', '1.6', '1.4', '0.75',
                     '--out', str(out)])
    err = capsys.readouterr().err
    assert code == 2 and not out.exists()
    assert len(err.strip().splitlines()) == 1
    assert err.startswith('crane-stiffness: full6 design refused: the peak loads')
    assert f'step 3 of 12 (wrench fx +0 N, fy +{fy:g} N' in err and 'direction (fx +0.000, fy +1.000' in err
    assert why in err and 'fy 3.306 N' in err  # and what fy may hold alone


def test_a_finer_pose_sensor_sees_a_smaller_bend_and_the_design_is_scaled_for_it(tmp_path, capsys):
    """With an LVDT array's noise (ten times finer than the tracker's) the lab program's bend is what the
    lack-of-fit test flags (predicted 2.09; the rig measured 2.10): the design is scaled down until it passes."""
    from crane_stiffness.full6.design import NoiseLevels
    from crane_stiffness.full6.linearity import predicted_lack_of_fit, program_steps
    lvdt = ['1.6e-7', '1.6e-7', '1.2e-7', '1.2e-6', '1.2e-6', '9e-7']
    out = tmp_path / 'program.yaml'
    assert cli_main(['full6', 'design', '--crane', CRANE, '--pose-noise', *lvdt, '--out', str(out)]) == 0
    printed = capsys.readouterr().out
    steps = np.array([s.wrench for s in held_steps(load_program_file(out))])
    geometry = lab_model(0.5, 50.0)
    peaks = 0.98 * axis_peaks(geometry, 2.0)
    scale = np.abs(steps).max(axis=0) / peaks
    assert np.all(scale < 0.5) and np.allclose(scale, scale[0], rtol=1e-3)  # every axis scaled alike
    noise = NoiseLevels.from_sensors([0.01, 0.01, 0.01, 5e-4, 5e-4, 5e-4], 1000.0, [float(v) for v in lvdt], 250.0)
    full = d_optimal_design(geometry, peaks, noise=noise)
    assert predicted_lack_of_fit(geometry, *program_steps(full), noise=noise) > 1.8  # as written, it would WARN
    assert 'so that the lack of fit the model predicts is' in printed
