"""The whole 6x6 stiffness on the simulated rig, end to end: program:=full6 on simulated time starts the pose sensor
and the live 6x6 fit beside the rig; the live K is the exact tangent's within the issue's bounds (status OK, every
diagonal entry within 1 %, K2 within 3 % with its sign), and `crane-stiffness analyze` of the session's bag gives the
same matrix and intervals as the live fit; the live U of every entry of K and of K2 (recorded on
/stiffness6/stiffness_expanded and in the status) is the offline law of propagation's, from the calibrations the
sensor nodes declare (read live over ROS, offline from the recorded parameters)."""
from __future__ import annotations

import numpy as np
import pytest

from rclpy.serialization import deserialize_message
from std_msgs.msg import Float64MultiArray

from crane_stiffness.analysis.full6 import analyze_full6
from crane_stiffness.bag import BagReader
from crane_stiffness.contract import topics
from crane_stiffness.launcher import rosrun
from crane_stiffness.launcher.rig import config_files
from crane_stiffness.contract import stiffness6_layout
from crane_stiffness.launcher.summary6 import summarize6, verdict6

pytestmark = pytest.mark.ros
SEEDS = {'load_cell': {'seed': 21}, 'lvdt': {'seed': 22}, 'pose_sensor': {'seed': 23}}


def test_program_full6_measures_the_whole_matrix_live_and_the_bag_gives_it_again(colcon_install, rig_host, tmp_path):
    """On the rig host (the rig of processes runs it in scripts/demo.py --program full6)."""
    share = rosrun.installed_config(colcon_install)
    run = rig_host.run(share=share, out=tmp_path, program='full6', session='s6', overrides=SEEDS,
                       arguments={'use_sim_time': 'true', 'real_time_factor': 'max'})
    codes = run['summary']['node_exit_codes']
    assert {'stiffness6_estimator', 'pose_sensor'} <= set(codes) and set(codes.values()) == {0}, codes
    summary = summarize6(config_files(share, 'full6')['crane'], run['stiffness6'], run['status6'])
    assert verdict6(summary) == '', (verdict6(summary), summary['status'])
    assert summary['status']['level'] == 'OK'
    assert all(abs(d['relative_error']) < 0.01 for d in summary['diagonal'].values()), summary['diagonal']
    assert summary['k2']['same_sign'] and abs(summary['k2']['relative_error']) < 0.03
    # the same fit from the bag: the pairs the live estimator fitted, to rounding
    offline = analyze_full6(tmp_path / 'bags' / 's6', tmp_path / 'analysis')
    live_k, live_low, live_high = stiffness6_layout.decode(run['stiffness6'])
    off = offline.stiffness
    np.testing.assert_allclose(np.array(off['value']), live_k, rtol=1e-9, atol=1e-9 * np.abs(live_k).max())
    np.testing.assert_allclose(np.array(off['low']), live_low, rtol=1e-9, atol=1e-9 * np.abs(live_k).max())
    np.testing.assert_allclose(np.array(off['high']), live_high, rtol=1e-9, atol=1e-9 * np.abs(live_k).max())
    assert offline.pairs['n'] == int(run['status6'][2]['pairs'])
    assert (tmp_path / 'analysis' / 'full6_stiffness.png').stat().st_size > 10_000
    # U: the live one (the last K ∓ U recorded: of the same fit as the last K) is the offline law of propagation's
    with BagReader(tmp_path / 'bags' / 's6') as reader:
        last = [m.data for m in reader.messages([topics.STIFFNESS6_EXPANDED])][-1]
    cube = stiffness6_layout.decode_message(deserialize_message(last, Float64MultiArray))
    np.testing.assert_array_equal(cube[0], live_k)
    gum = offline.matrix_uncertainty
    assert gum is not None and not gum.statistical_only
    np.testing.assert_allclose(cube[2] - cube[0], gum.stiffness.U, rtol=1e-6)
    np.testing.assert_allclose(cube[0] - cube[1], gum.stiffness.U, rtol=1e-6)
    values = run['status6'][2]
    assert float(values['k2_U']) == pytest.approx(float(gum.k2.U), rel=1e-6)
    assert values['statistical_only'] == 'false' and values['uncertainty'] == gum.calibration.statement
