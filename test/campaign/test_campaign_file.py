"""Campaign files: the paper's campaign expanded into its sessions; a bad file stops `campaign run` with exit 2 and one
stderr line naming the file and the key, before any node starts."""
from __future__ import annotations

import math

import pytest

from helpers import REPO
from crane_stiffness.analysis.sweep import slack_threshold
from crane_stiffness.campaign.errors import CampaignFileError
from crane_stiffness.campaign.spec import CAMPAIGN_PARAMS, load_campaign, plan_sessions, scaled_program_text
from crane_stiffness.cli.main import main
from crane_stiffness.params.files import load_yaml
from crane_stiffness.params.geometry import geometry_from_params

PAPER = REPO / 'config' / 'campaign_paper.yaml'


def test_the_paper_campaign_is_three_series_at_three_weights_and_two_lengths():
    campaign = load_campaign(PAPER)
    plans = plan_sessions(campaign)
    assert len(plans) == 18 and len({p.id for p in plans}) == 18
    assert {(p.series, p.weight, p.l0) for p in plans} == {
        (s, w, l0) for s in ('fy', 'fz', 'mz') for w in (25.0, 50.0, 100.0) for l0 in (0.5, 1.5)}
    for p in plans:
        g = geometry_from_params(p.nominal)
        assert g.l0 == pytest.approx(p.l0, rel=1e-12) and g.weight == p.weight
        assert p.true == p.nominal  # true = nominal in the paper campaign
        if p.series == 'fz':
            assert p.program_scale == 1.0
        else:  # the program's peak at half the load that slackens the nominal crane's first wire
            name = "side_force" if p.series == "fy" else "moment_z"
            text = scaled_program_text(REPO / "config" / f"program_campaign_{name}.yaml",
                                       p.program_scale)
            targets = load_yaml(text)['load_program']['ros__parameters']['segments.target']
            assert max(targets) == pytest.approx(0.5 * slack_threshold(g, p.series), rel=1e-9)


def test_a_true_crane_differs_from_the_nominal_one_in_e_a_and_weight_only():
    soft = plan_sessions(load_campaign(REPO / 'config' / 'campaign_paper_soft.yaml'))
    for p in soft:
        differs = {k for k in p.nominal if p.nominal[k] != p.true[k]}
        assert differs == {'geometry.youngs_modulus', 'geometry.weight'}
        assert p.true['geometry.youngs_modulus'] / p.nominal['geometry.youngs_modulus'] == pytest.approx(0.92)
        assert p.true['geometry.weight'] / p.nominal['geometry.weight'] == pytest.approx(1.02)
        assert geometry_from_params(p.true).k / geometry_from_params(p.nominal).k == pytest.approx(0.92)


def write(tmp_path, body: str):
    path = tmp_path / 'bad_campaign.yaml'
    path.write_text('campaign:\n  ros__parameters:\n' + ''.join(f'    {line}\n' for line in body.splitlines()))
    return path


GOOD = ('series: [fy]\nprograms: [campaign_side_force]\nweights: [50.0]\nlengths: [0.5]\n')


@pytest.mark.parametrize('body, key, rule', [
    (GOOD + 'weight: [50.0]\n', "'weight'", 'unknown key'),
    (GOOD.replace('[50.0]', '[50.0, -5.0]'), 'weights[1]', 'must be >= 0'),
    (GOOD.replace('campaign_side_force', 'no_such_program'), 'programs[0]', 'no program file'),
    (GOOD.replace('[fy]', '[fy, mz]'), 'programs', 'one per series'),
    (GOOD.replace('[fy]', '[fx]'), 'series[0]', 'must be one of fy, fz, mz'),
    (GOOD + 'heights: [0.5]\n', 'lengths', 'exactly one of lengths and heights'),
    (GOOD + 'repeats: 0\n', 'repeats', 'must be'),
    (GOOD + 'true.wire_stiffness_factor: -1.0\n', 'true.wire_stiffness_factor', 'must be > 0'),
    (GOOD.replace('campaign_side_force', 'campaign_moment_z'), 'programs[0]', 'not the series fy'),
    (GOOD + 'true.crane: maybe\n', 'true.crane', 'must be one of nominal, drawn'),
    (GOOD + 'true.crane: drawn\ntrue.uncertainty: no_such_file.yaml\n', 'true.uncertainty', 'not a file'),
    (GOOD + 'sensor_parameters: crane_lab.yaml\n', 'sensor_parameters', 'must be one of load_cell, lvdt'),
])
def test_a_bad_campaign_file_exits_2_naming_the_file_and_the_key(tmp_path, capsys, body, key, rule):
    path = write(tmp_path, body)
    with pytest.raises(CampaignFileError, match=rule):
        load_campaign(path)
    assert main(['campaign', 'run', str(path), '--out', str(tmp_path / 'out')]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(path) in err[0] and key in err[0] and rule in err[0], err
    assert not (tmp_path / 'out').exists()  # stopped before anything ran


def test_every_key_is_declared_once_with_its_unit():
    names = [spec.name for spec in CAMPAIGN_PARAMS]
    assert len(names) == len(set(names))
    assert all(spec.unit for spec in CAMPAIGN_PARAMS), [s.name for s in CAMPAIGN_PARAMS if not s.unit]
    assert all(math.isfinite(w) for w in load_campaign(PAPER).weights)


def test_the_gum_coverage_study_draws_each_session_s_true_crane_and_gives_its_sensors_their_truth_seeds():
    """config/campaign_coverage_gum.yaml: every session a true crane of its own, drawn from config/uncertainty_lab.yaml
    (the same in every planning), and sensors drawing their true errors with their own noise seeds."""
    spec = load_campaign(REPO / 'config' / 'campaign_coverage_gum.yaml')
    plans = plan_sessions(spec)
    assert len(plans) == 200 and spec.true_differs
    assert [p.true for p in plans] == [p.true for p in plan_sessions(spec)]  # seeded by the campaign's seed
    ratio = [p.true['geometry.youngs_modulus'] / p.nominal['geometry.youngs_modulus'] - 1.0 for p in plans]
    assert max(map(abs, ratio)) <= 0.05  # E within its ±5 % rectangular ...
    spread = math.sqrt(sum(r * r for r in ratio) / len(ratio))
    assert spread == pytest.approx(0.05 / math.sqrt(3.0), rel=0.15)  # ... spread as a rectangular one
    weights = [p.true['geometry.weight'] - 50.0 for p in plans]
    assert math.sqrt(sum(w * w for w in weights) / len(weights)) == pytest.approx(0.05, rel=0.15)  # U = 0.1 N, k = 2
    assert len({p.true['geometry.a'] for p in plans}) == 200
    assert all(max(map(abs, p.true['geometry.length_offsets'])) <= 5e-6 for p in plans)
    for p in plans:
        assert p.nominal['geometry.youngs_modulus'] == 206.831e9 and p.nominal['geometry.weight'] == 50.0
        assert p.seeds is not None and p.parameters is not None
        for node in ('load_cell', 'lvdt'):
            assert p.parameters[node]['truth.mode'] == 'drawn'
            assert p.parameters[node]['truth.seed'] == p.seeds[node]
        assert p.parameters['load_cell']['calibration.nonlinearity'] == [0.0] * 6


def test_sensor_parameters_for_a_node_that_is_no_sensor_are_refused_naming_the_section(tmp_path):
    (tmp_path / 'extra.yaml').write_text('lvdt:\n  ros__parameters:\n    truth.mode: drawn\n'
                                         'crane_model:\n  ros__parameters:\n    prediction_axis: fy\n')
    with pytest.raises(CampaignFileError, match="sensor_parameters.*section 'crane_model'"):
        load_campaign(write(tmp_path, GOOD + 'sensor_parameters: extra.yaml\n'))
