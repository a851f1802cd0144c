"""The measured stiffness's GUM uncertainty and E_n on the simulated rig (the real nodes, on the tests' rig host, on
simulated time, recorded and analysed from the bag): the load cell and the LVDT given true calibration errors
(``truth.mode: given``), the simulated crane the nominal one, so the truth is the model's exact tangent.

Errors of one declared standard uncertainty each, signed to add (the load cell reads 0.5 % high on fy; the LVDT
0.125 % low and a linearity error of +0.25/√3 % of its half stroke, which near rest lowers its slope by 3× that):
the expanded interval covers the true stiffness, the statistical one does not, and |E_n| <= 1. Errors three times
each declared bound: the report says the measurement and the model disagree.

The model's prediction has the uncertainty of a lab that measured its wire's modulus to ±1 % (an uncertainty file of
the test's): with the handbook's ±5 % (config/uncertainty_lab.yaml) the prediction's U is 6 % of k, about as large
as the errors three times the bounds the rig can simulate (6.3 %: the load cell's nonlinearity and the DAQ's gain
have no simulated error), so E_n would sit at 1.0 and decide nothing."""
from __future__ import annotations

import math

import pytest

from crane_stiffness.analysis.analyze import analyze_session
from crane_stiffness.bag import BagReader
from crane_stiffness.bag.session_metadata import read_node_parameters
from crane_stiffness.launcher import rosrun
from crane_stiffness.model import axis_stiffness, lab_model, rest_pose, tangent_stiffness
from crane_stiffness.sim.truth import load_cell_truth, lvdt_truth

pytestmark = pytest.mark.ros  # the rig's nodes on the tests' rig host

SIM_TIME = {'use_sim_time': 'true', 'real_time_factor': 'max'}
#: The rig's default crane (config/crane_lab.yaml at the campaign program's set-up: W = 50 N, h = 0.5 m).
K_TRUE = axis_stiffness(tangent_stiffness(lab_model(0.5, 50.0), rest_pose(lab_model(0.5, 50.0))), 'fy')
#: config/sensors.yaml's declarations: load cell sensitivity U = 1 % (k = 2); LVDT sensitivity U = 0.25 % (k = 2),
#: DAQ gain ±0.05 %, linearity ±0.25 % of the half stroke (rectangular) [%].
LC_SENSITIVITY_U, LVDT_SENSITIVITY_U, DAQ_GAIN, LINEARITY = 1.0, 0.25, 0.05, 0.25


def run(rig_host, colcon_install, tmp_path, name: str, load_cell: float, lvdt: float, linearity: float):
    """A session of program_campaign_side_force (0 → 3 N → 0 along fy, 5.3 s) with the given true errors [%]."""
    share = rosrun.installed_config(colcon_install)
    overrides = {'load_cell': {'truth.mode': 'given', 'truth.sensitivity': [0.0, load_cell, 0.0, 0.0, 0.0, 0.0],
                               'seed': 11},
                 'lvdt': {'truth.mode': 'given', 'truth.sensitivity': lvdt, 'truth.linearity': linearity,
                          'seed': 12}}
    summary = rig_host.run(share=share, out=tmp_path, program='campaign_side_force', session=name,
                           arguments=SIM_TIME, overrides=overrides)['summary']
    assert all(code == 0 for code in summary['node_exit_codes'].values()), summary['node_exit_codes']
    bag = tmp_path / 'bags' / name
    reader = BagReader(bag)
    try:
        nodes = read_node_parameters(reader)
    finally:
        reader.close()
    # the truth is recorded with the session (the nodes' parameters), for studies; the analysis does not read it
    assert load_cell_truth(nodes['load_cell']).sensitivity[1] == pytest.approx(load_cell / 100)
    assert (lvdt_truth(nodes['lvdt']).sensitivity, lvdt_truth(nodes['lvdt']).linearity) == pytest.approx(
        (lvdt / 100, linearity / 100))
    lab = tmp_path / 'modulus_measured.yaml'
    lab.write_text('crane_uncertainty:\n  ros__parameters:\n    uncertainty:\n'
                   '      youngs_modulus: {half_width: 2.06831e9, distribution: rectangular}\n')
    return analyze_session(bag, tmp_path / 'analysis' / name, reports=('md',), uncertainty_file=lab)


def test_errors_inside_the_declared_uncertainty_are_covered_and_agree_on_the_rig(rig_host, colcon_install, tmp_path):
    u_linearity = LINEARITY / math.sqrt(3.0)
    a = run(rig_host, colcon_install, tmp_path, 'inside', LC_SENSITIVITY_U / 2, -LVDT_SENSITIVITY_U / 2,
            u_linearity)
    expected = K_TRUE * (1 + LC_SENSITIVITY_U / 200) / (1 - LVDT_SENSITIVITY_U / 200 - 3 * u_linearity / 100)
    for branch in ('loading', 'unloading'):
        entry = a.uncertainty[branch]
        u = entry['uncertainty']
        print(branch, u['value'], u['U'], u['interval'], entry['ci95'], entry['En'], K_TRUE)
        assert entry['fit'] == 'hold means' and not entry['statistical_only']
        # the sensors' errors move the fit 1.1 % above the truth, far outside its statistical interval ...
        assert u['value'] == pytest.approx(expected, rel=2e-3)
        assert not entry['ci95'][0] <= K_TRUE <= entry['ci95'][1]
        # ... and inside the expanded one, which counts the declared calibrations
        assert u['interval'][0] <= K_TRUE <= u['interval'][1]
        assert {row['name'] for row in u['budget']} == {
            'stiffness_fit', 'load_cell_sensitivity', 'load_cell_nonlinearity', 'load_cell_misalignment',
            'lvdt_sensitivity', 'lvdt_daq_gain', 'lvdt_linearity'}
        en = entry['En']
        assert en['reference'] == pytest.approx(K_TRUE, rel=1e-9)
        assert abs(en['en']) <= 1.0 and en['agrees'], en
    report = (tmp_path / 'analysis' / 'inside' / 'report.md').read_text()
    assert f"E_n = {a.uncertainty['loading']['En']['en']:+.2f}: agree" in report


def test_errors_three_times_the_declared_bounds_disagree_on_the_rig(rig_host, colcon_install, tmp_path):
    a = run(rig_host, colcon_install, tmp_path, 'outside', 3 * LC_SENSITIVITY_U,
            -3 * (LVDT_SENSITIVITY_U + DAQ_GAIN), 3 * LINEARITY)
    report = (tmp_path / 'analysis' / 'outside' / 'report.md').read_text()
    for branch in ('loading', 'unloading'):
        entry = a.uncertainty[branch]
        u = entry['uncertainty']
        print(branch, u['value'], u['U'], u['interval'], entry['En'], K_TRUE)
        assert u['value'] == pytest.approx(K_TRUE * 1.03 / (1 - 0.009 - 0.0225), rel=2e-3)  # 6.4 % high
        assert not u['interval'][0] <= K_TRUE <= u['interval'][1]
        en = entry['En']
        assert en['en'] > 1.0 and not en['agrees'], en
        assert f"{branch} (hold means): k = {u['value']:.6g} N/m" in report
        assert f"E_n = {en['en']:+.2f}: disagree" in report
