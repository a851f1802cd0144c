"""The load step of a pair from the commands: the streaming labeller equals the vectorised rule pair by pair."""
from __future__ import annotations

import numpy as np
import pytest

from crane_stiffness.full6.errors import Full6InputError
from crane_stiffness.full6.steps import NO_STEP, StepLabeller, label_steps, stretch_starts


def _commands() -> tuple[np.ndarray, np.ndarray]:
    """100 Hz commands: 1 s at zero, a step to w1 held 1 s, a 0.5 s ramp, w2 held 1 s, back to zero for 0.5 s."""
    t = np.arange(0, 4.0, 0.01)
    w = np.zeros((t.size, 6))
    w1, w2 = np.array([1.0, -2.0, 10.0, 0.1, 0.2, -0.3]), np.array([-1.0, 2.0, 0.0, 0.0, 0.0, 0.3])
    w[(t >= 1.0) & (t < 2.0)] = w1
    ramp = (t >= 2.0) & (t < 2.5)
    w[ramp] = w1 + np.outer((t[ramp] - 2.0) / 0.5, w2 - w1)
    w[(t >= 2.5) & (t < 3.5)] = w2
    return t, w


def test_a_pair_takes_the_stretch_in_force_once_settled_and_none_in_a_ramp():
    t, w = _commands()
    starts = stretch_starts(t, w)
    assert starts[0] == 0.0 and starts[1] == pytest.approx(1.0) and starts[-1] == pytest.approx(3.5)
    held = len(starts) - 2  # the held w2 stretch: after the ramp's commands, each a stretch of its own
    stamps = np.array([-0.1, 0.05, 0.5, 1.1, 1.5, 2.2, 2.6, 3.2, 3.6, 3.995, 5.0])
    labels = label_steps(t, w, stamps, settle_s=0.2)
    assert labels.tolist() == [NO_STEP, NO_STEP, 0, NO_STEP, 1, NO_STEP, NO_STEP, held, NO_STEP, NO_STEP, NO_STEP]


def test_streaming_equals_vectorised_pair_by_pair_in_any_order():
    t, w = _commands()
    rng = np.random.default_rng(3)
    stamps = rng.uniform(-0.5, 4.5, 3000)
    expected = label_steps(t, w, stamps, settle_s=0.25)
    labeller = StepLabeller(0.25)
    got = np.full(stamps.size, -99)
    pending = list(rng.permutation(stamps.size))
    for k in range(t.size):  # commands arrive in order; pairs are asked for as they come, in random order
        labeller.command(t[k], w[k])
        still = []
        for i in pending:
            label = labeller.label(stamps[i])
            if label is None:
                still.append(i)
            else:
                got[i] = label
        pending = still
    got[pending] = NO_STEP  # never confirmed by a later command: never fitted
    assert np.array_equal(got, expected)
    assert (expected >= 0).sum() > 1500


def test_a_label_waits_for_a_command_after_the_pair_and_bad_settings_are_refused():
    labeller = StepLabeller(0.0)
    labeller.command(0.0, np.zeros(6))
    labeller.command(1.0, np.zeros(6))
    assert labeller.label(1.0) is None and labeller.label(0.5) == 0 and labeller.label(-0.5) == NO_STEP
    labeller.command(1.01, np.ones(6))
    assert labeller.label(1.0) == 0 and labeller.label(1.005) == 0 and labeller.stretches == 2
    for bad in (-1.0, float('nan'), 'x'):
        with pytest.raises(Full6InputError, match='settle_s'):
            StepLabeller(bad)  # type: ignore[arg-type]
