"""A multi-axis design as a load program with the existing segment kinds (0 s steps jump the axes together), the held
steps of a program, and config/program_full6.yaml: the designed program for the lab model, inside the slack rule."""
from __future__ import annotations

import numpy as np
import pytest
import yaml

from helpers import REPO

from crane_stiffness.full6.admissible import check_steps
from crane_stiffness.full6.design import d_optimal_design, naive_design
from crane_stiffness.full6.program import FILE_DECIMALS, design_program, held_steps, program_yaml
from crane_stiffness.model import lab_model
from crane_stiffness.sim.program import LoadProgram, Segment, load_program_file

LAB = lab_model(0.5, 50.0)
PEAKS = [2.8, 3.3, 24.0, 1.6, 1.4, 0.75]


@pytest.fixture(scope='module')
def design():
    return d_optimal_design(LAB, PEAKS)


def test_a_design_plays_as_a_program_of_existing_segment_kinds(design):
    program = design_program(design)
    assert program.duration_s == design.duration_s == 100.0
    steps = held_steps(program)
    assert len(steps) == design.n_steps + 2
    np.testing.assert_array_equal([s.wrench for s in steps[1:-1]], np.round(design.steps, FILE_DECIMALS) + 0.0)
    assert not np.any(steps[0].wrench) and not np.any(steps[-1].wrench)
    assert [(s.start_s, s.end_s) for s in steps[:3]] == [(0.0, 2.0), (2.0, 6.0), (6.0, 10.0)]
    assert (steps[-1].start_s, steps[-1].end_s) == (98.0, 100.0)
    # every instant of a hold commands the whole wrench: the six axes jump together
    for s in steps[1:4]:
        for t in np.linspace(s.start_s, s.end_s, 7)[:-1]:
            np.testing.assert_array_equal(program.wrench_at(t).wrench, s.wrench)
    settled = held_steps(program, settle_s=0.5)
    assert [(s.start_s, s.end_s, s.index) for s in settled[:2]] == [(0.5, 2.0, 0), (2.5, 6.0, 1)]
    # the exact design when asked for
    np.testing.assert_array_equal([s.wrench for s in held_steps(design_program(design, decimals=None))[1:-1]],
                                  design.steps)


def test_held_steps_merge_equal_neighbours_and_skip_ramps():
    program = load_program_file(REPO / 'config' / 'program_side_force.yaml')
    steps = held_steps(program)
    assert [float(s.wrench[1]) for s in steps] == [0.0, 0.8, 1.6, 2.4, 3.2, 4.0, 3.2, 2.4, 1.6, 0.8, 0.0]
    assert [(h.start_s, h.end_s) for h in program.holds('fy')] == [(s.start_s, s.end_s) for s in steps]
    with pytest.raises(ValueError, match='settle_s = -1'):
        held_steps(program, -1.0)
    segments = [Segment('step', 'fy', 0.0, 1.0), Segment('ramp', 'fy', 0.8, 1.0), Segment('hold', 'fy', 0.8, 2.0),
                Segment('step', 'mz', 0.1, 0.0), Segment('step', 'mz', 0.1, 1.0)]
    twice = LoadProgram(segments, repeats=2)
    assert [(s.start_s, s.end_s, float(s.wrench[1]), float(s.wrench[5])) for s in held_steps(twice)] == \
        [(0.0, 1.0, 0.0, 0.0), (2.0, 4.0, 0.8, 0.0), (4.0, 5.0, 0.8, 0.1), (5.0, 6.0, 0.0, 0.1),
         (7.0, 10.0, 0.8, 0.1)]  # the second repeat's mz step holds the wrench it finds


def test_the_program_file_text_reads_back_as_the_program(design):
    text = program_yaml(design, title='a title', how='how it was made')
    data = yaml.safe_load(text)
    params = data['load_program']['ros__parameters']
    assert LoadProgram.from_params(params).to_params() == design_program(design).to_params()
    assert text.startswith('# a title\n# how it was made\n')
    assert data['stiffness6_estimator']['ros__parameters'] == {'settle_s': design.settle_s}  # the 6x6 fit comes along
    naive = naive_design(LAB, PEAKS)
    assert '#     3    0.0000    3.3000    0.0000    0.0000    0.0000    0.0000    2.0034  wire_4 (CE)' in \
        program_yaml(naive)


def test_config_program_full6_is_the_lab_design_inside_the_slack_rule(design):
    program = load_program_file(REPO / 'config' / 'program_full6.yaml')
    assert program.name == 'full6' and program.duration_s == 100.0
    steps = held_steps(program)
    wrenches = np.array([s.wrench for s in steps])
    assert not np.any(wrenches[0]) and not np.any(wrenches[-1])
    # the file is what the design code makes for the lab model, to the file's 4 decimals
    np.testing.assert_allclose(wrenches[1:-1], design.steps, rtol=0, atol=0.6 * 10.0 ** -FILE_DECIMALS)
    factors = check_steps(LAB, wrenches[1:-1], 2.0)  # every step and transition keeps the safety factor 2
    assert factors.factor.min() > 2.001
    assert np.all(np.abs(wrenches).max(axis=0) <= PEAKS)
