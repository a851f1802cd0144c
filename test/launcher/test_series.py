"""The paper's three test series on the simulated rig, each from one argument (its program file carries the measuring
arrangement), and a program on one axis with the estimator set to another: never OK.

On simulated time as fast as the rig keeps up: nothing is lost at any load, so the live estimate is the offline fit
of the recorded session exactly. The sessions run back to back on the tests' rig host (conftest.rig_host), as
`campaign run` runs them; the side-force series runs on the rig of processes in test_startup, test_shutdown and the
demo."""
from __future__ import annotations

import pytest

from crane_stiffness.analysis.analyze import analyze_session
from crane_stiffness.launcher import rosrun

pytestmark = pytest.mark.ros  # every test here starts ROS (conftest)

#: program -> (fitted axis, stiffness unit); the prediction is the model's along that axis in that unit.
SERIES = {'side_force': ('fy', 'N/m'), 'force_z': ('fz', 'N/m'), 'moment_z': ('mz', 'N·m/rad')}
SIM_TIME = {'use_sim_time': 'true', 'real_time_factor': 'max'}


@pytest.mark.parametrize('program', ['force_z', 'moment_z'])  # side_force: test_startup, test_shutdown, the demo
def test_each_series_gives_its_prediction_in_its_unit_with_status_ok(colcon_install, rig_host, tmp_path, program):
    share = rosrun.installed_config(colcon_install)
    summary = rig_host.run(share=share, out=tmp_path, program=program, session=program, arguments=SIM_TIME)['summary']
    axis, unit = SERIES[program]
    loading = summary['status']['loading']
    print(program, summary['estimate']['loading']['stiffness'], summary['prediction'], loading)
    assert summary['program']['axis'] == axis and summary['unit'] == unit
    assert abs(summary['relative_error']) < 0.02, summary['estimate']['loading']
    assert summary['prediction']['stiffness'] == pytest.approx(summary['prediction']['eq18'], rel=1e-9)
    # the crane model node's, along the same axis
    assert summary['prediction']['from_node'] == pytest.approx(summary['prediction']['stiffness'], rel=1e-9)
    assert loading['level'] == 'OK' and unit in loading['message'], loading
    assert all(code == 0 for code in summary['node_exit_codes'].values()), summary['node_exit_codes']
    # analyze reads the arrangement from the session: the same axis, unit and estimate.
    result = analyze_session(tmp_path / 'bags' / program, write_files=False, progress=False)
    assert (result.axis, result.unit) == (axis, unit)
    fit = result.branch_fits['loading']
    assert fit.stiffness == pytest.approx(summary['prediction']['stiffness'], rel=0.02)
    assert not [p for p in result.problems if 'fit' in p or 'fitting' in p], result.problems
    assert result.live is not None  # the live estimate, from exactly the samples in the bag: the same numbers
    for branch in ('loading', 'unloading'):
        assert result.live.max_rel_diff[branch] < 1e-9, (branch, result.live)


def test_a_program_on_one_axis_with_the_estimator_on_another_is_never_ok(colcon_install, rig_host, tmp_path):
    """The issue's case: the moment_z program without its arrangement (sensors.yaml's: the estimator fits fy, the
    LVDT along y at the centre sees nothing of a pure Mz)."""
    share = rosrun.installed_config(colcon_install)
    text = (share / 'program_moment_z.yaml').read_text()
    program = tmp_path / 'moment_z_unarranged.yaml'
    program.write_text(text[:text.index('crane_model:')])  # only its load_program section
    summary = rig_host.run(share=share, out=tmp_path, program=str(program), session='mismatch',
                           arguments=SIM_TIME)['summary']
    for part in ('loading', 'unloading', 'input'):
        status = summary['status'][part]
        assert status['level'] in ('WARN', 'ERROR', 'STALE'), (part, status)
        assert 'fitting fy' in status['message'] and 'load mz' in status['message'], (part, status)
    result = analyze_session(tmp_path / 'bags' / 'mismatch', write_files=False, progress=False)
    assert result.axis == 'fy'
    assert any('fitting fy' in p and 'load mz' in p for p in result.problems), result.problems
