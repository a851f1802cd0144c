"""The absurd-command rule shared by crane_model and the estimator: the streaming and vectorised forms agree."""
from __future__ import annotations

import math

import numpy as np
import pytest

from crane_stiffness.contract.command_limits import CommandLimits, command_fault, command_faults
from crane_stiffness.errors import FieldError


def test_streaming_reasons_name_component_and_value() -> None:
    assert command_fault([0, 1, 0, 0, 0, 0]) is None
    assert command_fault([0, 1e4, 0, 0, 0, 1e3]) is None  # the limits themselves are allowed
    reason = command_fault([0, 1e30, 0, 0, 0, 0])
    assert reason is not None and 'fy' in reason and '1e+30' in reason and 'max_abs_force' in reason
    reason = command_fault([0, 0, 0, 0, 0, 1000.5])
    assert reason is not None and 'mz' in reason and 'max_abs_moment' in reason
    assert 'not finite' in command_fault([math.nan, 0, 0, 0, 0, 0])
    assert 'mx' in command_fault([0, 0, 0, -math.inf, 0, 0])
    assert command_fault([0, 20, 0, 0, 0, 0], CommandLimits(max_abs_force=10.0)) is not None
    with pytest.raises(FieldError, match='wrench'):
        command_fault([1, 2, 3])
    with pytest.raises(FieldError, match='max_abs_force'):
        CommandLimits(max_abs_force=-1.0)


def test_vectorised_form_agrees_with_streaming_form() -> None:
    rng = np.random.default_rng(9)
    w = rng.normal(0.0, 1.0, (2000, 6)) * np.array([3e3, 3e3, 3e3, 30.0, 30.0, 30.0])
    special = [math.nan, math.inf, -math.inf, 1e30, -1e30, 1e4, -1e3, 1e4 * (1 + 1e-12)]
    idx = rng.integers(0, len(w), 300)
    w[idx, rng.integers(0, 6, 300)] = rng.choice(special, 300)
    for limits in (CommandLimits(), CommandLimits(max_abs_force=2e3, max_abs_moment=50.0)):
        vec = command_faults(w, limits)
        stream = np.array([command_fault(row, limits) is not None for row in w])
        np.testing.assert_array_equal(vec, stream)
        assert 0 < vec.sum() < len(w)
    with pytest.raises(FieldError, match='wrenches'):
        command_faults(np.zeros((3, 5)))
