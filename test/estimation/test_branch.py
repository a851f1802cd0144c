"""Tests of crane_stiffness.estimation.branch: the live BranchTracker and its vectorized form, branch_labels."""
from __future__ import annotations

import numpy as np
import pytest

from helpers import REPO
from crane_stiffness.estimation.branch import BranchTracker, branch_labels
from crane_stiffness.estimation.errors import ParameterError
from crane_stiffness.sim.program import load_program_file

SIDE_FORCE = load_program_file(REPO / 'config' / 'program_side_force.yaml')


def test_branch_tracker_hysteresis() -> None:
    tracker = BranchTracker(threshold=0.2)
    loads = [0.0, 1.0, 2.0, 2.1, 2.0, 1.95, 1.85, 1.0, 0.5, 0.6, 0.71, 1.5, -0.1, -3.0]
    labels = [tracker.update(v) for v in loads]
    assert labels == ['loading', 'loading', 'loading', 'loading', 'loading', 'loading',  # noise within band
                      'unloading', 'unloading', 'unloading', 'unloading',  # 0.6 is 0.1 above the minimum
                      'loading', 'loading',  # 0.71 - 0.5 > 0.2
                      'unloading', 'loading']  # |-0.1| drop, then |-3| away from zero is loading again
    with pytest.raises(ParameterError, match='threshold'):
        BranchTracker(-1.0)


@pytest.mark.parametrize('threshold', [0.0, 0.2, 1.5])
def test_vectorized_branch_labels_equal_the_tracker(threshold):
    rng = np.random.default_rng(1)
    t, wrench = SIDE_FORCE.sample(1000.0)
    walks = [wrench[:, 1], wrench[:, 1] + rng.normal(0, 0.08, t.size), np.cumsum(rng.normal(0, 0.3, 20_000)),
             -wrench[:, 1]]
    for load in walks:
        tracker = BranchTracker(threshold)
        expected = np.array([tracker.update(v) == 'loading' for v in load])
        assert np.array_equal(branch_labels(load, threshold), expected)
