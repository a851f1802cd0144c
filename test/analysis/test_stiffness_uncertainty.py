"""Each branch's stiffness with its GUM uncertainty and E_n against the model, in the offline analysis
(crane_stiffness.analysis.stiffness_uncertainty): synthetic sessions whose sensors carry known calibration errors.

The truth is linear, k = the lab model's exact tangent along fy (so the model is right and only the sensors are
wrong); the load cell's reading is scaled by (1 + e_F), the LVDT's by (1 + e_x), e_x < 0 and e_F > 0 so that the
errors add. Errors of one declared standard uncertainty each: the expanded interval covers the truth and the
measurement agrees with the model; errors of three times each declared bound: the report says they disagree.
"""
from __future__ import annotations

import json
import math

import pytest

from crane_stiffness.analysis.analyze import analyze_session
from crane_stiffness.model import axis_stiffness, lab_model, rest_pose, tangent_stiffness
from crane_stiffness.sim.calibration import LOAD_CELL_COMPONENTS, LVDT_COMPONENTS
from crane_stiffness.sim.program import LoadProgram, Segment
from crane_stiffness.testing.synthetic import write_synthetic_session
from crane_stiffness.uncertainty.measurement import SMOOTH_SLOPE_FACTOR

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


def session(path, e_f: float, e_x: float, calibrated: bool = True):
    """A session of sensors reading (1 + e_F)·F and (1 + e_x)·x."""
    return write_synthetic_session(path, program(), geometry=GEOMETRY, stiffness=K_TRUE / (1.0 + e_x),
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
    assert en['reference'] == pytest.approx(K_TRUE, rel=1e-9) and en['U_reference'] == prediction['U']
    assert prediction['U'] == pytest.approx(3283.8, rel=2e-3)  # docs/uncertainty.md's lab model along fy
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
    assert en['U_reference'] == prediction['uncertainty']['U'] and en['agrees']
