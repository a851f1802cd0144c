"""Designed multi-axis load programs on the lab model (h = 0.5 m, W = 50 N): the D-optimal program against the naive
one with the same peaks and test time, both inside the slack rule (a naive program past it is refused)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from crane_stiffness.full6.admissible import check_steps
from crane_stiffness.full6.design import LAB_NOISE, d_optimal_design, naive_design
from crane_stiffness.full6.errors import Full6InputError, SlackDesignError
from crane_stiffness.model import lab_model

LAB = lab_model(0.5, 50.0)
#: The peaks of config/program_full6.yaml: each axis just inside its own margin over the safety factor 2.
PEAKS = [2.8, 3.3, 24.0, 1.6, 1.4, 0.75]


@pytest.fixture(scope='module')
def designs():
    return d_optimal_design(LAB, PEAKS), naive_design(LAB, PEAKS)


def test_a_naive_program_past_the_safety_factor_is_refused_at_its_first_bad_step():
    with pytest.raises(SlackDesignError) as err:
        naive_design(LAB, [2.8, 4.0, 24.0, 1.6, 1.4, 0.75])  # fy 4 N: inside the margin, not twice inside
    e = err.value
    assert (e.step, e.wire_name) == (2, 'wire_4 (CE)') and e.factor == pytest.approx(6.6110817 / 4.0, rel=1e-6)
    assert str(e).startswith('step 3 of 24 (wrench fx +0 N, fy +4 N,')
    assert 'too close to slack: along its direction wire_4 (CE) goes slack at 1.653 times this wrench, less than the ' \
           'safety factor 2' in str(e)
    with pytest.raises(SlackDesignError, match=r'^step 6 of 24 .* wire_1 \(AD\)'):
        naive_design(LAB, [2.8, 3.3, 25.0, 1.6, 1.4, 0.75])  # −25 N lifts W/2: every wire at a factor of 2 less a hair


def test_bad_design_arguments_are_named():
    with pytest.raises(Full6InputError, match=r'^peaks = .*the program must load all six axes'):
        d_optimal_design(LAB, [2.8, 3.3, 24.0, 1.6, 1.4, 0.0])
    with pytest.raises(Full6InputError, match=r'^n_steps = 13: must be even'):
        d_optimal_design(LAB, PEAKS, n_steps=13)
    with pytest.raises(Full6InputError, match=r'^n_steps = 18: must be a multiple of 12'):
        naive_design(LAB, PEAKS, n_steps=18)
    with pytest.raises(Full6InputError, match=r'^hold_s = 0.5: must be a finite number > settle_s'):
        naive_design(LAB, PEAKS, hold_s=0.5)


def test_the_designed_program_spans_six_axes_inside_the_rule(designs):
    design, naive = designs
    s = design.steps
    assert s.shape == (24, 6) and np.array_equal(s[1::2], -s[::2])  # fold-over pairs, played +v then −v
    assert np.all(np.abs(s) <= np.asarray(PEAKS) * (1 + 1e-12))
    assert design.slack.factor.min() >= 2.0 and design.slack.factor.min() == pytest.approx(2.002, rel=1e-4)
    check_steps(LAB, s, 2.0)  # transitions too
    m = design.wrench_scatter()
    scale = np.sqrt(np.diag(m))
    eig = np.linalg.eigvalsh(m / np.outer(scale, scale))
    assert eig[-1] / eig[0] < 3.0  # near-orthogonal (measured 2.67)
    assert design.efficiency > 0.97  # against the best continuous design on the same vertices (measured 0.980)
    assert design.duration_s == naive.duration_s == 100.0
    assert design.pairs(design.hold_s) == 875 and design.pairs(design.baseline_s) == 375  # 250 Hz, 0.5 s settling
    again = d_optimal_design(LAB, PEAKS)
    assert np.array_equal(again.steps, s)  # deterministic


def test_the_designed_program_beats_the_naive_one_on_paper(designs):
    """Predicted by the information matrix (the measurement is in test_full6_identify): log det 1243.7 against
    1226.7, and the intervals' geometric mean 1.22 (C) and 1.39 (K) times narrower."""
    design, naive = designs
    assert design.log_det_information() - naive.log_det_information() == pytest.approx(17.01, abs=0.05)
    (cd, kd), (cn, kn) = design.predicted_stderr(), naive.predicted_stderr()
    assert math.exp(np.mean(np.log(cn / cd))) == pytest.approx(1.224, abs=0.005)
    assert math.exp(np.mean(np.log(kn / kd))) == pytest.approx(1.393, abs=0.005)
    k = np.linalg.inv(design.model_compliance)
    # every diagonal entry of K predicted within 0.4 % (one standard error) by the design, not by the naive one
    assert np.all(np.diag(kd) / np.diag(k) < 0.0037) and np.max(np.diag(kn) / np.diag(k)) > 0.0045
    assert LAB_NOISE.pair_rate_hz == 250.0 and LAB_NOISE.wrench_std[0] == pytest.approx(0.005)
