"""The campaign series `full`: the whole 6x6 stiffness of every set-up from one designed test each. The campaign file
designs each set-up's program within its own slack margins (or checks a given six-axis program against them and
refuses it naming the set-up, step and wire); `campaign analyze` gives every session's K against the tangent and
the figures; `calibrate` recovers the true crane's E·A and W from the measured compliances (synthetic campaigns:
crane_stiffness.testing.synthetic_campaign); on the rig the campaign's live 6x6 equals the offline fit."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from crane_stiffness.campaign.analyze import analyze_campaign
from crane_stiffness.campaign.calibrate import calibrate_campaign
from crane_stiffness.campaign.errors import CampaignFileError
from crane_stiffness.campaign.spec import load_campaign, plan_sessions
from crane_stiffness.cli.main import main
from crane_stiffness.full6.admissible import axis_peaks, check_steps
from crane_stiffness.full6.program import held_steps
from crane_stiffness.full6.reference import reference_at_rest
from crane_stiffness.params.files import load_yaml
from crane_stiffness.params.geometry import geometry_from_params
from crane_stiffness.sim.program import LoadProgram
from crane_stiffness.testing.synthetic_campaign import write_synthetic_campaign

CLI = Path(sys.prefix) / 'bin' / 'crane-stiffness'


def campaign(tmp_path: Path, body: str, name: str = 'full') -> Path:
    path = tmp_path / f'{name}.yaml'
    path.write_text(f'campaign:\n  ros__parameters:\n    name: {name}\n    series: [full]\n'
                    + ''.join(f'    {line}\n' for line in body.strip().splitlines()))
    return path


def program_of(text: str) -> tuple[LoadProgram, dict]:
    data = load_yaml(text)
    return LoadProgram.from_params(data['load_program']['ros__parameters']), data


def test_each_set_up_gets_its_own_design_inside_its_own_slack_margins(tmp_path):
    plans = plan_sessions(load_campaign(campaign(tmp_path, 'programs: [design]\nweights: [25.0, 100.0]\n'
                                                          'lengths: [0.5, 1.5]\ndesign.steps: 16\n')))
    assert [p.id for p in plans] == ['full_W25_l0.5_r1', 'full_W100_l0.5_r1', 'full_W25_l1.5_r1',
                                     'full_W100_l1.5_r1']
    peaks = []
    for p in plans:
        program, data = program_of(p.program_text)
        assert 'stiffness6_estimator' in data  # the rig measures the 6x6 for it
        steps = np.array([h.wrench for h in held_steps(program)])
        assert len(steps) == 16 + 2  # the designed steps between two zero baselines
        g = geometry_from_params(p.nominal)
        assert check_steps(g, steps, 2.0).factor.min() >= 2.0  # every step keeps the safety factor
        assert np.all(np.abs(steps).max(axis=0) <= 0.98 * axis_peaks(g, 2.0) * (1 + 1e-4))
        peaks.append(np.abs(steps).max(axis=0))
    assert np.all(peaks[1] > 2.0 * peaks[0])  # four times the weight, larger margins, larger loads
    # Every simulated sensor of the campaign has its own seed.
    seeds = [s for p in plans for s in p.seeds.values()]
    assert len(seeds) == len(set(seeds)) == 12 and all(set(p.seeds) == {'load_cell', 'lvdt', 'pose_sensor'}
                                                        for p in plans)


def test_a_six_axis_program_that_would_slacken_a_wire_at_one_set_up_is_refused_naming_it(tmp_path, capsys):
    # program_full6 is designed for the lab model (W = 50 N, h = 0.5 m): at W = 25 N its loads exceed half the
    # margins.
    path = campaign(tmp_path, 'programs: [full6]\nweights: [50.0, 25.0]\nheights: [0.5]\n')
    with pytest.raises(CampaignFileError) as err:
        plan_sessions(load_campaign(path))
    message = str(err.value)
    assert 'W = 25 N, h = 0.5 m' in message and 'program_full6.yaml refused' in message
    assert 'step' in message and 'wire_' in message, message
    assert main(['campaign', 'run', str(path), '--out', str(tmp_path / 'out')]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and 'W = 25 N' in lines[0] and 'wire_' in lines[0], lines
    assert not (tmp_path / 'out').exists()  # nothing ran
    # The same program at its own set-up is accepted, as written.
    plans = plan_sessions(load_campaign(campaign(tmp_path, 'programs: [full6]\nweights: [50.0]\nheights: [0.5]\n',
                                                 'own')))
    assert plans[0].program_text is None and plans[0].program.endswith('program_full6.yaml')


@pytest.mark.parametrize('body, rule', [
    ('programs: [campaign_side_force]\nweights: [50.0]\nlengths: [0.5]\n', 'not a six-axis program'),
    ('programs: [design]\nweights: [50.0]\nlengths: [0.5]\ndesign.steps: 17\n', 'design.steps = 17: must be even'),
    ('programs: [design]\nweights: [50.0]\nlengths: [0.5]\ndesign.steps: 12\n', 'design.steps = 12: must be'),
    ('programs: [design]\nweights: [50.0]\nlengths: [0.5]\ndesign.settle_s: 5.0\n', 'shorter than design.hold_s'),
])
def test_a_bad_full_series_is_refused_naming_the_key(tmp_path, body, rule):
    with pytest.raises(CampaignFileError, match=rule):
        load_campaign(campaign(tmp_path, body))


def test_analyze_and_calibrate_recover_the_true_crane_from_the_6x6_of_four_set_ups(tmp_path):
    """The true crane's wires 8 % softer and its weight 10 % heavier than the nominal model the sessions record."""
    spec = load_campaign(campaign(tmp_path, 'programs: [design]\nweights: [25.0, 100.0]\nlengths: [0.5, 1.5]\n'
                                            'design.steps: 16\ndesign.hold_s: 2.0\ndesign.baseline_s: 1.0\n'
                                            'true.wire_stiffness_factor: 0.92\ntrue.weight_factor: 1.1\n'))
    out = tmp_path / 'campaign'
    write_synthetic_campaign(out, spec, seed=5)
    result = analyze_campaign(out, workers=2)
    assert result.rows == [] and len(result.full) == 4 and sorted(result.analysed) == sorted(
        r.session for r in result.full)
    for row in result.full:
        assert row.ok, (row.session, row.reasons)
        assert row.live_difference <= 1e-6
        assert row.k2 * row.k2_tangent > 0
        true = reference_at_rest(geometry_from_params(row.true)).tangent
        for i, d in enumerate(row.diagonal):  # the true crane measured, within 4 σ of its interval
            assert d['tangent'] == pytest.approx(reference_at_rest(geometry_from_params(row.nominal)).tangent[i, i])
            assert abs(d['measured'] - true[i, i]) < 4 * (d['high'] - d['low']) / 3.92, (row.session, d)
    table = (out / 'campaign' / 'full.csv').read_text().splitlines()
    assert len(table) == 5 and table[0].startswith('session,weight,l0,height,repeat,status,pairs,K_fx')
    for name in ('full_stiffness_diagonal.png', 'full_coupling_k2.png', 'report.md', 'report.html'):
        assert (out / 'campaign' / name).stat().st_size > 1000, name
    assert 'The whole 6x6 stiffness (series full)' in (out / 'campaign' / 'report.md').read_text()
    assert analyze_campaign(out, workers=1).analysed == []  # unchanged: not analysed again

    cal, files = calibrate_campaign(out, weight='scale')
    k, w = cal.parameter('k'), cal.parameter('W')
    assert k.value == pytest.approx(0.92, rel=0.005) and k.ci95_low < 0.92 < k.ci95_high, k
    assert w.ci95_low < 1.1 < w.ci95_high and w.stderr < 0.03, w  # W only through the pendulum terms: looser
    assert cal.chi2 / cal.dof < 2.0
    assert {Path(f).name for f in files} >= {'full_stiffness_diagonal_calibrated.png',
                                             'full_coupling_k2_calibrated.png', 'calibration.json'}
    saved = json.loads((out / 'calibration' / 'calibration.json').read_text())
    assert len(saved['sessions_used']) == 4 and saved['sessions_left_out'] == []


@pytest.mark.ros
def test_on_the_rig_the_campaign_s_live_6x6_equals_the_offline_fit_of_its_bag(tmp_path):
    path = campaign(tmp_path, 'programs: [design]\nweights: [50.0]\nlengths: [0.5]\ndesign.steps: 16\n'
                              'design.hold_s: 2.0\ndesign.baseline_s: 1.0\n', 'rig')
    out = tmp_path / 'out'
    run = subprocess.run([str(CLI), 'campaign', 'run', str(path), '--out', str(out), '--quiet'], capture_output=True,
                         text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-3000:]
    result = json.loads((out / 'sessions' / 'full_W50_l0.5_r1' / 'result.json').read_text())
    assert result['status6']['level'] == 'OK', result['status6']
    assert (out / 'sessions' / 'full_W50_l0.5_r1' / 'program.yaml').read_text() == plan_sessions(
        load_campaign(path))[0].program_text
    analysed = analyze_campaign(out, workers=1)
    row = analysed.full[0]
    assert row.ok, row.reasons
    assert row.live_difference <= 1e-6  # the live fit's last K is the bag's offline fit
    assert row.pairs > 1000 and row.k2 * row.k2_tangent > 0
    assert max(abs(d['relative_error']) for d in row.diagonal) < 0.03
