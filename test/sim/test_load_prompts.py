"""Where a program asks an operator for a new level (load_prompts) and when a measured load has settled there
(Settling): pure rules of load_application operator."""
from __future__ import annotations

import math

import pytest

from crane_stiffness.sim.program import LoadProgram, Segment, Settling, load_prompts


def test_levels_at_a_steps_start_and_a_ramps_end_over_every_repeat():
    program = LoadProgram([Segment('hold', 'fy', 0.0, 1.0), Segment('ramp', 'fy', 0.8, 2.0),
                           Segment('hold', 'fy', 0.8, 1.5), Segment('step', 'mz', -0.1, 0.5),
                           Segment('ramp', 'mz', -0.1, 1.0), Segment('ramp', 'fy', 0.0, 2.0),
                           Segment('step', 'mz', 0.0, 1.0)], repeats=2)
    prompts = load_prompts(program)
    cycle = 9.0
    expected = [(3.0, 'fy', 0.8, (0, 0.8, 0, 0, 0, 0)), (4.5, 'mz', -0.1, (0, 0.8, 0, 0, 0, -0.1)),
                (8.0, 'fy', 0.0, (0, 0, 0, 0, 0, -0.1)), (8.0, 'mz', 0.0, (0, 0, 0, 0, 0, 0))]
    expected += [(t + cycle, a, v, w) for t, a, v, w in expected]
    assert [(p.time_s, p.axis, p.level, p.wrench) for p in prompts] == expected  # a flat ramp asks for nothing
    assert [p.index for p in prompts] == list(range(8))
    # Each prompt's wrench is the program's command once the level is reached (two at one instant: the last one's).
    for p, following in zip(prompts, prompts[1:] + [None]):
        if following is None or following.time_s != p.time_s:
            assert tuple(program.wrench_at(p.time_s).wrench) == pytest.approx(p.wrench)
    assert prompts[1].text(8) == 'level 2/8: set mz = -0.1 N·m (with fy = 0.8 N)'


def test_settling_needs_the_whole_hold_inside_the_band():
    s = Settling(target=2.0, tolerance=0.05, hold_s=0.5)
    assert not s.update(0.0, 2.04)
    assert not s.update(0.4, 1.96)
    assert not s.update(0.45, 2.2)           # out of the band: the wait starts again
    assert not s.update(0.5, 2.0)
    assert not s.update(0.99, 2.01)
    assert s.update(1.0, 1.955)              # 0.5 s inside
    assert not s.update(1.1, math.nan)       # a NaN reading is not at the level
