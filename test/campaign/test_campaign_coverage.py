"""The intervals' coverage over a campaign (crane_stiffness.campaign.coverage): the binomial interval against
scipy's own exact interval, and the counts on synthetic campaigns against the campaign rows' own verdicts (the
loading interval against the tangent per one-axis session, the 36 intervals of K per six-axis session)."""
from __future__ import annotations

import csv
from pathlib import Path

import pytest
from scipy.stats import binomtest

from crane_stiffness.campaign.analyze import analyze_campaign
from crane_stiffness.campaign.coverage import binomial_interval
from crane_stiffness.campaign.spec import load_campaign
from crane_stiffness.testing.synthetic_campaign import write_synthetic_campaign


@pytest.mark.parametrize('k,n', [(0, 1), (1, 1), (0, 20), (19, 20), (20, 20), (190, 200), (47, 50), (1, 3)])
def test_the_fraction_s_interval_is_clopper_pearson(k, n):
    expected = binomtest(k, n).proportion_ci(confidence_level=0.95, method='exact')
    low, high = binomial_interval(k, n)
    assert (low, high) == pytest.approx((expected.low, expected.high), abs=1e-12)
    assert low <= k / n <= high


@pytest.mark.parametrize('k,n', [(1, 0), (-1, 5), (6, 5)])
def test_an_impossible_count_is_refused_naming_it(k, n):
    with pytest.raises(ValueError, match=f'k = {k}, n = {n}'):
        binomial_interval(k, n)


def campaign(tmp_path: Path, body: str) -> Path:
    path = tmp_path / 'coverage.yaml'
    path.write_text('campaign:\n  ros__parameters:\n    name: cov\n    weights: [50.0]\n    lengths: [0.5]\n'
                    + ''.join(f'    {line}\n' for line in body.strip().splitlines()))
    return path


def test_one_axis_coverage_counts_each_session_s_loading_and_unloading_interval(tmp_path):
    spec = load_campaign(campaign(tmp_path, 'series: [fy]\nprograms: [campaign_side_force]\nrepeats: 12\nseed: 3'))
    out = tmp_path / 'campaign'
    write_synthetic_campaign(out, spec, seed=40, sample_rate_hz=200)
    result = analyze_campaign(out, workers=2)
    coverage = {c.quantity: c for c in result.coverage}
    assert set(coverage) == {f'k fy {branch}{kind}' for branch in ('loading', 'unloading')
                             for kind in ('', ', repeatability', ', GUM U')} | {'prediction fy, GUM U',
                                                                               'prediction fy, Monte Carlo'}
    assert all(c.total == 12 for c in coverage.values())
    # the rows' own verdict, computed by the campaign analysis from the same session analyses (the true crane is the
    # nominal one here: the truth is the model's tangent)
    rows = result.rows
    assert coverage['k fy loading'].covered == sum(r.ci95_low <= r.model_tangent <= r.ci95_high for r in rows)
    assert coverage['k fy loading, GUM U'].covered == sum(abs(r.k_gum - r.model_tangent) <= r.U for r in rows)
    assert coverage['k fy loading, repeatability'].covered == sum(
        r.repeatability_low <= r.model_tangent <= r.repeatability_high for r in rows)
    # perfect sensors, a budget counting their certificates: every expanded interval holds the truth, and the
    # prediction's interval (about 6 % wide) holds its own nominal crane
    assert coverage['k fy loading, GUM U'].covered == coverage['prediction fy, GUM U'].covered == 12
    assert all(r.agreement == 'agree' and abs(r.en) < 0.1 and r.U > 0 for r in rows)
    with open(out / 'campaign' / 'coverage.csv') as f:
        table = {row['quantity']: row for row in csv.DictReader(f)}
    assert int(table['k fy loading']['covered']) == coverage['k fy loading'].covered
    assert int(table['k fy loading']['sessions']) == 12
    assert (out / 'campaign' / 'coverage.png').stat().st_size > 5000
    report = (out / 'campaign' / 'report.md').read_text()
    assert 'Coverage of the 95 % intervals' in report and 'k fy unloading, GUM U' in report
    assert 'U (k)' in report and 'repeatability (95 %)' in report and ': agree' in report


def test_six_axis_coverage_counts_every_entry_of_k_and_c_and_k2(tmp_path):
    spec = load_campaign(campaign(tmp_path, 'series: [full]\nprograms: [design]\nrepeats: 2\nseed: 5\n'
                                            'design.steps: 16\ndesign.hold_s: 2.0\ndesign.baseline_s: 1.0'))
    out = tmp_path / 'campaign'
    write_synthetic_campaign(out, spec, seed=9)
    result = analyze_campaign(out, workers=2)
    coverage = {c.quantity: c for c in result.coverage}
    k_entries = [q for q in coverage if q.startswith('K[')]
    c_entries = [q for q in coverage if q.startswith('C[')]
    assert len(k_entries) == len(c_entries) == 36 and 'K2' in coverage
    assert 'K[fy,uy]' in coverage and 'C[uy,fy]' in coverage
    assert all(coverage[q].total == 2 for q in [*k_entries, *c_entries, 'K2'])
    # K's entries covered, summed over the entries, equal the sessions' own counts of covering intervals
    assert sum(coverage[q].covered for q in k_entries) == sum(r.covered for r in result.full)
    assert coverage['K2'].covered == sum(r.k2_low <= r.k2_tangent <= r.k2_high for r in result.full)
    # two sessions are no coverage study: the report leaves the table out, the CSV has it
    assert 'Coverage of the 95 % intervals' not in (out / 'campaign' / 'report.md').read_text()
    # K's and C's 72 entries and K2; the same of the expanded (GUM) intervals and K2's statistical-only one; the
    # model's prediction: K's entries ± U and in its Monte Carlo interval, C's ± U, K2 ± U
    assert len((out / 'campaign' / 'coverage.csv').read_text().splitlines()) == 1 + 73 + 74 + 3 * 36 + 1


def test_six_axis_coverage_of_a_drawn_true_crane_is_against_its_tangent_and_counts_the_model_s_prediction(tmp_path):
    import json

    import numpy as np

    from crane_stiffness.full6.reference import k2_of
    from crane_stiffness.model.equilibrium import rest_pose
    from crane_stiffness.model.stiffness import tangent_stiffness
    from crane_stiffness.params.geometry import geometry_from_params
    spec = load_campaign(campaign(tmp_path, 'series: [full]\nprograms: [design]\nrepeats: 3\nseed: 5\n'
                                            'design.steps: 16\ndesign.hold_s: 2.0\ndesign.baseline_s: 1.0\n'
                                            'true.crane: drawn'))
    out = tmp_path / 'campaign'
    write_synthetic_campaign(out, spec, seed=9)
    result = analyze_campaign(out, workers=2)
    coverage = {c.quantity: c for c in result.coverage}
    assert len(result.full) == 3 and all(r.true and r.true != r.nominal for r in result.full)
    # The truth is each session's own drawn crane (recorded as its true_geometry), not the model the analysis ran:
    # counted here from the analyses' intervals and the true cranes' tangents.
    expected: dict[str, int] = {'K': 0, 'U K': 0, 'prediction U K': 0, 'prediction MC K': 0, 'prediction U K2': 0}
    moved = 0.0
    for row in result.full:
        analysis = json.loads((Path(row.analysis) / 'full6.json').read_text())
        g = geometry_from_params(row.true)
        truth = tangent_stiffness(g, rest_pose(g))
        nominal = np.asarray(analysis['reference']['tangent'])
        moved = max(moved, float(np.max(np.abs(truth - nominal)) / np.max(np.abs(nominal))))
        k = analysis['stiffness']
        expected['K'] += int(np.sum((np.asarray(k['low']) <= truth) & (truth <= np.asarray(k['high']))))
        low, high = analysis['uncertainty']['stiffness']['interval']
        expected['U K'] += int(np.sum((np.asarray(low) <= truth) & (truth <= np.asarray(high))))
        p = analysis['uncertainty']['prediction']
        value, big_u = np.asarray(p['stiffness']['value']), np.asarray(p['stiffness']['U'])
        expected['prediction U K'] += int(np.sum(np.abs(truth - value) <= big_u))
        low, high = (np.asarray(m) for m in p['stiffness']['interval'])
        expected['prediction MC K'] += int(np.sum((low <= truth) & (truth <= high)))
        expected['prediction U K2'] += int(abs(k2_of(truth) - p['k2']['value']) <= p['k2']['U'])
    assert moved > 1e-3  # the drawn cranes are not the nominal one
    for prefix, count in expected.items():
        entries = [q for q in coverage if q.startswith(prefix + '[') or q == prefix]
        assert len(entries) == (1 if prefix.endswith('K2') else 36), prefix
        assert all(coverage[q].total == 3 for q in entries), prefix
        assert sum(coverage[q].covered for q in entries) == count, prefix
    lines = (out / 'campaign' / 'coverage_gum_pooled.csv').read_text().splitlines()
    pooled = {line.split(',')[0]: line for line in lines}
    assert pooled['prediction U K (36 pooled)'].split(',')[1:3] == [str(expected['prediction U K']), '108']
