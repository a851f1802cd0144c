"""The 6×6 identification on synthetic sessions of the lab model (h = 0.5 m, W = 50 N): the designed program's
quasi-static responses from the nonlinear model plus seeded sensor noise (load cell as config/sensors.yaml, pose
2 µm and 20 µrad at 250 Hz, crane_stiffness.full6.design.LAB_NOISE), fitted with errors in both variables.

What is measured here (docs/full_stiffness.md quotes it): the accuracy against the exact tangent, the coverage of
the 95 % intervals, the designed program against the naive one; the streaming form against the vectorised one; the
status rules."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from crane_stiffness.full6.design import LAB_NOISE, NoiseLevels, d_optimal_design, naive_design
from crane_stiffness.full6.identify import ComplianceEstimator, identify
from crane_stiffness.full6.program import HeldStep, design_program
from crane_stiffness.full6.reference import K2_ENTRIES, k2_of
from crane_stiffness.model import lab_model
from crane_stiffness.contract.status import ERROR, OK, WAITING, WARN
from crane_stiffness.testing.synthetic_full6 import ModelResponses, model_responses, synthetic_pairs

LAB = lab_model(0.5, 50.0)
PEAKS = [2.8, 3.3, 24.0, 1.6, 1.4, 0.75]
SEEDS = range(20)


@pytest.fixture(scope='module')
def designed() -> ModelResponses:
    design = d_optimal_design(LAB, PEAKS)
    return model_responses(LAB, design_program(design), design.settle_s)


@pytest.fixture(scope='module')
def naive() -> ModelResponses:
    design = naive_design(LAB, PEAKS)
    return model_responses(LAB, design_program(design), design.settle_s)


def _linear(truth: ModelResponses, wrenches: np.ndarray | None = None) -> ModelResponses:
    """The same program on a crane that is exactly linear, d = C·w with the tangent's C (and other wrenches)."""
    steps = truth.steps if wrenches is None else [HeldStep(s.start_s, s.end_s, w, s.index)
                                                  for s, w in zip(truth.steps, wrenches)]
    w = np.array([s.wrench for s in steps])
    return dataclasses.replace(truth, steps=steps, deflection=w @ np.linalg.inv(truth.tangent).T)


def test_streaming_and_vectorised_fits_agree_to_1e_9(designed):
    session = synthetic_pairs(designed, seed=3, pose_bias=(1e-3, -2e-3, 5e-3, 0.01, -0.02, 0.03))
    batch = identify(session.wrench, session.deflection, session.step)
    live = ComplianceEstimator()
    for w, d, k in zip(session.wrench, session.deflection, session.step.tolist()):
        live.add(w, d, k)
    streamed = live.fit()
    assert live.n == batch.n == 21750 and batch.level == streamed.level == OK
    for field in dataclasses.fields(batch):
        a, b = getattr(batch, field.name), getattr(streamed, field.name)
        if isinstance(a, np.ndarray):
            assert np.abs(a - b).max() <= 1e-9 * np.abs(a).max(), field.name
        elif isinstance(a, float):
            assert abs(a - b) <= 1e-9 * abs(a), field.name
        else:
            assert a == b, field.name


def test_the_designed_program_identifies_the_tangent_in_every_seeded_run(designed):
    """Every diagonal entry of K within 1 % of the exact tangent, K2 within 3 % with its sign, status OK, in each of
    20 seeded runs (measured: largest diagonal errors 0.36, 0.30, 0.80, 0.52, 0.68, 0.12 %; K2 0.75 %)."""
    k_true = designed.tangent
    k2_true = k2_of(k_true)
    errors, k2_errors = [], []
    for seed in SEEDS:
        fit = identify(*_pairs(designed, seed))
        assert fit.level == OK, fit.message
        errors.append(np.diag(fit.stiffness) / np.diag(k_true) - 1.0)
        k2_errors.append(fit.k2 / k2_true - 1.0)
        for i, j, sign in K2_ENTRIES:
            assert fit.stiffness[i, j] * sign > 0.0 and abs(fit.stiffness[i, j] / k_true[i, j] - 1.0) < 0.03
    worst = np.abs(errors).max(axis=0)
    assert np.all(worst < 0.01), worst
    assert max(abs(e) for e in k2_errors) < 0.03 and k2_true > 0.0


def _pairs(truth: ModelResponses, seed: int):
    s = synthetic_pairs(truth, seed=seed)
    return s.wrench, s.deflection, s.step


def _coverage(truth: ModelResponses, seeds) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per entry, the share of runs whose interval holds the tangent's entry, C and K (6, 6); and the mean interval
    widths of C and K."""
    k = truth.tangent
    c = np.linalg.inv(k)
    cov_c, cov_k, width_c, width_k = (np.zeros((6, 6)) for _ in range(4))
    for seed in seeds:
        fit = identify(*_pairs(truth, seed))
        cov_c += fit.covers_compliance(c)
        cov_k += fit.covers_stiffness(k)
        width_c += fit.compliance_high - fit.compliance_low
        width_k += fit.stiffness_high - fit.stiffness_low
    n = len(seeds)
    return cov_c / n, cov_k / n, width_c / n, width_k / n


def test_the_intervals_cover_the_tangent(designed):
    """Over the 20 seeded runs, 94.6 % of C's 720 intervals and 95.6 % of K's hold the tangent's entry. The least
    covered entries hold it in 15 (C[θ_z, my]) and 16 (K[fx, θ_x]) of 20: with 72 entries at 95 % each, some entry
    below 18 of 20 is the rule, not the exception (P ≈ 0.996 were they independent), so entry by entry the check
    takes more runs: over 200 more, every one of the 72 intervals holds its entry in at least 90 % of them
    (measured: 92.0 % at least; 96.0 % of C's, 95.4 % of K's pooled)."""
    cov_c, cov_k, _, _ = _coverage(designed, SEEDS)
    assert cov_c.mean() >= 0.93 and cov_k.mean() >= 0.93
    assert cov_c.min() >= 0.75 and cov_k.min() >= 0.75
    cov_c, cov_k, _, _ = _coverage(designed, range(100, 300))
    assert cov_c.min() >= 0.90 and cov_k.min() >= 0.90, (cov_c.min(), cov_k.min())
    assert 0.94 <= cov_c.mean() <= 0.975 and 0.94 <= cov_k.mean() <= 0.975


def test_the_designed_program_beats_the_naive_one(designed, naive):
    """Same peaks, steps and test time: the designed program's intervals are 1.23 (C) and 1.40 (K) times narrower
    in geometric mean over the 36 entries (mean widths of 20 seeded runs each), as the design predicted (1.22,
    1.39); the naive program's largest error on K's diagonal was 1.06 % (K[my, θ_y]) in the same runs."""
    _, _, wc_d, wk_d = _coverage(designed, SEEDS)
    _, _, wc_n, wk_n = _coverage(naive, SEEDS)
    ratio_c = math.exp(np.mean(np.log(wc_n / wc_d)))
    ratio_k = math.exp(np.mean(np.log(wk_n / wk_d)))
    assert ratio_c == pytest.approx(1.226, abs=0.01) and ratio_k == pytest.approx(1.396, abs=0.01)


def test_errors_in_the_wrench_are_corrected():
    """A load cell 50 times noisier than the lab's on an exactly linear crane: least squares (wrench noise counted
    as 0) attenuates C by the share of the wrench's scatter that is noise (2.4 % on C[u_x, fx], 7 standard errors,
    and the lack of fit shows it); the estimator, with the noise from the steps' scatter or given, does not."""
    design = d_optimal_design(LAB, PEAKS)
    truth = _linear(model_responses(LAB, design_program(design), design.settle_s))
    c = np.linalg.inv(truth.tangent)
    noisy = NoiseLevels(LAB_NOISE.wrench_std * 50.0, LAB_NOISE.pose_std / 10.0, LAB_NOISE.pair_rate_hz)
    session = synthetic_pairs(truth, noise=noisy, seed=7)
    args = (session.wrench, session.deflection, session.step)
    ols = identify(*args, wrench_noise=np.zeros(6))
    estimated = identify(*args)
    given = identify(*args, wrench_noise=noisy.wrench_std)
    assert np.diag(ols.compliance)[0] / c[0, 0] - 1.0 == pytest.approx(-0.024, abs=0.003)
    assert (ols.compliance[0, 0] - c[0, 0]) / ols.compliance_stderr[0, 0] < -5.0 and ols.level == WARN
    for fit in (estimated, given):
        z = (np.diag(fit.compliance) - np.diag(c)) / np.diag(fit.compliance_stderr)
        assert np.all(np.abs(z) < 3.0), z
        assert fit.level == OK
    np.testing.assert_allclose(np.sqrt(np.diag(estimated.wrench_noise)), noisy.wrench_std, rtol=0.02)


def test_the_status_is_never_ok_on_a_design_that_cannot_determine_c(designed):
    linear = _linear(designed)
    assert ComplianceEstimator().fit().level == WAITING
    # noise-free pairs: nothing to weigh the fit by
    s = synthetic_pairs(linear, seed=1, noise=NoiseLevels(np.zeros(6), np.zeros(6), 250.0))
    fit = identify(s.wrench, s.deflection, s.step)
    assert fit.level == ERROR and fit.message.startswith('undetermined: the deflections do not scatter within')
    # too few steps
    s = synthetic_pairs(linear, seed=1)
    few = s.step < 6
    fit = identify(s.wrench[few], s.deflection[few], s.step[few])
    assert fit.level == ERROR and fit.message == 'undetermined: 6 distinct steps, at least 8 needed'
    # an axis never loaded: mz
    w = linear.wrenches.copy()
    w[:, 5] = 0.0
    fit = identify(*_pairs(_linear(linear, w), 1))
    assert fit.level == ERROR and fit.message == 'undetermined: the load on mz does not spread beyond its noise'
    # two axes always loaded together: my tied to fx
    w = linear.wrenches.copy()
    w[:, 4] = -0.5 * w[:, 0]
    fit = identify(*_pairs(_linear(linear, w), 1))
    assert fit.level == ERROR and fit.message.startswith('undetermined: the wrench design\'s condition number ')
    assert fit.condition > 1e3
    # nearly so: passes at a condition number below 100
    w[:, 4] += 0.4 * linear.wrenches[:, 4]
    fit = identify(*_pairs(_linear(linear, w), 1))
    assert fit.level == OK and 10.0 < fit.condition < 100.0


def test_the_status_is_never_ok_on_a_non_linear_window(designed):
    """The naive program with its side forces at 8 N instead of 3.3 N slackens wire_4 or wire_3 on those steps
    (first slack at 6.61 N; the model still holds the load, softer, as the paper's Fig. 9): the step means leave the
    plane, and the lack-of-fit test says so. The lab design's window passes it."""
    naive = naive_design(LAB, PEAKS)
    steps = naive.steps.copy()
    steps[:, 1] *= 8.0 / 3.3
    truth = model_responses(LAB, design_program(dataclasses.replace(naive, steps=steps)), naive.settle_s)
    assert truth.slack.any()
    fit = identify(*_pairs(truth, 2))
    assert fit.level == WARN and fit.message.startswith('nonlinear: the step means scatter ')
    assert fit.lack_of_fit > 100.0 and fit.lack_of_fit_p < 1e-12
    clean = identify(*_pairs(designed, 2))
    assert clean.level == OK and 0.7 < clean.lack_of_fit < 1.3
