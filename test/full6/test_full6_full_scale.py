"""A load cell at its full scale in the 6x6 measurement (crane_stiffness.full6.full_scale): its samples are left out,
live and offline alike, and the status is never OK after one; without the rule the clipped samples bend K."""
from __future__ import annotations

import numpy as np
import pytest

from crane_stiffness.analysis.full6 import analyze_full6
from crane_stiffness.full6.design import d_optimal_design
from crane_stiffness.full6.full_scale import at_full_scale, check_full_scale, with_full_scale
from crane_stiffness.full6.errors import Full6InputError
from crane_stiffness.full6.identify import identify
from crane_stiffness.full6.pairs import full6_pairs
from crane_stiffness.full6.program import design_program
from crane_stiffness.full6.reference import reference_at_rest
from crane_stiffness.model.geometry import lab_model
from crane_stiffness.contract.status import ERROR, OK, STALE, WAITING, WARN
from crane_stiffness.testing.synthetic_full6_bag import write_full6_session

LAB = lab_model(0.5, 50.0)
PEAKS = np.array([2.8, 3.3, 24.0, 1.6, 1.4, 0.75])
#: A load cell whose moment range the program's largest mx (1.6 N·m, on a few of its steps) passes.
SMALL = np.array([40.0, 40.0, 120.0, 1.5, 2.0, 2.0])


def test_the_rule():
    w = np.array([[0.0, 0, 0, 1.1759, 0, 0], [0, 0, 0, -1.1761, 0, 0], [0, 0, 0, 0, 0, 5.0]])
    at = at_full_scale(w, [40, 40, 120, 1.2, 1.2, 0])  # the last 2 % of 1.2 starts at 1.176; mz unchecked
    assert at.tolist() == [[False] * 6, [False, False, False, True, False, False], [False] * 6]
    with pytest.raises(Full6InputError, match='load_cell_full_scale'):
        check_full_scale([1.0, 2.0])
    assert with_full_scale(OK, 'OK: 26 steps', [0] * 6) == (OK, 'OK: 26 steps')
    level, message = with_full_scale(OK, 'OK: 26 steps', [0, 0, 0, 12, 3, 0])
    assert level == WARN and message == 'load cell at full scale: samples left out (mx 12, my 3); OK: 26 steps'
    assert with_full_scale(WAITING, 'waiting: x', [0, 0, 0, 1, 0, 0])[0] == WARN
    assert with_full_scale(ERROR, 'x', [1, 0, 0, 0, 0, 0])[0] == ERROR
    assert with_full_scale(STALE, 'x', [1, 0, 0, 0, 0, 0])[0] == STALE


def test_offline_the_clipped_samples_are_left_out_and_the_status_says_so(tmp_path):
    program = design_program(d_optimal_design(LAB, PEAKS, n_steps=16, hold_s=1.5, settle_s=0.3, baseline_s=0.5))
    settings = {'settle_s': 0.3, 'load_cell_full_scale': SMALL.tolist()}
    bag = tmp_path / 'clipped'
    session = write_full6_session(bag, program, LAB, seed=4, estimator6=settings, full_scale=SMALL)
    result = analyze_full6(bag, write_files=False)
    assert result.status['level'] == 'WARN', result.status
    assert result.status['message'].startswith('load cell at full scale: samples left out (mx ')
    assert any('load cell at full scale' in p for p in result.problems)
    fit = result.fit
    assert fit is not None and fit.n < result.pairs['poses']
    tangent = reference_at_rest(LAB).tangent
    kept = np.abs(np.diag(fit.stiffness) / np.diag(tangent) - 1)
    # the same bag, its full scale not recorded: the clipped samples are fitted and bend K
    blind = tmp_path / 'blind'
    write_full6_session(blind, program, LAB, seed=4, estimator6={'settle_s': 0.3}, full_scale=SMALL)
    bent = analyze_full6(blind, write_files=False)
    assert bent.fit is not None and bent.fit.n > fit.n
    bent_error = np.abs(np.diag(bent.fit.stiffness) / np.diag(tangent) - 1)
    assert bent_error[3] > 0.02 and bent_error[3] > 5 * kept[3], (bent_error, kept)  # K[mx, θ_x]
    assert session.counts


def test_live_the_node_leaves_them_out_as_offline_and_is_never_ok(rclpy_context):
    """The node fed the samples as its subscriptions hand them over (in stamp order), without DDS."""
    import rclpy

    from crane_stiffness.nodes.stiffness6_estimator import Stiffness6EstimatorNode
    from crane_stiffness.testing.synthetic_full6 import model_responses
    design = d_optimal_design(LAB, PEAKS, n_steps=16, hold_s=1.5, settle_s=0.3, baseline_s=0.5)
    program = design_program(design)
    truth = model_responses(LAB, program, 0.0)
    rng = np.random.default_rng(3)
    starts = [s.start_s for s in truth.steps]
    tc = np.arange(0.0, program.duration_s, 0.01)
    wc = np.array([program.wrench_at(t).wrench for t in tc])
    tw = np.arange(0.0, program.duration_s, 0.001) + 1e-4
    w = truth.wrenches[np.clip(np.searchsorted(starts, tw, side='right') - 1, 0, None)]
    w = np.clip(w + rng.normal(0, [0.01] * 3 + [5e-4] * 3, w.shape), -SMALL, SMALL)
    tp = np.arange(0.0, program.duration_s, 0.004) + 2e-4
    d = truth.deflection[np.clip(np.searchsorted(starts, tp, side='right') - 1, 0, None)]
    d = d + rng.normal(0, [2e-6] * 3 + [2e-5] * 3, d.shape)
    from crane_stiffness.model.rotation import matrix_to_quaternion, rotvec_to_matrix
    q = np.array([matrix_to_quaternion(rotvec_to_matrix(r)) for r in d[:, 3:]])
    node = Stiffness6EstimatorNode(context=rclpy_context, parameter_overrides=[
        rclpy.parameter.Parameter('settle_s', value=0.3), rclpy.parameter.Parameter('stale_after_s', value=3600.0),
        rclpy.parameter.Parameter('load_cell_full_scale', value=SMALL.tolist())])
    published = []
    node.pub_status.publish = published.append  # what it would send
    t0 = node.get_clock().now().nanoseconds * 1e-9 - program.duration_s  # the program just ended
    try:
        events = sorted([(t, 0, i) for i, t in enumerate(tc)] + [(t, 1, i) for i, t in enumerate(tw)]
                        + [(t, 2, i) for i, t in enumerate(tp)])
        for t, kind, i in events:
            if kind == 0:
                node._take(t0 + t, 'command', tuple(wc[i]))
            elif kind == 1:
                node._take(t0 + t, 'wrench', tuple(w[i]))
            else:
                node._take(t0 + t, 'pose', (*d[i, :3], *q[i]))
        node.program_state = 'done'
        node._publish()
        status = published[-1].status[0]
        clipped = at_full_scale(w, SMALL)
        assert node.counters['at_full_scale'] == int(clipped.any(axis=1).sum()) > 0
        assert status.level == bytes([WARN]) and status.message.startswith('load cell at full scale: samples left out')
        # the fit is the offline one of the samples below the line
        keep = ~clipped.any(axis=1)
        offline = full6_pairs(t0 + tc, wc, t0 + tw[keep], t0 + tw[keep], w[keep], t0 + tp, t0 + tp, d[:, :3], q,
                              settle_s=0.3)
        expected = identify(offline.wrench, offline.deflection, offline.step)
        assert node.fit is not None and node.fit.n == len(offline)
        np.testing.assert_allclose(node.fit.stiffness, expected.stiffness, rtol=1e-9)
    finally:
        node.destroy_node()


def test_the_rig_s_6x6_fit_knows_the_simulated_load_cell_s_full_scale():
    from helpers import REPO
    from crane_stiffness.params.files import load_params
    sensors = REPO / 'config' / 'sensors.yaml'
    assert load_params(sensors, 'stiffness6_estimator')['load_cell_full_scale'] == \
        load_params(sensors, 'load_cell')['full_scale']
