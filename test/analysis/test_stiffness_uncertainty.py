"""Each branch's stiffness with its GUM uncertainty and E_n against the model, in the offline analysis
(crane_stiffness.analysis.stiffness_uncertainty): synthetic sessions whose sensors carry known calibration errors.

The truth is linear, k = the lab model's exact tangent along fy (so the model is right and only the sensors are
wrong); the load cell's reading is scaled by (1 + e_F), the LVDT's by (1 + e_x), e_x < 0 and e_F > 0 so that the
errors add. Errors of one declared standard uncertainty each: the expanded interval covers the truth and the
measurement agrees with the model; errors of three times each declared bound: the report says they disagree.

Beside each GUM result stands JCGM 101's Monte Carlo (seeded, reproducible) with the GUM's validation, and a budget
figure; a session far from the model (a displacement gain 10 times too large, a negative gain) is flagged with its
likely causes and ``analyze`` exits EXIT_NOT_OK (the real command line, as a subprocess).
"""
from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import pytest

from crane_stiffness.analysis.analyze import analyze_session
from crane_stiffness.analysis.budget_figure import MAX_BARS, budget_bars
from crane_stiffness.analysis.stiffness_uncertainty import near_power_of_ten
from crane_stiffness.cli.exit_codes import EXIT_NOT_OK, EXIT_OK, EXIT_USAGE
from crane_stiffness.model import axis_stiffness, lab_model, rest_pose, tangent_stiffness
from crane_stiffness.sim.calibration import LOAD_CELL_COMPONENTS, LVDT_COMPONENTS
from crane_stiffness.sim.program import LoadProgram, Segment
from crane_stiffness.testing.synthetic import write_synthetic_session
from crane_stiffness.uncertainty.measurement import SMOOTH_SLOPE_FACTOR
from crane_stiffness.uncertainty.montecarlo import numerical_tolerance
from crane_stiffness.uncertainty.prediction import predict_stiffness

REPO = Path(__file__).resolve().parents[2]

GEOMETRY = lab_model(0.5, 50.0)
K_TRUE = axis_stiffness(tangent_stiffness(GEOMETRY, rest_pose(GEOMETRY)), 'fy')  # 53793.5 N/m
FULL_SCALE, HALF_STROKE, PEAK = 40.0, 2.5e-3, 10.0


def declared(components) -> dict:
    """A node's calibration parameters at their defaults (the sim's data-sheet values)."""
    return {spec.name: spec.default for c in components for spec in c.specs()}


LOAD_CELL = {'full_scale': [FULL_SCALE, FULL_SCALE, 120.0, 2.0, 2.0, 2.0], **declared(LOAD_CELL_COMPONENTS)}
LVDT = {'axis': [0.0, 1.0, 0.0], 'contact_point': [0.0, 0.0, 0.0], 'range_m': [-HALF_STROKE, HALF_STROKE],
        **declared(LVDT_COMPONENTS)}


def program() -> LoadProgram:
    """0 → 2 → … → 10 N and back on fy in 0.4 s ramps and 0.6 s holds."""
    segs = [Segment('hold', 'fy', 0.0, 0.6)]
    for level in (2.0, 4.0, 6.0, 8.0, 10.0, 8.0, 6.0, 4.0, 2.0, 0.0):
        segs += [Segment('ramp', 'fy', level, 0.4), Segment('hold', 'fy', level, 0.6)]
    return LoadProgram(segs, repeats=1, name='steps_to_10N', rate_hz=100.0)


def errors(times: float, bound: bool) -> tuple[float, float]:
    """(e_F, e_x): each declared component's error, at ``times`` its standard uncertainty (or its bound), signed
    to add: the sensitivities and gains as such, the (non)linearities as the slope error they give over the test's
    range (force 0…PEAK, displacement 0…PEAK/K_TRUE)."""
    x_span = PEAK / K_TRUE

    def size(value: float, divisor: float) -> float:
        return times * value / (1.0 if bound else divisor)
    e_f = size(1.0e-2, 2.0) + size(0.2e-2 * min(FULL_SCALE / PEAK, SMOOTH_SLOPE_FACTOR), math.sqrt(3.0))
    e_x = -(size(0.25e-2, 2.0) + size(0.05e-2, math.sqrt(3.0))
            + size(0.25e-2 * min(HALF_STROKE / x_span, SMOOTH_SLOPE_FACTOR), math.sqrt(3.0)))
    return e_f, e_x


def session(path, e_f: float, e_x: float, calibrated: bool = True, gain: float = 1.0):
    """A session of sensors reading (1 + e_F)·F and (1 + e_x)·gain·x."""
    return write_synthetic_session(path, program(), geometry=GEOMETRY, stiffness=K_TRUE / (1.0 + e_x) / gain,
                                   sensor=lambda w: w * (1.0 + e_f), seed=11,
                                   lvdt=LVDT if calibrated else {k: LVDT[k] for k in ('axis', 'contact_point')},
                                   load_cell=LOAD_CELL if calibrated else None)


def test_errors_inside_the_declared_uncertainty_are_covered_and_agree(tmp_path):
    e_f, e_x = errors(1.0, bound=False)
    session(tmp_path / 'inside', e_f, e_x)
    a = analyze_session(tmp_path / 'inside', tmp_path / 'out', formats=('png',), reports=('md',))
    loading = a.uncertainty['loading']
    u = loading['uncertainty']
    assert loading['fit'] == 'hold means' and not loading['statistical_only']
    # the fit sees the sensors' errors: ~3 % above the truth, well outside its own statistical interval ...
    assert u['value'] == pytest.approx(K_TRUE * (1.0 + e_f) / (1.0 + e_x), rel=2e-3)
    assert not loading['ci95'][0] <= K_TRUE <= loading['ci95'][1]
    # ... and inside the expanded one, which counts the calibrations
    assert u['interval'][0] <= K_TRUE <= u['interval'][1]
    names = {row['name'] for row in u['budget']}
    assert {'stiffness_fit', 'load_cell_sensitivity', 'load_cell_nonlinearity', 'load_cell_misalignment',
            'lvdt_sensitivity', 'lvdt_daq_gain', 'lvdt_linearity'} == names
    assert loading['type_a'] == 'hold means' and 1.9 < u['k'] < 2.1
    en = loading['En']
    assert abs(en['en']) <= 1.0 and en['agrees']
    prediction = a.uncertainty['prediction']['uncertainty']
    assert prediction['U'] == pytest.approx(3283.8, rel=2e-3)  # docs/uncertainty.md's lab model along fy
    # E_n's reference U: the GUM interval is not validated by the Monte Carlo (one rectangular input dominates), so
    # the Monte Carlo's interval, the larger distance to its ends (JCGM 101 8.2): about 7 % below the GUM's U
    mc = prediction['monte_carlo']
    assert not mc['validation']['validated'] and en['U_reference_from'].startswith('Monte Carlo')
    far_end = max(prediction['value'] - mc['interval'][0], mc['interval'][1] - prediction['value'])
    assert en['reference'] == pytest.approx(K_TRUE, rel=1e-9) and en['U_reference'] == pytest.approx(far_end)
    assert 0.85 * prediction['U'] < en['U_reference'] < prediction['U']
    md = (tmp_path / 'out' / 'report.md').read_text()
    assert f"loading (hold means): k = {u['value']:.6g} N/m, U = {u['U']:.4g} N/m (k = {u['k']:.2f}, 95 %)" in md
    assert f"E_n = {en['en']:+.2f}: agree" in md
    data = json.loads((tmp_path / 'out' / 'analysis.json').read_text())
    assert data['uncertainty']['loading']['uncertainty']['U'] == u['U']


def test_errors_three_times_the_declared_ones_disagree(tmp_path):
    e_f, e_x = errors(3.0, bound=True)
    session(tmp_path / 'outside', e_f, e_x)
    a = analyze_session(tmp_path / 'outside', tmp_path / 'out', formats=('png',), reports=('md',))
    loading = a.uncertainty['loading']
    u = loading['uncertainty']
    assert u['value'] == pytest.approx(K_TRUE * (1.0 + e_f) / (1.0 + e_x), rel=2e-3)
    assert not u['interval'][0] <= K_TRUE <= u['interval'][1]
    en = loading['En']
    assert en['en'] > 1.0 and not en['agrees']
    assert f"E_n = {en['en']:+.2f}: disagree" in (tmp_path / 'out' / 'report.md').read_text()


def test_a_session_without_declarations_says_statistical_only(tmp_path):
    session(tmp_path / 'bare', 0.0, 0.0, calibrated=False)
    a = analyze_session(tmp_path / 'bare', tmp_path / 'out', formats=('png',), reports=('md',))
    for branch in ('loading', 'unloading'):
        entry = a.uncertainty[branch]
        assert entry['statistical_only'] and entry['calibration'].startswith('statistical only')
        assert [row['name'] for row in entry['uncertainty']['budget']] == ['stiffness_fit']
    assert 'statistical only: no calibration declared' in (tmp_path / 'out' / 'report.md').read_text()


def test_the_uncertainty_file_option_sets_the_prediction_uncertainty(tmp_path, capsys):
    from crane_stiffness.cli.main import main as cli_main
    session(tmp_path / 'inside', *errors(1.0, bound=False))
    wide = tmp_path / 'wide.yaml'  # Young's modulus known to ±10 % instead of ±5 %: the prediction's U nearly doubles
    wide.write_text('crane_uncertainty:\n  ros__parameters:\n    uncertainty:\n'
                    '      youngs_modulus: {half_width: 20.6831e9, distribution: rectangular}\n')
    assert cli_main(['analyze', str(tmp_path / 'inside'), '--out', str(tmp_path / 'o'), '--json',
                     '--uncertainty', str(wide)]) == 0
    data = json.loads(capsys.readouterr().out)
    prediction = data['uncertainty']['prediction']
    assert prediction['uncertainty_file'] == str(wide)
    # docs/uncertainty.md's budget along fy with E's contribution doubled: u_c = √(3100² + 574² + 258² + 87²)
    u_c = math.sqrt((2 * 1550.0) ** 2 + 574.0 ** 2 + 258.0 ** 2 + 87.0 ** 2)
    assert prediction['uncertainty']['U'] == pytest.approx(1.96 * u_c, rel=0.01)
    en = data['uncertainty']['loading']['En']
    assert en['U_reference'] == prediction['U_for_En'] and en['agrees']


def check_monte_carlo(result: dict, width_rel: float = 0.06) -> dict:
    """A result's Monte Carlo as JCGM 101 states it: batches of 10⁴ trials (at least two), settled; its u close to
    the GUM's u_c, its intervals about the value and as wide as 2U to ``width_rel``; the validation's d_low, d_high
    and δ recomputed from both."""
    mc = result['monte_carlo']
    assert mc is not None and mc['converged'] and mc['seed'] == 0 and mc['coverage'] == 0.95
    assert mc['trials'] >= 20_000 and mc['trials'] % 10_000 == 0
    assert mc['u'] == pytest.approx(result['u_c'], rel=0.03)
    for low, high in (mc['interval'], mc['shortest']):
        assert low < result['value'] < high and high - low == pytest.approx(2 * result['U'], rel=width_rel)
    check = mc['validation']
    assert check['delta'] == numerical_tolerance(result['u_c'], 2)
    assert check['d_low'] == pytest.approx(abs(result['interval'][0] - mc['interval'][0]), rel=1e-12, abs=1e-9)
    assert check['d_high'] == pytest.approx(abs(result['interval'][1] - mc['interval'][1]), rel=1e-12, abs=1e-9)
    assert check['validated'] == (check['d_low'] <= check['delta'] and check['d_high'] <= check['delta'])
    return mc


def test_monte_carlo_beside_the_gum_reproducible_and_in_the_report_and_json(tmp_path):
    session(tmp_path / 'inside', *errors(1.0, bound=False))
    a = analyze_session(tmp_path / 'inside', tmp_path / 'out', formats=('png',), reports=('md',))
    md = (tmp_path / 'out' / 'report.md').read_text()
    for branch in ('loading', 'unloading'):
        mc = check_monte_carlo(a.uncertainty[branch]['uncertainty'])
        low, high = mc['interval']
        assert (f"{branch}: Monte Carlo (JCGM 101, {mc['trials']} draws): [{low:.6g}, {high:.6g}] N/m" in md)
        verdict = 'validated' if mc['validation']['validated'] else 'NOT validated'
        assert f"the GUM interval is {verdict} (d_low = {mc['validation']['d_low']:.3g}, d_high = " in md
    # the prediction's: the crane's inputs through the exact tangent, the same draws as predict_stiffness's own
    prediction = a.uncertainty['prediction']
    mc = check_monte_carlo(prediction['uncertainty'], width_rel=0.1)  # flatter than a normal: narrower than 2U
    direct = predict_stiffness(GEOMETRY, 'fy', seed=0).monte_carlo
    assert mc['interval'] == direct['interval'] and mc['trials'] == direct['trials'] == 20_000
    assert not mc['validation']['validated']  # docs/uncertainty.md: one rectangular input dominates (E)
    assert mc['interval'][0] == pytest.approx(50825.4, abs=0.1) and mc['interval'][1] == pytest.approx(56856.3, abs=0.1)
    assert 'model prediction: Monte Carlo (JCGM 101, 20000 draws): [50825.4, 56856.3] N/m' in md
    data = json.loads((tmp_path / 'out' / 'analysis.json').read_text())
    assert data['uncertainty']['loading']['uncertainty']['monte_carlo'] == \
        a.uncertainty['loading']['uncertainty']['monte_carlo']
    # seeded: the same bag gives the same numbers; switched off, the GUM alone (and the same GUM)
    again = analyze_session(tmp_path / 'inside', write_files=False)
    off = analyze_session(tmp_path / 'inside', write_files=False, monte_carlo=False)
    for key in ('loading', 'unloading', 'prediction'):
        assert again.uncertainty[key]['uncertainty'] == a.uncertainty[key]['uncertainty']
        assert off.uncertainty[key]['uncertainty']['monte_carlo'] is None
        assert off.uncertainty[key]['uncertainty']['U'] == a.uncertainty[key]['uncertainty']['U']
    assert off.verdict == a.verdict == {'level': 'OK', 'reasons': []}


def test_the_budget_figure_draws_each_estimates_contributions_largest_first(tmp_path):
    session(tmp_path / 'inside', *errors(1.0, bound=False))
    a = analyze_session(tmp_path / 'inside', tmp_path / 'out', formats=('png', 'svg'), reports=('md',))
    for fmt in ('png', 'svg'):
        assert str(tmp_path / 'out' / f'budget.{fmt}') in a.files
    assert (tmp_path / 'out' / 'budget.png').read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
    svg = (tmp_path / 'out' / 'budget.svg').read_text()
    for name in ('load_cell_sensitivity', 'lvdt_linearity', 'youngs_modulus', 'wire_diameter'):
        assert name in svg
    assert 'budget.png' in (tmp_path / 'out' / 'report.md').read_text()
    for key in ('loading', 'unloading', 'prediction'):
        result = a.uncertainty[key]['uncertainty']
        bars = budget_bars(result)
        values = [v for _, v in bars]
        drawn = values[:-1] if bars[-1][0].endswith('(in quadrature)') else values
        assert drawn == sorted(drawn, reverse=True) and len(bars) <= MAX_BARS
        # every contribution is drawn (the smallest summed in quadrature): together they make u_c (no correlations)
        assert math.sqrt(sum(v * v for v in values)) == pytest.approx(result['u_c'], rel=1e-9)
    assert budget_bars(a.uncertainty['loading']['uncertainty'])[0][0] == 'load_cell_sensitivity'
    assert budget_bars(a.uncertainty['prediction']['uncertainty'])[0][0] == 'youngs_modulus'
    assert budget_bars(a.uncertainty['prediction']['uncertainty'])[-1][0].endswith('others (in quadrature)')


@pytest.mark.parametrize('ratio, decade', [(0.1, -1), (0.0998, -1), (1000.0, 3), (1.0e-3, -3), (12.0, 1),
                                           (0.85, 0), (1.1, 0), (5.0, 0), (30.0, 0), (-0.1, -1)])
def test_near_power_of_ten(ratio, decade):
    assert near_power_of_ten(ratio) == decade


def run_analyze(bag: Path, out: Path, *extra: str) -> subprocess.CompletedProcess:
    """The real command line, as a lab runs it."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(REPO), os.environ.get('PYTHONPATH')])))
    return subprocess.run([sys.executable, '-m', 'crane_stiffness.cli', 'analyze', str(bag), '--out', str(out),
                           '--quiet', *extra], cwd=REPO, env=env, capture_output=True, text=True, timeout=600)


def test_a_displacement_gain_ten_times_too_large_is_flagged_and_analyze_exits_not_ok(tmp_path):
    session(tmp_path / 'gain10', 0.0, 0.0, gain=10.0)
    a = analyze_session(tmp_path / 'gain10', tmp_path / 'out', formats=('png',), reports=('md',))
    assert a.verdict['level'] == 'NOT OK' and len(a.model_disagreements) == 2
    assert a.verdict['reasons'] == a.model_disagreements and set(a.model_disagreements) <= set(a.problems)
    loading = a.uncertainty['loading']
    k, big_u = loading['uncertainty']['value'], loading['uncertainty']['U']
    assert k == pytest.approx(K_TRUE / 10.0, rel=2e-3) and loading['En']['en'] < -1.0
    prediction = a.uncertainty['prediction']['uncertainty']
    line = next(p for p in a.problems if p.startswith('loading far from the model'))
    assert (f"measured k = {k:.6g} ± {big_u:.4g} N/m against the model's {prediction['value']:.6g} ± "
            f"{a.uncertainty['prediction']['U_for_En']:.4g} N/m (U, 95 %), -90.0 %") in line
    assert 'the ratio 0.1 is near 1/10, so the displacement reads about 10 times too large' in line
    # the causes in the order a lab checks them
    order = [line.index(w) for w in ('(1) the displacement gain or units', '(2) the sign or the LVDT',
                                     "(3) the load cell's axis", '(4) the wrong topic', '(5) the crane file')]
    assert order == sorted(order)
    md = (tmp_path / 'out' / 'report.md').read_text()
    assert 'Verdict: NOT OK' in md and line.replace('|', '\\|') in md
    run = run_analyze(tmp_path / 'gain10', tmp_path / 'cli')
    assert run.returncode == EXIT_NOT_OK == 5, run.stderr
    assert 'verdict: NOT OK' in run.stdout and 'near 1/10' in run.stdout
    run = run_analyze(tmp_path / 'gain10', tmp_path / 'cli_json', '--json')
    assert run.returncode == EXIT_NOT_OK and json.loads(run.stdout)['verdict']['level'] == 'NOT OK'


def test_a_negative_displacement_gain_is_flagged_with_the_sign_hint(tmp_path):
    session(tmp_path / 'negative', 0.0, 0.0, gain=-1.0)
    a = analyze_session(tmp_path / 'negative', tmp_path / 'out', formats=('png',), reports=('md',))
    assert a.branch_fits['loading'].stiffness == pytest.approx(-K_TRUE, rel=2e-3)
    hint = ("not positive: not a stiffness: check the sign of displacement_gain, the LVDT's axis parameter and its "
            "mounting direction, then the load cell's axis and frame")
    assert any(p.startswith('loading fit not trusted: slope') and hint in p for p in a.verdict['reasons'])
    far = next(p for p in a.model_disagreements if p.startswith('loading far from the model'))
    assert '-200.0 %' in far and '(the measured slope is negative: look here first)' in far
    assert 'near 1/' not in far
    run = run_analyze(tmp_path / 'negative', tmp_path / 'cli')
    assert run.returncode == EXIT_NOT_OK, run.stderr
    assert hint in run.stdout


def test_an_agreeing_session_exits_ok_from_the_command_line(tmp_path):
    session(tmp_path / 'inside', *errors(1.0, bound=False))
    run = run_analyze(tmp_path / 'inside', tmp_path / 'cli', '--monte-carlo', 'off')
    assert run.returncode == EXIT_OK, run.stderr
    assert 'verdict: OK' in run.stdout and 'Monte Carlo' not in run.stdout


def test_a_campaign_crane_off_nominal_is_flagged_by_analyze_and_stays_ok_in_the_campaign(tmp_path):
    """A campaign simulates cranes off nominal on purpose: its sessions disagree with the nominal model, which is
    the campaign's finding (its tables), not a broken session."""
    from crane_stiffness.campaign.analyze import session_row
    # a crane 12 % stiffer than the nominal one it records (linear truth: the lab crane slackens towards 10 N)
    write_synthetic_session(tmp_path / 'off', program(), geometry=GEOMETRY, stiffness=1.12 * K_TRUE, seed=3,
                            live=True)
    a = analyze_session(tmp_path / 'off', tmp_path / 'out', formats=('png',), reports=('md',))
    assert a.verdict['level'] == 'NOT OK' and a.uncertainty['loading']['En']['en'] > 1.0
    assert a.verdict['reasons'] == a.model_disagreements
    plan = {'id': 'off', 'series': 'side_force', 'weight': 50.0, 'l0': GEOMETRY.l0, 'height': 0.5, 'repeat': 0,
            'nominal': {}, 'true': {'wire_stiffness_factor': 1.12}}
    row = session_row(plan, json.loads((tmp_path / 'out' / 'analysis.json').read_text()), None, tmp_path / 'out')
    assert set(a.model_disagreements) <= set(a.problems)  # the analysis' own report says so ...
    assert row.status == 'OK' and row.reasons == [] == [n for n in a.problems if n not in a.model_disagreements]


@pytest.mark.parametrize('entry, field, words', [
    ('{u: -1.0e9}', 'youngs_modulus.u', 'must be >= 0'),
    ('{u: .nan}', 'youngs_modulus.u', 'must be finite'),
    ('{half_width: 1.0e9, distribution: lognormal}', 'youngs_modulus.distribution', 'unknown distribution'),
    ('{U: 1.0e9, k: 0}', 'youngs_modulus.k', 'coverage factor must be > 0'),
    ('{U: 1.0e9, k: -2}', 'youngs_modulus.k', 'coverage factor must be > 0'),
    ('{u: 1.0e9, correlation: 1.5}', 'youngs_modulus.correlation', 'unknown key'),
])
def test_a_bad_uncertainty_file_is_refused_naming_the_field(tmp_path, capsys, entry, field, words):
    from crane_stiffness.cli.main import main as cli_main
    session(tmp_path / 'inside', *errors(1.0, bound=False))
    bad = tmp_path / 'bad.yaml'
    bad.write_text(f'crane_uncertainty:\n  ros__parameters:\n    uncertainty:\n      youngs_modulus: {entry}\n')
    assert cli_main(['analyze', str(tmp_path / 'inside'), '--out', str(tmp_path / 'o'), '--quiet',
                     '--uncertainty', str(bad)]) == EXIT_USAGE
    err = capsys.readouterr().err
    assert f'crane-stiffness: {field} = ' in err and words in err


def test_compare_states_u_beside_each_k_and_e_n_between_sessions_and_with_the_model(tmp_path):
    from crane_stiffness.analysis.compare import compare_sessions
    session(tmp_path / 'inside', *errors(1.0, bound=False))
    session(tmp_path / 'outside', *errors(3.0, bound=True))
    c = compare_sessions([tmp_path / 'inside', tmp_path / 'outside'], tmp_path / 'cmp', reports=('md',))
    alone = [analyze_session(tmp_path / name, write_files=False) for name in ('inside', 'outside')]
    for row, a in zip(c.rows, alone):
        for branch in ('loading', 'unloading'):
            u = a.uncertainty[branch]['uncertainty']
            assert (row[f'{branch}_measured_k'], row[f'{branch}_U'], row[f'{branch}_coverage_factor']) == \
                (u['value'], u['U'], u['k'])
            assert row[f'{branch}_En_model'] == a.uncertainty[branch]['En']['en']
        assert row['model_U'] == pytest.approx(3283.8, rel=2e-3) and row['model_coverage_factor'] > 1.95
    assert [r['verdict'] for r in c.rows] == ['OK', 'NOT OK']
    assert abs(c.rows[0]['loading_En_model']) <= 1.0 < c.rows[1]['loading_En_model']
    # the two sessions against each other: both measurements' U count
    pairs = {p['branch']: p for p in c.agreement}
    assert set(pairs) == {'loading', 'unloading'}
    for branch, p in pairs.items():
        a, b = c.rows
        assert (p['a'], p['b'], p['k_a'], p['k_b']) == ('inside', 'outside', a[f'{branch}_measured_k'],
                                                       b[f'{branch}_measured_k'])
        assert p['En'] == pytest.approx((p['k_b'] - p['k_a']) / math.hypot(p['U_a'], p['U_b']), rel=1e-12)
    data = json.loads((tmp_path / 'cmp' / 'compare.json').read_text())
    assert data['agreement'][0]['En'] == c.agreement[0]['En'] and data['rows'][1]['loading_U'] == c.rows[1]['loading_U']
    md = (tmp_path / 'cmp' / 'compare.md').read_text()
    r = c.rows[1]
    assert (f"| outside | loading (hold means) | {r['loading_measured_k']:.6g} ± {r['loading_U']:.4g} "
            f"(k = {r['loading_coverage_factor']:.2f}) |") in md
    assert "| inside | outside | loading | " in md and 'Sessions against each other' in md
