"""Load programs: piecewise-linear wrench commands made of ramps, holds and steps, repeated.

A program is a list of segments, each acting on one wrench axis (fx fy fz mx my mz, N or N·m, the paper's fixed
frame with z down), run ``repeats`` times. Every axis starts at 0 and keeps its value until a segment moves it:

- ``ramp``: linear from the axis' value at the segment start to ``target`` over ``duration`` (> 0) s;
- ``hold``: keeps the axis at ``target`` for ``duration`` (> 0) s; ``target`` must equal the value held (it is
  written out so the parameter file reads as a table of levels);
- ``step``: jumps to ``target`` at the segment start and holds it for ``duration`` (≥ 0) s.

A repeat starts from where the previous one ended. Phase at time t: ``'loading'`` while |command| on the
segment's axis increases, ``'unloading'`` while it decreases, ``'hold'`` otherwise (holds, steps, flat ramps).

Parameters are flat parallel arrays so they map onto ROS 2 parameters (see :meth:`LoadProgram.from_params` and
:func:`load_program_file`)::

    load_program:
      ros__parameters:
        name: side_force
        rate_hz: 100.0
        repeats: 1
        segments.kind: [ramp, hold]
        segments.axis: [fy, fy]
        segments.target: [2.0, 2.0]
        segments.duration: [1.0, 1.0]
"""
from __future__ import annotations

import math
from bisect import bisect_right
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from os import PathLike
from pathlib import Path
from typing import Any, Literal

import numpy as np
import yaml
from numpy.typing import NDArray

from crane_stiffness.contract.axes import AXES
from crane_stiffness.params.files import ParamFile, applicable_sections
from crane_stiffness.params.spec import ParamSpec
from crane_stiffness.sim.errors import ParameterError, ProgramFileError

KINDS = ('ramp', 'hold', 'step')
Phase = Literal['loading', 'unloading', 'hold']
PARAM_NAMES = ('name', 'rate_hz', 'repeats', 'segments.kind', 'segments.axis', 'segments.target',
               'segments.duration')
# Set on every ROS 2 node; tolerated so a node's full parameter dict can be passed in.
_IGNORED_PARAMS = ('use_sim_time',)
# Relative tolerance for a hold's target matching the held value.
_HOLD_TOLERANCE = 1e-9


@dataclass(frozen=True, slots=True)
class Segment:
    """One program segment: ``kind`` in KINDS, ``axis`` in AXES, ``target`` in N or N·m, ``duration_s`` in s."""

    kind: str
    axis: str
    target: float
    duration_s: float

    @property
    def axis_index(self) -> int:
        """Index 0..5 of the axis in the wrench [fx, fy, fz, mx, my, mz]."""
        return AXES.index(self.axis)


@dataclass(frozen=True, slots=True)
class ProgramState:
    """Commanded load at one instant.

    Attributes:
        wrench: ``[fx, fy, fz, mx, my, mz]``, N and N·m, fixed frame.
        segment_index: Index of the active segment (the last one once done).
        repeat_index: Index of the active repeat, 0-based (the last one once done).
        phase: 'loading', 'unloading' or 'hold'.
        done: True from ``duration_s`` on.
        progress: Elapsed fraction of the whole program, 0..1.
    """

    wrench: NDArray[np.float64]
    segment_index: int
    repeat_index: int
    phase: Phase
    done: bool
    progress: float


@dataclass(frozen=True, slots=True)
class HoldInterval:
    """A stretch of time during which the program holds one axis at a constant level (for analysis).

    Attributes:
        axis: Axis name.
        level: Held value, N or N·m.
        start_s: Start time from the program start, s.
        end_s: End time, s.
        segment_index: First segment of the stretch.
        repeat_index: Repeat it belongs to.
        approach: 'loading' if the level was reached by increasing |load| on that axis, else 'unloading' (the
            initial zero counts as loading).
    """

    axis: str
    level: float
    start_s: float
    end_s: float
    segment_index: int
    repeat_index: int
    approach: Literal['loading', 'unloading']


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_))


class LoadProgram:
    """A validated load program; see the module docstring for the segment semantics."""

    def __init__(self, segments: Sequence[Segment], repeats: int = 1, name: str = 'program',
                 rate_hz: float = 100.0) -> None:
        """Create and validate a program.

        Args:
            segments: At least one segment.
            repeats: Times the segment list is run, integer ≥ 1.
            name: Label, non-empty.
            rate_hz: Rate at which a node publishes the command, Hz, > 0 (also the default of :meth:`sample`).

        Raises:
            ParameterError: Naming the field (``segments.duration[3]`` etc.), the value and the rule.
        """
        if not isinstance(name, str) or not name:
            raise ParameterError('name', name, 'must be a non-empty string')
        if isinstance(repeats, (bool, np.bool_)) or not isinstance(repeats, (int, np.integer)) or repeats < 1:
            raise ParameterError('repeats', repeats, 'must be an integer >= 1')
        if not _is_number(rate_hz) or not math.isfinite(rate_hz) or rate_hz <= 0.0:
            raise ParameterError('rate_hz', rate_hz, 'must be a finite number > 0 (Hz)')
        segments = tuple(segments)
        if not segments:
            raise ParameterError('segments.kind', [], 'must hold at least one segment')
        for i, seg in enumerate(segments):
            if seg.kind not in KINDS:
                raise ParameterError(f'segments.kind[{i}]', seg.kind, f'must be one of {", ".join(KINDS)}')
            if seg.axis not in AXES:
                raise ParameterError(f'segments.axis[{i}]', seg.axis, f'must be one of {", ".join(AXES)}')
            if not _is_number(seg.target) or not math.isfinite(seg.target):
                raise ParameterError(f'segments.target[{i}]', seg.target, 'must be a finite number (N or N·m)')
            if not _is_number(seg.duration_s) or not math.isfinite(seg.duration_s):
                raise ParameterError(f'segments.duration[{i}]', seg.duration_s, 'must be a finite number (s)')
            if seg.kind == 'step':
                if seg.duration_s < 0.0:
                    raise ParameterError(f'segments.duration[{i}]', seg.duration_s,
                                         "must be >= 0 for a 'step' (hold time after the jump)")
            elif seg.duration_s <= 0.0:
                raise ParameterError(f'segments.duration[{i}]', seg.duration_s, f"must be > 0 for a '{seg.kind}'")
        self._segments = tuple(Segment(s.kind, s.axis, float(s.target), float(s.duration_s)) for s in segments)
        self._repeats = int(repeats)
        self._name = name
        self._rate_hz = float(rate_hz)
        self._starts = [0.0]
        for seg in self._segments:
            self._starts.append(self._starts[-1] + seg.duration_s)
        self._cycle_s = self._starts[-1]
        if self._cycle_s <= 0.0:
            raise ParameterError('segments.duration', [s.duration_s for s in self._segments],
                                 'must add up to more than 0 s')
        # Wrench at each segment start for the first repeat (from zero) and for the later ones (from the end of
        # a repeat); all later repeats start alike.
        first_starts, first_end = self._start_values(np.zeros(6))
        later_starts, later_end = first_starts, first_end
        if self._repeats > 1:
            later_starts, later_end = self._start_values(first_end)
        self._start_table = [first_starts, later_starts]
        self._final = later_end

    def _start_values(self, initial: NDArray[np.float64]) -> tuple[list[NDArray[np.float64]], NDArray[np.float64]]:
        wrench = initial.copy()
        starts = []
        for i, seg in enumerate(self._segments):
            starts.append(wrench.copy())
            j = seg.axis_index
            held = wrench[j]
            if seg.kind == 'hold' and abs(seg.target - held) > _HOLD_TOLERANCE * max(1.0, abs(held)):
                raise ParameterError(f'segments.target[{i}]', seg.target,
                                     f"must equal the held value {held:g} of {seg.axis} for a 'hold' "
                                     "(use a ramp or a step to change it)")
            wrench[j] = seg.target
        return starts, wrench

    @classmethod
    def from_params(cls, params: Mapping[str, Any], *, strict: bool = True) -> LoadProgram:
        """Build from ROS-style parameters (parallel arrays; see the module docstring).

        Args:
            params: Keys ``segments.kind`` [str], ``segments.axis`` [str], ``segments.target`` [float, N or N·m],
                ``segments.duration`` [float, s] (all required, equal lengths), ``repeats`` (int ≥ 1, default 1),
                ``name`` (str, default 'program'), ``rate_hz`` (float > 0, default 100). Integers are accepted
                for the float arrays.
            strict: Reject keys that are not program parameters (``use_sim_time`` and how the load is applied,
                :data:`LOAD_APPLICATION_PARAMS`, are always accepted: a program file may say so).

        Raises:
            ParameterError: Naming the field, the value and the rule.
        """
        if strict:
            for key in params:
                if key not in PARAM_NAMES and key not in _IGNORED_PARAMS and key not in LOAD_APPLICATION_KEYS:
                    raise ParameterError(str(key), params[key],
                                         f'unknown load-program parameter; known: {", ".join(PARAM_NAMES)}')
        arrays: dict[str, list[Any]] = {}
        for key in ('segments.kind', 'segments.axis', 'segments.target', 'segments.duration'):
            if key not in params:
                raise ParameterError(key, None, 'is required')
            value = params[key]
            # Any sequence will do: rclpy returns array.array for double arrays.
            if isinstance(value, (str, bytes, Mapping)) or not hasattr(value, '__len__'):
                raise ParameterError(key, value, 'must be a list')
            arrays[key] = list(value)
        lengths = {key: len(value) for key, value in arrays.items()}
        if len(set(lengths.values())) != 1:
            raise ParameterError('segments.*', lengths, 'the four segments arrays must have equal lengths')
        for key in ('segments.kind', 'segments.axis'):
            for i, item in enumerate(arrays[key]):
                if not isinstance(item, str):
                    raise ParameterError(f'{key}[{i}]', item, 'must be a string')
        segments = [Segment(kind, axis, target, duration) for kind, axis, target, duration in
                    zip(arrays['segments.kind'], arrays['segments.axis'], arrays['segments.target'],
                        arrays['segments.duration'])]
        return cls(segments, repeats=params.get('repeats', 1), name=params.get('name', 'program'),
                   rate_hz=params.get('rate_hz', 100.0))

    def to_params(self) -> dict[str, Any]:
        """The parameters :meth:`from_params` takes, as plain Python values."""
        return {
            'name': self._name,
            'rate_hz': self._rate_hz,
            'repeats': self._repeats,
            'segments.kind': [s.kind for s in self._segments],
            'segments.axis': [s.axis for s in self._segments],
            'segments.target': [s.target for s in self._segments],
            'segments.duration': [s.duration_s for s in self._segments],
        }

    @property
    def name(self) -> str:
        """Program label."""
        return self._name

    @property
    def rate_hz(self) -> float:
        """Command rate, Hz."""
        return self._rate_hz

    @property
    def repeats(self) -> int:
        """Number of repeats."""
        return self._repeats

    @property
    def segments(self) -> tuple[Segment, ...]:
        """The segments of one repeat."""
        return self._segments

    @property
    def cycle_duration_s(self) -> float:
        """Duration of one repeat, s."""
        return self._cycle_s

    @property
    def duration_s(self) -> float:
        """Duration of the whole program, s."""
        return self._cycle_s * self._repeats

    def wrench_at(self, t_s: float) -> ProgramState:
        """Command at ``t_s`` seconds from the program start.

        Segments are half-open ``[start, end)``: at a boundary the next segment is active. Before 0 the state is
        the zero wrench of segment 0; from ``duration_s`` on it is the final wrench with ``done=True``.
        """
        t = float(t_s)
        if math.isnan(t):
            raise ParameterError('t_s', t_s, 'must not be NaN')
        total = self.duration_s
        if t >= total:
            return ProgramState(self._final.copy(), len(self._segments) - 1, self._repeats - 1, 'hold', True, 1.0)
        if t < 0.0:
            return ProgramState(np.zeros(6), 0, 0, 'hold', False, 0.0)
        repeat = min(int(t // self._cycle_s), self._repeats - 1)
        local = t - repeat * self._cycle_s
        # bisect_right skips zero-duration steps: their start equals the next segment's start.
        i = min(bisect_right(self._starts, local) - 1, len(self._segments) - 1)
        seg = self._segments[i]
        wrench = self._start_table[min(repeat, 1)][i].copy()
        j = seg.axis_index
        phase: Phase = 'hold'
        if seg.kind == 'ramp':
            start_value = wrench[j]
            value = start_value + (seg.target - start_value) * (local - self._starts[i]) / seg.duration_s
            wrench[j] = value
            rate = seg.target - start_value
            if rate != 0.0:
                # d|v|/dt = sign(v)·dv/dt; at v = 0 any motion moves away from zero.
                phase = 'loading' if value == 0.0 or (value > 0.0) == (rate > 0.0) else 'unloading'
        else:
            wrench[j] = seg.target
        return ProgramState(wrench, i, repeat, phase, False, t / total)

    def sample(self, rate_hz: float | None = None) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Command sampled from 0 to ``duration_s`` inclusive at ``rate_hz`` (default: the program's rate).

        Returns:
            ``(t_s, wrench)`` with shapes (n,) and (n, 6).
        """
        rate = self._rate_hz if rate_hz is None else float(rate_hz)
        if not (math.isfinite(rate) and rate > 0.0):
            raise ParameterError('rate_hz', rate_hz, 'must be a finite number > 0 (Hz)')
        n = int(math.floor(self.duration_s * rate + 1e-9)) + 1
        t = np.arange(n) / rate
        return t, np.array([self.wrench_at(ti).wrench for ti in t])

    def holds(self, axis: str | None = None) -> list[HoldInterval]:
        """Intervals of constant command on the segments' axes, in time order; consecutive holds and steps at
        the same level on the same axis are merged. ``axis`` filters by axis name."""
        if axis is not None and axis not in AXES:
            raise ParameterError('axis', axis, f'must be one of {", ".join(AXES)}')
        intervals: list[HoldInterval] = []
        approach: dict[str, Literal['loading', 'unloading']] = {name: 'loading' for name in AXES}
        for repeat in range(self._repeats):
            for i, seg in enumerate(self._segments):
                start_value = self._start_table[min(repeat, 1)][i][seg.axis_index]
                if abs(seg.target) != abs(start_value):
                    approach[seg.axis] = 'loading' if abs(seg.target) > abs(start_value) else 'unloading'
                if seg.kind == 'ramp' or seg.duration_s == 0.0:
                    continue
                start = repeat * self._cycle_s + self._starts[i]
                last = intervals[-1] if intervals else None
                if last is not None and last.axis == seg.axis and last.level == seg.target \
                        and math.isclose(last.end_s, start, rel_tol=1e-12, abs_tol=1e-12):
                    intervals[-1] = HoldInterval(last.axis, last.level, last.start_s, start + seg.duration_s,
                                                 last.segment_index, last.repeat_index, last.approach)
                else:
                    intervals.append(HoldInterval(seg.axis, seg.target, start, start + seg.duration_s, i, repeat,
                                                  approach[seg.axis]))
        return [h for h in intervals if axis is None or h.axis == axis]

    def levels(self, axis: str | None = None) -> NDArray[np.float64]:
        """Distinct held levels (N or N·m), sorted ascending; ``axis`` filters by axis name."""
        return np.unique([h.level for h in self.holds(axis)])

    def __repr__(self) -> str:
        return (f'LoadProgram(name={self._name!r}, segments={len(self._segments)}, repeats={self._repeats}, '
                f'duration_s={self.duration_s:g})')


def load_program_file(path: str | PathLike[str], node: str | None = None, *, strict: bool = True) -> LoadProgram:
    """Read a load program from a ROS 2 parameter YAML file.

    Args:
        path: The YAML file (``<node>: {ros__parameters: {...}}``).
        node: Node whose parameters to use: its name (in any namespace) or fully qualified name; the sections that
            apply to it are merged as ROS merges them (wildcards such as ``/**`` first; see
            crane_stiffness.params.files). None: the first block in the file.
        strict: Passed to :meth:`LoadProgram.from_params`.

    Raises:
        ProgramFileError: Unreadable file, invalid YAML, or no matching ``ros__parameters`` block.
        ParameterError: Invalid program parameters.
    """
    path = Path(path)
    try:
        file = ParamFile.read(path)
    except OSError as exc:
        raise ProgramFileError(f'{path}: cannot read: {exc}') from exc
    except yaml.YAMLError as exc:
        raise ProgramFileError(f'{path}: invalid YAML: {exc}') from exc
    blocks = [key for key, params in file.sections.items() if params is not None]
    if not blocks:
        raise ProgramFileError(f'{path}: no "<node>: ros__parameters:" block found')
    keys = blocks[:1] if node is None else applicable_sections(blocks, node)
    if not keys:
        raise ProgramFileError(f'{path}: no parameters for node {node!r}; nodes in file: {", ".join(blocks)}')
    return LoadProgram.from_params(file.params(keys), strict=strict)


#: A load program's parameters, declared once (the load_program node declares them, the session recorder records
#: them; a program file holds them under ``load_program``).
PROGRAM_PARAMS: tuple[ParamSpec, ...] = (
    ParamSpec('name', 'hold_zero', 'program name, recorded with the session'),
    ParamSpec('rate_hz', 100.0, 'command publication rate [Hz]', above=0.0),
    ParamSpec('repeats', 1, 'how many times the segment list is played (>= 1)', low=1),
    ParamSpec('segments.kind', ['hold'], 'segment kinds: ramp | hold | step'),
    ParamSpec('segments.axis', ['fy'], 'segment axes: fx fy fz [N] or mx my mz [N·m], fixed frame (z down)'),
    ParamSpec('segments.target', [0.0], 'segment end values [N or N·m]'),
    ParamSpec('segments.duration', [1.0], 'segment durations [s]',
              rule='one per segment; kind, axis, target and duration lists have the same length'),
)
#: Their names.
PROGRAM_KEYS = tuple(spec.name for spec in PROGRAM_PARAMS)


# ------------------------------------------------------------------------------------------- load application --
#: How the commanded load reaches the crane: ``model`` the simulated crane (crane_model applies the command),
#: ``operator`` a person hangs weights or sets a screw at each new level when the program asks and confirms (or the
#: measured load settles at the level), ``actuator`` a driver of a loading actuator subscribed to
#: /crane/wrench_command applies it. Only ``operator`` changes how the program plays.
LOAD_APPLICATIONS = ('model', 'operator', 'actuator')
#: The unit of each axis' level, for the operator's prompt.
AXIS_UNITS = {'fx': 'N', 'fy': 'N', 'fz': 'N', 'mx': 'N·m', 'my': 'N·m', 'mz': 'N·m'}

#: How the load reaches the crane and the unloaded-state tare, declared once (the load_program node declares them;
#: the recorder reads them back with the node's parameters, so the session record holds them).
LOAD_APPLICATION_PARAMS: tuple[ParamSpec, ...] = (
    ParamSpec('load_application', 'model', 'how the commanded load reaches the crane: model = the simulated crane '
              '(crane_model applies each command); operator = a person applies each new level the program names '
              '(on /load_program/state) and the program holds there until ~/confirm is called or the measured '
              'load settles at it (operator_settle_s); actuator = a loading actuator\'s driver subscribed to '
              '/crane/wrench_command applies it [-]', choices=LOAD_APPLICATIONS,
              rule='operator: wall-clock time only'),
    ParamSpec('operator_tolerance', 0.05, "load_application operator: the measured load's component on the level's "
              'axis (/load_cell/wrench, in the sensor\'s frame: mount it aligned with crane_base) counts as at the '
              'level within this [N or N·m]', above=0.0),
    ParamSpec('operator_settle_s', 0.0, 'load_application operator: the level counts as applied once the measured '
              'load has stayed within operator_tolerance of it this long; 0 = only a ~/confirm call confirms [s]',
              low=0.0, high=3600.0),
    ParamSpec('tare_services', [''], 'std_srvs/Trigger services called in turn at the unloaded state just before '
              "the program's first step (e.g. /netft/tare, /modbus_lvdt/zero); their answers are published with "
              "the program's state and so kept in the session record; the program does not start when one fails; "
              "[''] = none [-]", rule='wall-clock time only'),
    ParamSpec('operator', '', 'who runs the test, recorded with the tare and each confirmed level; empty = the '
              "login name of the node's process [-]"),
)


@dataclass(frozen=True, slots=True)
class LoadPrompt:
    """A new level the operator applies (load_application operator): at program time ``time_s`` [s] the command
    reaches ``level`` [N or N·m] on ``axis``; ``wrench`` is the whole commanded wrench then ([fx fy fz] N,
    [mx my mz] N·m, fixed frame)."""

    index: int
    time_s: float
    axis: str
    level: float
    wrench: tuple[float, ...]

    def text(self, total: int) -> str:
        """The instruction, e.g. 'level 2/11: set fy = 0.8 N (every other axis as it is)'."""
        others = [f'{a} = {v:g} {AXIS_UNITS[a]}' for a, v in zip(AXES, self.wrench) if a != self.axis and v != 0.0]
        return (f'level {self.index + 1}/{total}: set {self.axis} = {self.level:g} {AXIS_UNITS[self.axis]} ('
                + ('with ' + ', '.join(others) if others else 'every other axis unloaded') + ')')


def load_prompts(program: LoadProgram) -> list[LoadPrompt]:
    """Where the command reaches a new level, in program order over every repeat: at the start of a step, at the
    end of a ramp (the command ramps meanwhile, so an operator applying it by hand is told at once and the program
    holds at the ramp's end until the level is confirmed). A segment that leaves its axis' value unchanged (a hold,
    a flat ramp) asks for nothing."""
    prompts: list[LoadPrompt] = []
    wrench = [0.0] * len(AXES)
    t = 0.0
    for _ in range(program.repeats):
        for seg in program.segments:
            j = seg.axis_index
            changed = seg.kind in ('step', 'ramp') and seg.target != wrench[j]
            if changed:
                wrench[j] = seg.target
                at = t if seg.kind == 'step' else t + seg.duration_s
                prompts.append(LoadPrompt(len(prompts), at, seg.axis, seg.target, tuple(wrench)))
            t += seg.duration_s
    return prompts


class Settling:
    """Whether a measured value has stayed within ``tolerance`` of ``target`` for ``hold_s`` [s] (samples in time
    order; a sample outside the band starts the wait again)."""

    def __init__(self, target: float, tolerance: float, hold_s: float) -> None:
        self.target, self.tolerance, self.hold_s = float(target), float(tolerance), float(hold_s)
        self._since: float | None = None

    def update(self, t_s: float, value: float) -> bool:
        """Feed the sample ``value`` at time ``t_s`` [s]; True once settled."""
        if not (math.isfinite(value) and abs(value - self.target) <= self.tolerance):
            self._since = None
            return False
        if self._since is None:
            self._since = t_s
        return t_s - self._since >= self.hold_s
#: Their names.
LOAD_APPLICATION_KEYS = tuple(spec.name for spec in LOAD_APPLICATION_PARAMS)
