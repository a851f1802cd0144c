"""Tests of crane_stiffness.sim.program: sampling, phases, validation, parameter files."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from crane_stiffness.sim import (LoadProgram, ParameterError, ProgramFileError, Segment, SimError,
                                 load_program_file)

CONFIG = Path(__file__).resolve().parents[2] / 'config'

PARAMS = {
    'name': 'small',
    'rate_hz': 50.0,
    'repeats': 2,
    'segments.kind': ['ramp', 'hold', 'step', 'ramp', 'step'],
    'segments.axis': ['fy', 'fy', 'mz', 'fy', 'mz'],
    'segments.target': [4.0, 4.0, 0.2, -2.0, 0.0],
    'segments.duration': [2.0, 1.0, 0.5, 3.0, 0.0],
}


def test_sampling_at_known_times() -> None:
    program = LoadProgram.from_params(PARAMS)
    assert program.cycle_duration_s == 6.5
    assert program.duration_s == 13.0
    cases = [
        # t, fy, mz, segment, repeat, phase
        (0.0, 0.0, 0.0, 0, 0, 'loading'),
        (0.5, 1.0, 0.0, 0, 0, 'loading'),
        (2.0, 4.0, 0.0, 1, 0, 'hold'),  # boundaries belong to the next segment
        (3.2, 4.0, 0.2, 2, 0, 'hold'),  # the step jumped mz, fy still held
        (4.0, 3.0, 0.2, 3, 0, 'unloading'),  # ramp 4 → −2 over 3 s
        (5.5, 0.0, 0.2, 3, 0, 'loading'),  # through zero: |fy| grows again
        (6.0, -1.0, 0.2, 3, 0, 'loading'),
        (6.5, -2.0, 0.0, 0, 1, 'unloading'),  # repeat 2 starts where repeat 1 ended (the 0 s step reset mz)
        (7.5, 1.0, 0.0, 0, 1, 'loading'),  # −2 → 4 over 2 s
        (6.75, -1.25, 0.0, 0, 1, 'unloading'),
    ]
    for t, fy, mz, segment, repeat, phase in cases:
        state = program.wrench_at(t)
        assert state.wrench[1] == pytest.approx(fy), t
        assert state.wrench[5] == pytest.approx(mz), t
        assert (state.segment_index, state.repeat_index, state.phase) == (segment, repeat, phase), t
        assert state.progress == pytest.approx(t / 13.0)
        assert not state.done
        assert state.wrench[[0, 2, 3, 4]].tolist() == [0.0] * 4


def test_before_start_and_after_end() -> None:
    program = LoadProgram.from_params(PARAMS)
    before = program.wrench_at(-1.0)
    assert before.wrench.tolist() == [0.0] * 6 and not before.done and before.progress == 0.0
    end = program.wrench_at(13.0)
    assert end.done and end.progress == 1.0 and end.phase == 'hold'
    assert end.wrench.tolist() == [0.0, -2.0, 0.0, 0.0, 0.0, 0.0]
    assert (end.segment_index, end.repeat_index) == (4, 1)
    with pytest.raises(ParameterError, match='t_s'):
        program.wrench_at(math.nan)


def test_sample_and_round_trip() -> None:
    program = LoadProgram.from_params(PARAMS)
    t, wrench = program.sample()
    assert t.shape == (651,) and wrench.shape == (651, 6)
    assert t[-1] == pytest.approx(13.0)
    assert wrench[25, 1] == pytest.approx(1.0)  # t = 0.5 s at 50 Hz
    assert LoadProgram.from_params(program.to_params()).to_params() == program.to_params()


def test_holds_and_levels() -> None:
    program = LoadProgram([Segment('ramp', 'fy', 2.0, 1.0), Segment('hold', 'fy', 2.0, 1.0),
                           Segment('step', 'fy', 4.0, 1.0), Segment('hold', 'fy', 4.0, 0.5),
                           Segment('ramp', 'fy', 2.0, 1.0), Segment('hold', 'fy', 2.0, 1.0)])
    holds = program.holds()
    assert [(h.level, h.start_s, h.end_s, h.approach) for h in holds] == [
        (2.0, 1.0, 2.0, 'loading'), (4.0, 2.0, 3.5, 'loading'), (2.0, 4.5, 5.5, 'unloading')]
    assert program.levels().tolist() == [2.0, 4.0]
    assert program.levels('mz').size == 0


def test_paper_programs_load_and_fit_the_demo() -> None:
    expected = {'side_force': ('fy', 4.0), 'moment_z': ('mz', 0.5), 'force_z': ('fz', 20.0)}
    for name, (axis, peak) in expected.items():
        program = load_program_file(CONFIG / f'program_{name}.yaml')
        assert program.name == name
        assert program.rate_hz == 100.0
        assert 10.0 <= program.duration_s <= 30.0
        t, wrench = program.sample()
        j = ['fx', 'fy', 'fz', 'mx', 'my', 'mz'].index(axis)
        assert wrench[:, j].max() == pytest.approx(peak)
        assert np.delete(wrench, j, axis=1).max() == 0.0
        assert wrench[-1, j] == 0.0  # unloaded at the end
        levels = program.levels(axis)
        assert levels[0] == 0.0 and levels[-1] == pytest.approx(peak) and levels.size == 6
        approaches = [h.approach for h in program.holds(axis)]
        assert approaches.count('unloading') == 5  # every level below the peak is also visited unloading


def test_linear_programs_keep_every_wire_taut_on_the_lab_rig_and_the_slack_program_does_not() -> None:
    """The paper's series test the linear range; Fig. 9's slack behaviour has its own program."""
    from crane_stiffness.params.geometry import geometry_from_params
    from crane_stiffness.params.files import load_params
    from crane_stiffness.model import solve_path

    g = geometry_from_params(load_params(CONFIG / 'crane_lab.yaml'))
    for name, expect_slack in (('side_force', False), ('moment_z', False), ('force_z', False),
                               ('side_force_slack', True)):
        program = load_program_file(CONFIG / f'program_{name}.yaml')
        _, wrench = program.sample(rate_hz=10.0)
        path = solve_path(g, wrench)
        assert any(eq.slack.any() for eq in path) == expect_slack, name


def test_load_program_file_node_selection(tmp_path: Path) -> None:
    text = (CONFIG / 'program_side_force.yaml').read_text()
    path = tmp_path / 'two.yaml'
    other = 'other_node:\n  ros__parameters:\n    foo: 1\n'
    path.write_text(other + text.replace('load_program:', '/rig/load_program:'))
    assert load_program_file(path, node='load_program').name == 'side_force'
    with pytest.raises(ParameterError, match='foo'):
        load_program_file(path)  # the first block is not a program
    with pytest.raises(ProgramFileError, match='nodes in file'):
        load_program_file(path, node='missing')
    nested = tmp_path / 'nested.yaml'
    nested.write_text('/**:\n  ros__parameters:\n    name: n\n    segments:\n      kind: [ramp]\n      axis: [fx]\n'
                      '      target: [1]\n      duration: [2]\n    use_sim_time: false\n')
    program = load_program_file(nested, node='load_program')
    assert program.duration_s == 2.0 and program.wrench_at(1.0).wrench[0] == 0.5
    with pytest.raises(ProgramFileError, match='cannot read'):
        load_program_file(tmp_path / 'absent.yaml')
    bad = tmp_path / 'bad.yaml'
    bad.write_text('load_program: [unclosed\n')
    with pytest.raises(ProgramFileError, match='invalid YAML'):
        load_program_file(bad)
    assert issubclass(ProgramFileError, SimError)


def _with(**changes: object) -> dict:
    params = {key: (list(value) if isinstance(value, list) else value) for key, value in PARAMS.items()}
    for key, value in changes.items():
        params[key.replace('__', '.')] = value
    return params


@pytest.mark.parametrize(('params', 'field', 'text'), [
    (_with(segments__kind=['ramp', 'hold', 'step', 'ramp']), 'segments.*', 'equal lengths'),
    (_with(segments__kind=['ramp', 'hold', 'jump', 'ramp', 'step']), 'segments.kind[2]', 'ramp, hold, step'),
    (_with(segments__axis=['fy', 'fy', 'tz', 'fy', 'mz']), 'segments.axis[2]', 'fx, fy, fz, mx, my, mz'),
    (_with(segments__target=[4.0, 4.0, math.nan, -2.0, 0.0]), 'segments.target[2]', 'finite'),
    (_with(segments__target=[4.0, 4.0, '0.2', -2.0, 0.0]), 'segments.target[2]', 'finite number'),
    (_with(segments__duration=[2.0, 0.0, 0.5, 3.0, 0.0]), 'segments.duration[1]', "> 0 for a 'hold'"),
    (_with(segments__duration=[2.0, 1.0, 0.5, 3.0, -0.1]), 'segments.duration[4]', ">= 0 for a 'step'"),
    (_with(segments__target=[4.0, 3.0, 0.2, -2.0, 0.0]), 'segments.target[1]', 'held value 4'),
    (_with(repeats=0), 'repeats', '>= 1'),
    (_with(repeats=1.5), 'repeats', 'integer'),
    (_with(rate_hz=-1.0), 'rate_hz', '> 0'),
    (_with(name=''), 'name', 'non-empty'),
    (_with(segments__kind='ramp'), 'segments.kind', 'list'),
    ({'segments.kind': ['ramp']}, 'segments.axis', 'required'),
    (_with(segment__kind=['ramp']), 'segment.kind', 'unknown'),
])
def test_validation_names_the_field(params: dict, field: str, text: str) -> None:
    with pytest.raises(ParameterError) as info:
        LoadProgram.from_params(params)
    assert info.value.field == field
    assert text in str(info.value)
    assert str(info.value).startswith(f'{field} = ')
    assert isinstance(info.value, ValueError)


def test_hold_after_repeat_is_checked_on_later_repeats() -> None:
    # Valid once: the hold at 0 opens the program, but a second repeat would start at 3 N.
    params = {'segments.kind': ['hold', 'ramp'], 'segments.axis': ['fx', 'fx'], 'segments.target': [0.0, 3.0],
              'segments.duration': [1.0, 1.0]}
    assert LoadProgram.from_params(params).duration_s == 2.0
    with pytest.raises(ParameterError, match=r'segments.target\[0\]'):
        LoadProgram.from_params({**params, 'repeats': 2})
    loose = LoadProgram.from_params({**params, 'frame_id': 'platform'}, strict=False)
    assert loose.name == 'program'
