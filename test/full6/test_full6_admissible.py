"""The loads a multi-axis program may hold on the lab model (h = 0.5 m, W = 50 N): the slack rule and its refusals
naming the step, the direction and the wire."""
from __future__ import annotations

import math

import numpy as np
import pytest

from crane_stiffness.design.margins import slack_margins
from crane_stiffness.full6.admissible import (admissible_vertices, axis_peaks, check_steps, slack_factors,
                                              tension_rates)
from crane_stiffness.full6.errors import Full6InputError, SlackDesignError
from crane_stiffness.model import lab_model, rest_pose, solve_batch

LAB = lab_model(0.5, 50.0)
#: The peaks of config/program_full6.yaml: each axis just inside its own margin over the safety factor 2.
PEAKS = [2.8, 3.3, 24.0, 1.6, 1.4, 0.75]


def test_axis_peaks_are_the_margins_code_s_margins_over_the_safety_factor():
    peaks = axis_peaks(LAB, 2.0)
    np.testing.assert_allclose(peaks, [2.86267, 3.30554, 25.0, 1.64978, 1.42943, 0.754593], rtol=1e-5)
    rest = rest_pose(LAB)
    forces = slack_margins(LAB, rest, np.vstack([np.eye(3), -np.eye(3)]), 'force').margin
    moments = slack_margins(LAB, rest, np.vstack([np.eye(3), -np.eye(3)]), 'moment').margin
    np.testing.assert_allclose(peaks, np.minimum(np.r_[forces[:3], moments[:3]], np.r_[forces[3:], moments[3:]]) / 2,
                               rtol=1e-10)
    # the factor scales exactly with the load
    w = np.array([1.0, -0.5, 3.0, 0.2, 0.1, -0.1])
    f = slack_factors(LAB, [w, 2.0 * w, np.zeros(6)])
    assert f.factor[1] == pytest.approx(f.factor[0] / 2.0, rel=1e-10) and f.factor[2] == math.inf
    assert f.wire[0] == f.wire[1] and f.wire[2] == -1


def test_tension_rates_predict_the_model_s_tensions_under_a_small_load():
    rates = tension_rates(LAB, PEAKS)
    assert np.allclose(rates[:, 2], rates[0, 2], rtol=1e-9)  # a vertical pull shares out equally
    w = np.array([0.3, -0.2, 2.0, 0.1, -0.05, 0.04])
    t = solve_batch(LAB, np.vstack([w, -w])).wire_tensions
    np.testing.assert_allclose((t[0] - t[1]) / 2.0, rates @ w, rtol=1e-6)  # the odd part: affine to third order


def test_a_step_that_would_slacken_a_wire_is_refused_naming_step_direction_and_wire():
    steps = np.zeros((3, 6))
    steps[0, 0] = 1.0
    steps[1, 1] = 7.0  # +fy slackens wire_4 (CE) at 6.61 N
    steps[2, 1] = -1.0
    with pytest.raises(SlackDesignError) as err:
        check_steps(LAB, steps, 2.0)
    e = err.value
    assert (e.step, e.wire, e.wire_name, e.transition) == (1, 3, 'wire_4 (CE)', False)
    np.testing.assert_allclose(e.direction, [0, 1, 0, 0, 0, 0])
    assert e.factor == pytest.approx(6.6110817 / 7.0, rel=1e-6)
    msg = str(e)
    assert msg.startswith('step 2 of 3 (wrench fx +0 N, fy +7 N, fz +0 N, mx +0 N·m, my +0 N·m, mz +0 N·m; '
                          'direction (fx +0.000, fy +1.000,')
    assert 'it would slacken wire_4 (CE): along its direction that wire goes slack at 0.9444 times' in msg


def test_a_transition_that_leaves_the_rule_is_refused():
    """Two steps on the same face of the admissible set, each exactly on the rule: the straight path between them
    dips a little below it (the tensions are not quite affine in the load), and the check names the transition."""
    v = admissible_vertices(LAB, PEAKS, 2.0)
    f = slack_factors(LAB, v)
    face = f.wire == f.wire[0]
    a, b = v[face][:2] * (f.factor[face][:2, None] / 2.0)  # factor 2 exactly (to rounding)
    tol = 1.0 - 1e-7
    held = check_steps(LAB, [a], 2.0 * tol)
    assert held.factor[0] == pytest.approx(2.0, rel=1e-9)
    with pytest.raises(SlackDesignError, match=r'^the transition from step 1 to step 2 of 2, (25|50|75)% of the '
                                               r'way, \(wrench .*\) is refused: it comes too close to slack') as err:
        check_steps(LAB, [a, b], 2.0 * tol)
    assert err.value.transition and err.value.wire == f.wire[0]


def test_bad_arguments_are_named():
    with pytest.raises(Full6InputError, match=r'^peaks = .*the design must load all six axes'):
        admissible_vertices(LAB, [2.8, 3.3, 24.0, 1.6, 1.4, 0.0])
    with pytest.raises(Full6InputError, match=r'^safety_factor = 0.5'):
        check_steps(LAB, np.ones((1, 6)), 0.5)
