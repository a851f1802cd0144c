"""A multi-axis design as a load program, and the held steps of a load program.

The existing program kinds express a multi-axis step: every axis keeps its value until a segment moves it, and a
``step`` of 0 s jumps one axis without holding it (crane_stiffness.sim.program). So each held wrench of a design is
six segments, ``step`` on fx, fy, fz, mx, my of 0 s and a ``step`` on mz held ``hold_s``: the six axes jump together
and the model (and an actuator) follow the straight path between the wrenches, which the slack check covers
(crane_stiffness.full6.admissible). The program opens with a zero ``hold`` of ``baseline_s`` and closes with a jump
back to zero held as long. Units N, N·m, s; the paper's fixed frame, z down.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from crane_stiffness.contract.axes import AXES
from crane_stiffness.full6.admissible import wire_label
from crane_stiffness.full6.design import LoadDesign
from crane_stiffness.full6.errors import Full6InputError
from crane_stiffness.sim.program import LoadProgram, Segment

#: Decimals of the loads written to a program file (0.1 mN, 0.1 mN·m).
FILE_DECIMALS = 4


@dataclass(frozen=True)
class HeldStep:
    """A stretch of constant commanded wrench: ``start_s`` to ``end_s`` from the program start [s], ``wrench`` (6,)
    [N, N·m], ``index`` its rank among the program's held steps (0-based)."""

    start_s: float
    end_s: float
    wrench: NDArray[np.float64]
    index: int


def design_program(design: LoadDesign, name: str = 'full6', rate_hz: float = 100.0,
                   decimals: int | None = FILE_DECIMALS) -> LoadProgram:
    """The :class:`~crane_stiffness.sim.program.LoadProgram` of a design (module docstring), its loads rounded to
    ``decimals`` (None: as designed)."""
    steps = design.steps if decimals is None else np.round(design.steps, decimals) + 0.0
    segments = [Segment('hold', AXES[0], 0.0, design.baseline_s)]
    for wrench, hold in [(w, design.hold_s) for w in steps] + [(np.zeros(6), design.baseline_s)]:
        segments += [Segment('step', axis, float(value), 0.0) for axis, value in zip(AXES[:5], wrench[:5])]
        segments.append(Segment('step', AXES[5], float(wrench[5]), hold))
    return LoadProgram(segments, repeats=1, name=name, rate_hz=rate_hz)


def held_steps(program: LoadProgram, settle_s: float = 0.0) -> list[HeldStep]:
    """The stretches of constant wrench of ``program`` (all repeats), in time order, each with its first
    ``settle_s`` seconds left out (a stretch no longer than that is dropped); ramps hold nothing. Neighbouring
    stretches at the same wrench are one. Index counts the stretches kept."""
    if not (math.isfinite(settle_s) and settle_s >= 0.0):
        raise Full6InputError('settle_s', settle_s, 'must be a finite number >= 0 (s)')
    starts = np.cumsum([0.0] + [s.duration_s for s in program.segments])
    cycle = program.cycle_duration_s
    bounds = np.unique(np.concatenate([r * cycle + starts for r in range(program.repeats)]))
    stretches: list[list] = []
    for a, b in zip(bounds[:-1], bounds[1:]):
        state = program.wrench_at(float(a))
        if program.segments[state.segment_index].kind == 'ramp':
            continue
        last = stretches[-1] if stretches else None
        if last is not None and last[1] == a and np.array_equal(last[2], state.wrench):
            last[1] = float(b)
        else:
            stretches.append([float(a), float(b), state.wrench])
    kept = [(a + settle_s, b, w) for a, b, w in stretches if b - a > settle_s]
    return [HeldStep(a, b, w, i) for i, (a, b, w) in enumerate(kept)]


def _flow(items: list[str], indent: int, per_line: int) -> str:
    """A YAML flow sequence of ``items``, ``per_line`` a line, continuation lines indented ``indent`` spaces."""
    lines = [', '.join(items[i:i + per_line]) for i in range(0, len(items), per_line)]
    return '[' + (',\n' + ' ' * indent).join(lines) + ']'


def program_yaml(design: LoadDesign, *, name: str = 'full6', rate_hz: float = 100.0, title: str = '',
                 how: str = '') -> str:
    """The text of a program parameter file (``load_program: ros__parameters:`` as config/program_*.yaml) for
    ``design``: a header (``title``, then how it was made, ``how``) with the table of its steps, then the program,
    one held wrench a line (the baseline's hold on its own first line); then the ``stiffness6_estimator`` section
    (its ``settle_s``), which makes the rig start the 6x6 measurement for the program."""
    program = design_program(design, name, rate_hz)
    params = program.to_params()
    steps = np.round(design.steps, FILE_DECIMALS) + 0.0
    header = [f'# {line}' if line else '#' for line in (title.splitlines() + how.splitlines())]
    header += [f'# Units N, N·m, s; frame: the paper\'s fixed frame, z down. Criterion: {design.criterion}; '
               f'safety factor {design.safety_factor:g};',
               f'# {design.n_steps} steps held {design.hold_s:g} s ({design.settle_s:g} s settling left out of the '
               f'fit) between zero baselines of {design.baseline_s:g} s: {design.duration_s:g} s.',
               '# Peak loads: ' + ', '.join(f'{a} {p:g}' for a, p in zip(AXES, design.peaks)) + ' (N, N·m).',
               '# Each held wrench is six segments: steps of 0 s on fx fy fz mx my (the axes jump together) and a step',
               '# on mz held for the step\'s time. The steps, with the factor at which their direction slackens the',
               '# first wire (crane_stiffness.full6.admissible):',
               '#  step' + ''.join(f'{a:>10}' for a in AXES) + '    factor  wire']
    for i, (w, f, k) in enumerate(zip(steps, design.slack.factor, design.slack.wire)):
        header.append(f'#  {i + 1:4d}' + ''.join(f'{v:10.4f}' for v in w) + f'  {f:8.4f}  {wire_label(int(k))}')
    indent = len('    segments.duration: [')
    out = header + ['load_program:', '  ros__parameters:', f'    name: {name}', f'    rate_hz: {rate_hz!r}',
                    '    repeats: 1']
    formats = (('segments.kind', str), ('segments.axis', str),
               ('segments.target', lambda v: f'{v:{FILE_DECIMALS + 5}.{FILE_DECIMALS}f}'), ('segments.duration', repr))
    for key, fmt in formats:
        items = [fmt(v) for v in params[key]]
        body = _flow(items[1:], indent, 6)[1:]
        label = f'    {key}:'
        out.append(f'{label:<{indent - 1}}[{items[0].strip()},\n' + ' ' * indent + body)
    # The measuring arrangement: the 6x6 fit (and with it the pose sensor) for this program (rig six_axis:=auto).
    out += ['stiffness6_estimator:', '  ros__parameters:', f'    settle_s: {design.settle_s!r}']
    return '\n'.join(out) + '\n'


__all__ = ['FILE_DECIMALS', 'HeldStep', 'design_program', 'held_steps', 'program_yaml']
