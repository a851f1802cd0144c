"""A test campaign as a file: the paper's matrix of sessions, read and checked, and expanded into its sessions.

The file is a ROS 2 parameter YAML with one section, ``campaign`` (see config/campaign_paper.yaml)::

    campaign:
      ros__parameters:
        name: paper
        crane: crane_lab.yaml                 # the nominal crane (geometry file)
        series: [fy, fz, mz]                  # side force, vertical force, moment about z (full: the 6×6)
        programs: [campaign_side_force, campaign_force_z, campaign_moment_z]   # one per series (full: design)
        weights: [25.0, 50.0, 100.0]          # W [N]
        lengths: [0.5, 1.5]                   # l0 [m] (or heights: h [m])
        repeats: 1
        load_fraction: 0.5                    # side-force/moment peak: this fraction of the first-slack load
        true.wire_stiffness_factor: 1.0       # simulated rig only: the true crane against the nominal
        true.weight_factor: 1.0
        true.crane: nominal                   # or drawn: each session's true crane drawn from true.uncertainty
        sensor_parameters: none               # or a file of node sections set on top of the sensors' parameters

The series ``full`` measures the whole 6×6 stiffness of every set-up in one designed multi-axis test
(crane_stiffness.campaign.full_series): its program is ``design`` (the D-optimal program of each set-up, made from
the ``design.*`` keys) or a six-axis program file, checked against every set-up's slack margins.

Every key is declared once in :data:`CAMPAIGN_PARAMS` (default, unit, rule). :func:`load_campaign` raises
:class:`~crane_stiffness.campaign.errors.CampaignFileError` naming the file and the key for an unknown key, a
value against its rule (a negative weight), a list of the wrong length or a program file that does not exist.

:func:`plan_sessions` expands a campaign into its sessions, in run order (series, length, weight, repeat), each
with the nominal geometry parameters the analysis uses and the true ones the simulated crane runs with. No ROS.
"""
from __future__ import annotations

import hashlib
import json
import math
import os
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Mapping

from crane_stiffness.campaign.errors import CampaignFileError
from crane_stiffness.campaign.full_series import DESIGN, FULL, DesignSettings, full_program
from crane_stiffness.errors import ParameterError
from crane_stiffness.params.errors import ConfigError
from crane_stiffness.params.files import ParamFile, config_path, load_params, load_yaml, share_dir
from crane_stiffness.params.geometry import geometry_from_params, geometry_to_params
from crane_stiffness.params.spec import ParamSpec, check_spec, is_number
from crane_stiffness.launcher.rig_description import is_six_axis_program
from crane_stiffness.sim.program import load_program_file

SECTION = 'campaign'
#: The series a campaign can run, by loaded axis, and their names in the paper.
SERIES = {'fy': 'side force', 'fz': 'vertical force', 'mz': 'moment about z', 'full': 'whole 6x6 stiffness'}

#: The keys of a campaign file, declared once (default, description with unit, rule).
CAMPAIGN_PARAMS: tuple[ParamSpec, ...] = (
    ParamSpec('name', 'campaign', 'campaign name, recorded with every session [-]'),
    ParamSpec('crane', 'crane_lab.yaml', 'the nominal crane: a geometry parameter file, a name in the installed '
              'config/ or a path (relative to the campaign file) [-]'),
    ParamSpec('series', ['fy'], 'the test series by loaded axis: fy (side force), fz (vertical force), mz (moment '
              'about z), or full (the whole 6x6 stiffness from one multi-axis test) [-]',
              rule='each one of fy, fz, mz, full, no repeats'),
    ParamSpec('programs', ['side_force'], 'the program of each series: program_<name>.yaml in the installed config/, '
              'or a path to a program file (relative to the campaign file); for full: design (each set-up\'s '
              'D-optimal program, design.*) or a six-axis program [-]', rule='one per series'),
    ParamSpec('weights', [50.0], 'suspended weights W [N]', rule='at least one; each >= 0'),
    ParamSpec('lengths', [0.0], "unstretched wire lengths l0; [0.0] = use 'heights' [m]",
              rule="each > 0; exactly one of lengths and heights given"),
    ParamSpec('heights', [0.0], "unloaded heights h between the triangles; [0.0] = use 'lengths' [m]",
              rule="each > 0; exactly one of lengths and heights given"),
    ParamSpec('repeats', 1, 'sessions per series, weight and length [-]', low=1),
    ParamSpec('load_fraction', 0.5, "peak of a side-force or moment program as a fraction of the load at which the "
              "nominal crane's first wire goes slack (the program's levels scaled to it); 0 = the levels as "
              'written [-]', low=0.0, high=0.95),
    ParamSpec('seed', 1, "simulated sensors only: the noise seed of the campaign; session i's load cell takes "
              'seed + 2·i, its LVDT seed + 2·i + 1 and (series full) its pose sensor seed + 2·n + i of n sessions, so '
              'the campaign gives the same numbers in every run on simulated time; -1 = fresh noise in every '
              'session [-]', low=-1),
    ParamSpec('design.steps', 24, "series full, program design: held steps of each set-up's D-optimal program "
              '(even; at least 8 fold-over pairs: six pairs alone fit C exactly from their differences and leave '
              "the lack-of-fit test blind to the response's odd-order bend) [-]", low=16),
    ParamSpec('design.hold_s', 4.0, 'series full, program design: time each step is held [s]', above=0.0),
    ParamSpec('design.settle_s', 0.5, 'series full, program design: first part of each hold left out of the 6x6 '
              'fit [s]', low=0.0),
    ParamSpec('design.baseline_s', 2.0, 'series full, program design: zero-load baseline at each end [s]',
              above=0.0),
    ParamSpec('design.safety_factor', 2.0, 'series full: every held wrench (and the path between two) could grow '
              'this many times before a wire goes slack, on every set-up [-]', low=1.0),
    ParamSpec('design.peak_fraction', 0.98, "series full, program design: each axis' peak as this fraction of its "
              'largest admissible load alone at the set-up [-]', above=0.0, high=1.0),
    ParamSpec('design.seed', 0, "series full, program design: seed of the design's random starts [-]", low=0),
    ParamSpec('design.full_scale_fraction', 0.9, "series full, program design: each axis' peak at most this fraction "
              "of the load cell's full scale (config/sensors.yaml, load_cell.full_scale) [-]", above=0.0, high=1.0),
    ParamSpec('design.max_lack_of_fit', 1.2, 'series full, program design: the design scaled down until the lack-of-'
              'fit statistic the nonlinear model predicts for it is at most this (1 = a linear response; the 6x6 '
              'status turns WARN near 1.4) [-]', above=1.0),
    ParamSpec('true.wire_stiffness_factor', 1.0, "simulated rig only: the true crane's wire stiffness k (E·A) over "
              'the nominal one [-]', above=0.0),
    ParamSpec('true.weight_factor', 1.0, "simulated rig only: the true crane's weight over the nominal W [-]",
              above=0.0),
    ParamSpec('true.crane', 'nominal', "simulated rig only: nominal (the true crane is the nominal one, scaled by "
              "true.*_factor) or drawn (each session's true crane drawn from the inputs' uncertainties of "
              'true.uncertainty, seeded by seed: a coverage study of the prediction) [-]',
              choices=('nominal', 'drawn')),
    ParamSpec('true.uncertainty', 'uncertainty_lab.yaml', "true.crane drawn: the crane inputs' uncertainties the "
              'true cranes are drawn from (a file as crane-stiffness analyze --uncertainty reads; a name in the '
              'installed config/ or a path relative to the campaign file) [-]'),
    ParamSpec('sensor_parameters', 'none', 'simulated rig only: a ROS parameter file whose node sections (load_cell, '
              "lvdt, ...) are set on top of the rig's own sensor parameters in every session (true calibration "
              'errors, coloured noise); a node it sets to truth.mode drawn gets its own truth.seed per session '
              '(its noise seed); none = nothing on top [-]'),
)
_SPECS = {spec.name: spec for spec in CAMPAIGN_PARAMS}
#: The simulated sensors a campaign's sensor_parameters may set (each takes a noise seed per session).
SENSOR_NODES = ('load_cell', 'lvdt', 'pose_sensor')


@dataclass(frozen=True)
class Campaign:
    """A checked campaign file. Lengths in m, weights in N."""

    path: Path
    name: str
    crane: Path
    series: tuple[str, ...]
    programs: tuple[Path, ...]
    weights: tuple[float, ...]
    lengths: tuple[float, ...]
    """l0 of each set-up; empty when the file gives heights."""
    heights: tuple[float, ...]
    """h of each set-up; empty when the file gives lengths."""
    repeats: int
    load_fraction: float
    seed: int
    """The simulated sensors' noise seed of the campaign (-1: fresh noise)."""
    design: DesignSettings
    """Series full with program design: the program designed for each set-up."""
    true_wire_stiffness_factor: float
    true_weight_factor: float
    true_crane: str = 'nominal'
    """'nominal', or 'drawn': each session's true crane drawn from :attr:`true_uncertainty` (:mod:`.true_draw`)."""
    true_uncertainty: Path | None = None
    """The crane inputs' uncertainty file the true cranes are drawn from (true_crane 'drawn')."""
    sensor_parameters: dict[str, dict[str, Any]] = field(default_factory=dict)
    """Parameters by node set on top of the rig's sensor parameters in every session (simulated rig)."""

    @property
    def true_differs(self) -> bool:
        """The simulated crane is not the nominal one."""
        return self.true_wire_stiffness_factor != 1.0 or self.true_weight_factor != 1.0 or self.true_crane != 'nominal'


@dataclass(frozen=True)
class SessionPlan:
    """One session of a campaign: what the operator sets up, what the simulated crane is, what the analysis uses."""

    index: int
    id: str
    series: str
    program: str
    """The program file as the campaign gives it, or 'design' (the runner writes its scaled or designed copy beside
    the session)."""
    program_scale: float
    """Factor on the program's levels (and the estimator's hysteresis) for this set-up; 1 = as written."""
    weight: float
    l0: float
    height: float
    repeat: int
    nominal: dict[str, Any]
    """Every geometry.* parameter of the nominal crane of this set-up (the model the analysis uses)."""
    true: dict[str, Any]
    """Every geometry.* parameter of the crane the simulated rig runs (= nominal unless the campaign sets true.*)."""
    seeds: dict[str, int] | None = None
    """The simulated sensors' noise seeds by node (load_cell, lvdt, and pose_sensor in series full); None: fresh
    noise."""
    program_text: str | None = None
    """Series full with program design: the program file designed for this set-up (YAML text)."""
    parameters: dict[str, dict[str, Any]] | None = None
    """Parameters by node set on the simulated rig's nodes in this session beyond the rig's own (the campaign's
    sensor_parameters, a drawn truth's truth.seed); None: none."""

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def _fail(path: Path, key: str, value: Any, rule: str) -> CampaignFileError:
    return CampaignFileError(f'{path}: {key} = {value!r}: {rule}')


def _resolve(path: Path, value: str) -> Path:
    """A file named in the campaign: a path relative to the campaign file when it exists there, else a name in the
    installed config/."""
    local = (path.parent / value)
    if local.is_file():
        return local
    return config_path(value)


def _program_path(path: Path, value: str) -> Path:
    if value.endswith('.yaml'):
        local = path.parent / value
        return local if local.is_file() else Path(value)
    return share_dir() / 'config' / f'program_{value}.yaml'


def _numbers(path: Path, key: str, value: Any) -> tuple[float, ...]:
    if not isinstance(value, list) or not value or not all(is_number(v) for v in value):
        raise _fail(path, key, value, 'must be a non-empty list of numbers')
    return tuple(float(v) for v in value)


def load_campaign(path: str | os.PathLike) -> Campaign:
    """Read and check a campaign file (see the module docstring). Raises CampaignFileError naming file and key."""
    path = Path(path)
    try:
        file = ParamFile.read(path)
    except OSError as exc:
        raise CampaignFileError(f'{path}: cannot read: {exc.strerror or exc}') from None
    except Exception as exc:  # yaml.YAMLError and its kin
        raise CampaignFileError(f'{path}: not valid YAML: {exc}') from None
    if not file.is_mapping or set(file.sections) != {SECTION} or file.sections[SECTION] is None:
        found = ', '.join(file.sections) if file.is_mapping else 'no mapping'
        raise CampaignFileError(f'{path}: expected exactly one section "{SECTION}: ros__parameters: ..." '
                                f'(found: {found})')
    given = file.params([SECTION])
    unknown = sorted(set(given) - set(_SPECS))
    if unknown:
        raise CampaignFileError(f'{path}: unknown key {unknown[0]!r} (known: {", ".join(_SPECS)})')
    values = {name: given.get(name, spec.default) for name, spec in _SPECS.items()}
    for name, spec in _SPECS.items():
        value = values[name]
        if isinstance(spec.default, str) and (not isinstance(value, str) or not value):
            raise _fail(path, name, value, 'must be a non-empty string')
        if isinstance(spec.default, (int, float)) and not is_number(value):
            raise _fail(path, name, value, 'must be a number')
        if isinstance(spec.default, int) and not isinstance(spec.default, bool) and not isinstance(value, int):
            raise _fail(path, name, value, 'must be an integer')
        try:
            check_spec(spec, value)
        except ParameterError as exc:
            raise CampaignFileError(f'{path}: {exc}') from None
    series = values['series']
    if not isinstance(series, list) or not series:
        raise _fail(path, 'series', series, 'must be a non-empty list of fy, fz, mz')
    for i, s in enumerate(series):
        if s not in SERIES:
            raise _fail(path, f'series[{i}]', s, 'must be one of fy, fz, mz, full')
    if len(set(series)) != len(series):
        raise _fail(path, 'series', series, 'must not name a series twice')
    programs = values['programs']
    if not isinstance(programs, list) or len(programs) != len(series):
        raise _fail(path, 'programs', programs, f'must be a list of {len(series)} program(s), one per series')
    program_paths = []
    for i, (axis, name) in enumerate(zip(series, programs)):
        if not isinstance(name, str) or not name:
            raise _fail(path, f'programs[{i}]', name, 'must be a program name or file')
        if axis == FULL and name == DESIGN:
            program_paths.append(Path(DESIGN))
            continue
        program = _program_path(path, name)
        if not program.is_file():
            raise _fail(path, f'programs[{i}]', name, f'no program file {program}')
        try:
            loaded = load_program_file(program, 'load_program')
        except (ValueError, CampaignFileError, ConfigError) as exc:
            raise _fail(path, f'programs[{i}]', name, f'not a valid program: {exc}') from None
        axes = {s.axis for s in loaded.segments if s.target != 0.0}
        if axis == FULL:
            if not is_six_axis_program(program):
                raise _fail(path, f'programs[{i}]', name, 'is not a six-axis program (no stiffness6_estimator '
                            'section): give design, or a program made by crane-stiffness full6 design')
        elif axes != {axis}:
            raise _fail(path, f'programs[{i}]', name, f'loads {", ".join(sorted(axes)) or "nothing"}, not the '
                        f'series {axis}')
        program_paths.append(program)
    weights = _numbers(path, 'weights', values['weights'])
    for i, w in enumerate(weights):
        if not math.isfinite(w) or w < 0.0:
            raise _fail(path, f'weights[{i}]', w, 'must be >= 0 [N]')
    lengths = _numbers(path, 'lengths', values['lengths'])
    heights = _numbers(path, 'heights', values['heights'])
    lengths = () if lengths == (0.0,) else lengths
    heights = () if heights == (0.0,) else heights
    if bool(lengths) == bool(heights):
        raise _fail(path, 'lengths', list(lengths), 'give exactly one of lengths and heights')
    for key, seq in (('lengths', lengths), ('heights', heights)):
        for i, v in enumerate(seq):
            if not math.isfinite(v) or v <= 0.0:
                raise _fail(path, f'{key}[{i}]', v, 'must be > 0 [m]')
    crane = values['crane']
    try:
        crane_path = _resolve(path, crane)
        load_params(crane_path)
    except ConfigError as exc:
        raise _fail(path, 'crane', crane, str(exc)) from None
    uncertainty = None
    if values['true.crane'] == 'drawn':
        uncertainty = _true_uncertainty(path, values['true.uncertainty'], crane_path)
    sensors: dict[str, dict[str, Any]] = {}
    if values['sensor_parameters'] != 'none':
        sensors = _sensor_parameters(path, values['sensor_parameters'])
    return Campaign(path=path, name=values['name'], crane=crane_path, series=tuple(series),
                    programs=tuple(program_paths), weights=weights, lengths=lengths, heights=heights,
                    repeats=int(values['repeats']), load_fraction=float(values['load_fraction']),
                    seed=int(values['seed']), design=_design_settings(path, values),
                    true_wire_stiffness_factor=float(values['true.wire_stiffness_factor']),
                    true_weight_factor=float(values['true.weight_factor']), true_crane=values['true.crane'],
                    true_uncertainty=uncertainty, sensor_parameters=sensors)


def _true_uncertainty(path: Path, value: str, crane: Path) -> Path:
    """The uncertainty file the true cranes are drawn from, checked against the crane it scatters."""
    from crane_stiffness.campaign.true_draw import check_uncertainty_file
    try:
        found = _resolve(path, value)
        check_uncertainty_file(found, crane)
    except (ConfigError, ParameterError, ValueError) as exc:
        raise _fail(path, 'true.uncertainty', value, str(exc)) from None
    return found


def _sensor_parameters(path: Path, value: str) -> dict[str, dict[str, Any]]:
    """The node sections of the campaign's sensor_parameters file: {node: {parameter: value}}."""
    try:
        file = ParamFile.read(_resolve(path, value))
    except (OSError, ConfigError) as exc:
        raise _fail(path, 'sensor_parameters', value, f'cannot read: {exc}') from None
    except Exception as exc:  # yaml.YAMLError and its kin
        raise _fail(path, 'sensor_parameters', value, f'not valid YAML: {exc}') from None
    if not file.is_mapping or not file.sections:
        raise _fail(path, 'sensor_parameters', value, 'must hold node sections "<node>: ros__parameters: ..."')
    out = {}
    for node in file.sections:
        params = file.params([node])
        if node not in SENSOR_NODES or not params:
            raise _fail(path, 'sensor_parameters', value, f'section {node!r}: must be one of '
                        f'{", ".join(SENSOR_NODES)} with its parameters')
        out[node] = params
    return out


def _design_settings(path: Path, values: Mapping[str, Any]) -> DesignSettings:
    steps = int(values['design.steps'])
    if steps % 2:
        raise _fail(path, 'design.steps', steps, 'must be even (fold-over pairs +v, -v)')
    if not float(values['design.settle_s']) < float(values['design.hold_s']):
        raise _fail(path, 'design.settle_s', values['design.settle_s'],
                    f"must be shorter than design.hold_s = {values['design.hold_s']} s")
    return DesignSettings(steps=steps, hold_s=float(values['design.hold_s']),
                          settle_s=float(values['design.settle_s']), baseline_s=float(values['design.baseline_s']),
                          safety_factor=float(values['design.safety_factor']),
                          peak_fraction=float(values['design.peak_fraction']), seed=int(values['design.seed']),
                          full_scale_fraction=float(values['design.full_scale_fraction']),
                          max_lack_of_fit=float(values['design.max_lack_of_fit']))


def _set_up(campaign: Campaign, weight: float, size: float) -> tuple[dict[str, Any], dict[str, Any]]:
    """(nominal, true) geometry parameters of one set-up: the crane file at weight W and length l0 (or height h)."""
    params = {k: v for k, v in load_params(campaign.crane).items() if k.startswith('geometry.')}
    params.pop('geometry.height', None)
    params['geometry.weight'] = weight
    params['geometry.' + ('l0' if campaign.lengths else 'height')] = size
    nominal = geometry_to_params(geometry_from_params(params))
    true = dict(nominal)
    true['geometry.weight'] = weight * campaign.true_weight_factor
    if nominal['geometry.wire_stiffness']:  # k given: scale it; else E (k = E·A/l0 keeps its length rule)
        true['geometry.wire_stiffness'] = nominal['geometry.wire_stiffness'] * campaign.true_wire_stiffness_factor
    else:
        true['geometry.youngs_modulus'] = nominal['geometry.youngs_modulus'] * campaign.true_wire_stiffness_factor
    return nominal, true


def program_scale(campaign: Campaign, series: str, program: Path, nominal: Mapping[str, Any]) -> float:
    """Factor on a program's levels so that its peak is ``load_fraction`` of the load at which the nominal crane's
    first wire goes slack (side force, moment); 1 for the vertical force (no wire goes slack), load_fraction 0 or the
    series full (its program is designed, or checked, for each set-up)."""
    if campaign.load_fraction == 0.0 or series in ('fz', FULL):
        return 1.0
    from crane_stiffness.analysis.sweep import slack_threshold
    peak = float(abs(load_program_file(program, 'load_program').levels(series)).max())
    threshold = slack_threshold(geometry_from_params(nominal), series)
    if not math.isfinite(threshold) or peak == 0.0:
        return 1.0
    return campaign.load_fraction * threshold / peak


def session_id(series: str, weight: float, size: float, repeat: int, by_length: bool = True) -> str:
    """'fy_W50_l0.5_r1': series, W [N], l0 (or h) [m], repeat."""
    return f'{series}_W{weight:g}_{"l" if by_length else "h"}{size:g}_r{repeat}'


def plan_sessions(campaign: Campaign) -> list[SessionPlan]:
    """The campaign's sessions in run order: by series, then length, then weight (hang the weights in turn at one
    wire length), then repeat. Series full: each set-up's program designed (or checked) here, so that a set-up
    whose program would slacken a wire is refused before any session runs (CampaignFileError naming it).

    Seeds (simulated sensors): session i of n takes load cell seed + 2·i, LVDT seed + 2·i + 1 and, in series full,
    pose sensor seed + 2·n + i: every sensor of the campaign its own seed."""
    plans: list[SessionPlan] = []
    sizes = campaign.lengths or campaign.heights
    total = len(campaign.series) * len(sizes) * len(campaign.weights) * campaign.repeats
    for series, program in zip(campaign.series, campaign.programs):
        for size in sizes:
            for weight in campaign.weights:
                nominal, true = _set_up(campaign, weight, size)
                g = geometry_from_params(nominal)
                scale = program_scale(campaign, series, program, nominal)
                text = (full_program(str(program), nominal, campaign.design, weight, size, bool(campaign.lengths))
                        if series == FULL else None)
                for repeat in range(1, campaign.repeats + 1):
                    index = len(plans)
                    seeds = (None if campaign.seed < 0 else
                             {'load_cell': campaign.seed + 2 * index, 'lvdt': campaign.seed + 2 * index + 1})
                    if seeds is not None and series == FULL:
                        seeds['pose_sensor'] = campaign.seed + 2 * total + index
                    plans.append(SessionPlan(
                        index=index, id=session_id(series, weight, size, repeat, bool(campaign.lengths)),
                        series=series, program=str(program), program_scale=scale, weight=weight, l0=g.l0,
                        height=g.height, repeat=repeat, nominal=nominal,
                        true=_drawn_true(campaign, nominal, index) if campaign.true_crane == 'drawn' else true,
                        seeds=seeds, program_text=text, parameters=_session_parameters(campaign, seeds)))
    return plans


def _session_rng(campaign: Campaign, index: int, stream: int) -> Any:
    """A generator for session ``index``'s draws of one kind (``stream``): seeded by the campaign's seed, or fresh
    (seed -1)."""
    import numpy as np
    return np.random.default_rng(None if campaign.seed < 0 else (campaign.seed, index, stream))


def _drawn_true(campaign: Campaign, nominal: dict[str, Any], index: int) -> dict[str, Any]:
    """Session ``index``'s true crane drawn about ``nominal`` (:mod:`.true_draw`), then scaled by true.*_factor."""
    from crane_stiffness.campaign.true_draw import TRUE_CRANE_STREAM, draw_true_crane, uncertainty_entries
    assert campaign.true_uncertainty is not None  # load_campaign resolves it for true.crane drawn
    entries = uncertainty_entries(campaign.true_uncertainty, geometry_from_params(nominal))
    true = draw_true_crane(nominal, entries, _session_rng(campaign, index, TRUE_CRANE_STREAM))
    true['geometry.weight'] *= campaign.true_weight_factor
    key = 'geometry.wire_stiffness' if true['geometry.wire_stiffness'] else 'geometry.youngs_modulus'
    true[key] *= campaign.true_wire_stiffness_factor
    return true


def _session_parameters(campaign: Campaign, seeds: Mapping[str, int] | None) -> dict[str, dict[str, Any]] | None:
    """The campaign's sensor_parameters for one session: a node drawing its true calibration errors
    (truth.mode drawn) draws them with its own noise seed (another stream of it: sim.truth), or a fresh one."""
    if not campaign.sensor_parameters:
        return None
    out = {}
    for node, params in campaign.sensor_parameters.items():
        params = dict(params)
        if params.get('truth.mode') == 'drawn':
            import numpy as np
            params['truth.seed'] = (seeds or {}).get(node, int(np.random.default_rng().integers(2 ** 31)))
        out[node] = params
    return out


def plan_fingerprint(plans: list[SessionPlan]) -> str:
    """A digest of the sessions planned: a campaign directory is resumed only by the campaign it was started with."""
    return hashlib.sha256(json.dumps([p.to_dict() for p in plans], sort_keys=True).encode()).hexdigest()[:16]


def scaled_program_text(program: Path, scale: float) -> str:
    """The program file with its load levels (segments.target) and the estimator's hysteresis scaled by ``scale``
    (a YAML of the same sections; the file itself when ``scale`` is 1)."""
    import yaml
    text = program.read_text()
    if scale == 1.0:
        return text
    data = load_yaml(text)
    load = data['load_program']['ros__parameters']
    load['segments.target'] = [float(v) * scale for v in load['segments.target']]
    estimator = data.get('stiffness_estimator', {}).get('ros__parameters')
    if estimator is not None and 'hysteresis' in estimator:
        estimator['hysteresis'] = float(estimator['hysteresis']) * scale
    return f'# {program.name} with its levels scaled by {scale:.6g} for this set-up\n' + yaml.safe_dump(
        data, sort_keys=False, default_flow_style=None)
