"""When a fit may be called OK (estimation/quality.py), live and offline alike, and the moment series' angle reading."""
from __future__ import annotations

import math

import numpy as np
import pytest

from crane_stiffness.estimation.errors import ParameterError
from crane_stiffness.estimation.settings import LiveSettings
from crane_stiffness.estimation.live import LiveStiffness
from crane_stiffness.estimation.quality import (CommandRange, axis_problem, fit_problems, moved_axes, noise_std,
                                                scatter_ratio)
from crane_stiffness.contract.status import OK, WARN


def test_noise_std_from_successive_differences_ignores_ramps_and_steps():
    rng = np.random.default_rng(1)
    t = np.arange(20_000) * 1e-3
    slow = 0.8 * t + np.repeat(np.arange(20) * 4.0, 1000)  # a ramp and 19 steps of 4 N
    assert noise_std(slow + rng.normal(0, 0.01, t.size)) == pytest.approx(0.01, rel=0.05)
    assert math.isnan(noise_std([1.0, 2.0]))


def test_scatter_ratio_is_one_for_a_linear_fit_with_noise_on_both_sensors_and_large_otherwise():
    rng = np.random.default_rng(2)
    x_true = np.repeat(np.linspace(0, 75e-6, 6), 2000) + np.linspace(0, 1e-6, 12_000)
    k = 53_794.0
    x = x_true + rng.normal(0, 2e-7, x_true.size)
    y = k * x_true + rng.normal(0, 0.01, x_true.size)
    slope, intercept = np.polyfit(x, y, 1)
    rms = float(np.sqrt(np.mean((y - slope * x - intercept) ** 2)))
    assert scatter_ratio(x, y, slope, rms) == pytest.approx(1.0, abs=0.15)
    # Slow hysteresis-like wander (not noise): far beyond what the sensors explain.
    wander = 0.3 * np.sin(np.linspace(0, 20, x.size))
    rms = float(np.sqrt(np.mean((y + wander - slope * x - intercept) ** 2)))
    assert scatter_ratio(x, y + wander, slope, rms) > 5


@pytest.mark.parametrize('k, low, high, scatter, expected', [
    (53_794.0, 53_700.0, 53_900.0, 0.9, []),
    (-447.0, -1093.0, 199.0, 1.0, ['slope -447 is not positive', 'its 95 % interval -1093 .. 199 contains zero']),
    (204.0, -470.0, 878.0, 1.0, ['its 95 % interval -470 .. 878 contains zero']),
    (53_794.0, 53_700.0, 53_900.0, 4.2, ["scatter 4.2 x what the sensors' noise explains"]),
    (math.nan, math.nan, math.nan, math.nan, ['slope nan is not positive']),
])
def test_fit_problems_say_which(k, low, high, scatter, expected):
    found = fit_problems(k, low, high, scatter, 3.0)
    assert len(found) == len(expected)
    for text, start in zip(found, expected):
        assert text.startswith(start), (text, start)


def test_axis_problem_names_both_axes():
    zero, mz = np.zeros(6), np.array([0, 0, 0, 0, 0, 0.5])
    assert axis_problem('fy', zero, zero) == ''
    assert moved_axes(zero, mz) == ['mz']
    assert axis_problem('mz', zero, mz) == ''
    text = axis_problem('fy', zero, mz)
    assert 'fitting fy' in text and 'load mz' in text and 'fy does not move' in text
    both = np.array([0, 4.0, 0, 0, 0, 0.5])
    assert 'also move mz' in axis_problem('fy', zero, both)


def test_command_range_streaming_equals_the_offline_min_max():
    rng = np.random.default_rng(3)
    wrenches = rng.normal(size=(500, 6)) * np.array([0, 1, 0, 0, 0, 0])
    live = CommandRange()
    assert live.problem('fy') == ''  # nothing seen yet
    for w in wrenches:
        live.add(w)
    live.add([math.nan] * 6)  # never counted
    np.testing.assert_array_equal(live.low, wrenches.min(axis=0))
    np.testing.assert_array_equal(live.high, wrenches.max(axis=0))
    assert live.problem('fy') == axis_problem('fy', wrenches.min(axis=0), wrenches.max(axis=0)) == ''
    assert 'fitting mz' in live.problem('mz')


def test_lever_arm_turns_the_tangential_reading_into_the_angle_the_same_way_live_and_offline():
    s = LiveSettings.from_params({'force_axis': 'mz', 'lever_arm_m': 0.1})
    readings = np.array([0.0, 2.7e-5, -1e-3, 0.0999, 0.2])
    offline = s.reading_to_displacement(readings)
    live = [s.reading_to_displacement(float(r)) for r in readings]
    np.testing.assert_array_equal(offline[:4], np.array(live[:4]))
    assert math.isnan(live[4]) and math.isnan(offline[4])  # beyond the arm: not a reading, dropped as non-finite
    assert offline[1] == pytest.approx(2.7e-4, rel=1e-7)
    assert s.stiffness_unit == 'N·m/rad' and s.displacement_unit == 'rad'
    assert LiveSettings.from_params({'force_axis': 'fy'}).reading_to_displacement(1.5e-5) == 1.5e-5
    with pytest.raises(ParameterError, match=r"lever_arm_m.*must be 0 for the force axis fy"):
        LiveSettings.from_params({'force_axis': 'fy', 'lever_arm_m': 0.1})
    with pytest.raises(ParameterError, match='lever_arm_m'):
        LiveSettings.from_params({'force_axis': 'mz', 'lever_arm_m': -0.1})


def _feed(live: LiveStiffness, axis: int, load: np.ndarray, disp: np.ndarray, rng) -> None:
    for i, (f, x) in enumerate(zip(load, disp)):
        t = 1.0 + i * 1e-3
        command = np.zeros(6)
        command[axis] = f
        if i % 10 == 0:
            live.add_command(t, command, t)
        wrench = np.zeros(6) + rng.normal(0, 0.01, 6)
        wrench[axis] += f
        live.add_force(t, wrench, t)
        live.add_displacement(t, x + rng.normal(0, 2e-7), t)


def test_live_estimate_fitting_another_axis_than_the_loaded_one_is_never_ok():
    """The issue's moment_z symptom on the core: the program loads mz, the estimator fits fy against an LVDT that
    sees nothing. Before: k = -447 N/m, status OK. Now WARN, naming both axes and why the fit means nothing."""
    rng = np.random.default_rng(4)
    load = np.concatenate([np.linspace(0, 0.5, 3000), np.linspace(0.5, 0, 3000)])
    live = LiveStiffness(LiveSettings.from_params({'force_axis': 'fy', 'window': 30_000, 'delay_window_s': 0.0}))
    _feed(live, 5, load, np.zeros(load.size), rng)  # mz moves; the y LVDT reads noise
    live.values()
    live.refresh()
    reports = live.report()
    for r in reports:
        assert r.level >= WARN, r
        assert 'fitting fy' in r.message and 'load mz' in r.message, r.message
    # the y LVDT reads noise: least squares would fit noise against noise (a slope of -447 N/m); the fit with the
    # displacement noise counted finds no spread beyond it and gives no estimate at all
    assert 'no estimate yet' in reports[0].message and math.isnan(live.loading_stiffness())
    # The same program with the estimator on mz and an angle reading: OK.
    live = LiveStiffness(LiveSettings.from_params({'force_axis': 'mz', 'lever_arm_m': 0.1, 'hysteresis': 0.02,
                                                   'window': 30_000, 'delay_window_s': 0.0}))
    _feed(live, 5, load, 0.1 * np.sin(load / 1871.5), rng)
    live.values()
    live.refresh()
    loading = live.report()[0]
    assert loading.level == OK, loading.message
    assert live.loading_stiffness() == pytest.approx(1871.5, rel=0.01)
