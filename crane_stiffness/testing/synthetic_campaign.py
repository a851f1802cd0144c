"""A synthetic campaign directory, as ``crane-stiffness campaign run`` leaves it, without ROS: every planned session a
synthetic bag (crane_stiffness.testing.synthetic; six-axis for the series full:
crane_stiffness.testing.synthetic_full6_bag) made with the campaign's true crane and recording the nominal one,
its result.json saying the run's statuses were OK. For the campaign tests (analysis, calibration statistics, Dask)
and the campaign benchmark.
"""
from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from crane_stiffness.campaign.full_series import FULL
from crane_stiffness.campaign.runner import prepare_campaign
from crane_stiffness.campaign.session import RESULT_FILE, campaign_entry
from crane_stiffness.campaign.spec import Campaign, SessionPlan, plan_sessions, scaled_program_text
from crane_stiffness.params.files import load_yaml
from crane_stiffness.params.geometry import geometry_from_params
from crane_stiffness.sim.program import LoadProgram
from crane_stiffness.testing.synthetic import write_synthetic_session

#: The simulated sensors' noise (config/sensors.yaml's order of magnitude): load cell [N], LVDT [m].
FORCE_NOISE = 0.01
DISPLACEMENT_NOISE = 2e-7


def session_program(plan: SessionPlan, repeats: int = 1) -> tuple[LoadProgram, dict[str, Any]]:
    """The session's scaled program (played ``repeats`` times) and its stiffness_estimator section."""
    data = load_yaml(scaled_program_text(Path(plan.program), plan.program_scale))
    program = LoadProgram.from_params({**data['load_program']['ros__parameters'], 'repeats': repeats})
    estimator = dict((data.get('stiffness_estimator') or {}).get('ros__parameters') or {})
    return program, estimator


def _write_result(out: Path, plan: SessionPlan, result: dict[str, Any]) -> None:
    folder = out / 'sessions' / plan.id
    folder.mkdir(parents=True, exist_ok=True)
    tmp = folder / (RESULT_FILE + '.tmp')
    tmp.write_text(json.dumps(result))
    os.replace(tmp, folder / RESULT_FILE)


def write_synthetic_full(out: Path, campaign: Campaign, plan: SessionPlan, seed: int) -> None:
    """One session of the series full (crane_stiffness.testing.synthetic_full6_bag): the pose deflected by the true
    crane's tangent compliance, the nominal crane recorded; its result.json holds the K the live estimator would
    have published last (the offline fit of the same samples, which the live one equals: test_stiffness6_node)
    and status OK."""
    from crane_stiffness.analysis.full6 import analyze_full6
    from crane_stiffness.contract.stiffness6_layout import encode
    from crane_stiffness.testing.synthetic_full6_bag import write_full6_session
    data = load_yaml(plan.program_text or Path(plan.program).read_text())
    program = LoadProgram.from_params(data['load_program']['ros__parameters'])
    estimator6 = dict((data.get('stiffness6_estimator') or {}).get('ros__parameters') or {})
    bag = out / 'bags' / plan.id
    write_full6_session(bag, program, geometry_from_params(plan.true), seed=seed, estimator6=estimator6,
                        recorded_geometry=geometry_from_params(plan.nominal), notes=f'synthetic session {plan.id}')
    fit = analyze_full6(bag, write_files=False).fit
    assert fit is not None
    live = encode(fit.stiffness, fit.stiffness_low, fit.stiffness_high)
    ok = {'level': 'OK', 'message': 'synthetic'}
    _write_result(out, plan, {'session': plan.id, 'plan': plan.to_dict(),
                              'campaign_entry': campaign_entry(campaign, plan, hardware=False, confirmed=None),
                              'status': {part: ok for part in ('loading', 'unloading', 'input')},
                              'status6': {**ok, 'values': {}}, 'stiffness6': live, 'bag': str(bag)})


def write_synthetic_plan(out: Path, campaign: Campaign, plan: SessionPlan, seed: int,
                         sample_rate_hz: float = 1000.0, repeats: int = 1) -> None:
    """One session of a synthetic campaign: its bag and its result.json."""
    if plan.series == FULL:
        write_synthetic_full(out, campaign, plan, seed)
        return
    program, estimator = session_program(plan, repeats)
    # A moment series' LVDT reads the rotation itself here (no lever arm): no LVDT arrangement recorded.
    estimator.pop('lever_arm_m', None)
    entry = campaign_entry(campaign, plan, hardware=False, confirmed=None)
    write_synthetic_session(out / 'bags' / plan.id, program, geometry=geometry_from_params(plan.true),
                            recorded_geometry=geometry_from_params(plan.nominal), axis=plan.series,
                            estimator=estimator, seed=seed, sample_rate_hz=sample_rate_hz,
                            force_noise=FORCE_NOISE, displacement_noise=DISPLACEMENT_NOISE,
                            campaign=entry, notes=f'synthetic session {plan.id}')
    status = {part: {'level': 'OK', 'message': 'synthetic'} for part in ('loading', 'unloading', 'input')}
    _write_result(out, plan, {'session': plan.id, 'plan': plan.to_dict(), 'campaign_entry': entry, 'status': status,
                              'bag': str(out / 'bags' / plan.id)})


def write_synthetic_campaign(out: str | os.PathLike, campaign: Campaign, seed: int = 0,
                             sample_rate_hz: float = 1000.0, repeats: int = 1) -> list[SessionPlan]:
    """Every session of ``campaign`` in ``out`` (seeds ``seed``, ``seed + 1``, ...), each program played
    ``repeats`` times; returns the plan."""
    out = Path(out)
    plans = plan_sessions(campaign)
    prepare_campaign(out, campaign, plans)
    for plan in plans:
        write_synthetic_plan(out, campaign, plan, seed + plan.index, sample_rate_hz, repeats)
    return plans


# --- The GUM coverage study in its fast synthetic form ---------------------------------------------------------------

#: The sensors of the GUM coverage study: config/sensors.yaml with campaign_coverage_gum_sensors.yaml on top.
GUM_SENSOR_FILES = ('sensors.yaml', 'campaign_coverage_gum_sensors.yaml')
#: The side-force program of the coverage campaigns at W = 50 N, l0 = 0.5 m (program_campaign_side_force.yaml
#: scaled to half the first-slack load): hold levels [N], holds [s], ramps [s], the part of a hold averaged.
GUM_PEAK_N = 3.4267425537109375
GUM_LEVELS = (0.0, 1 / 3, 2 / 3, 1.0, 2 / 3, 1 / 3, 0.0)
GUM_HOLD_S, GUM_RAMP_S, GUM_SETTLE = 0.5, 0.3, 0.3


def gum_sensor_params(node: str, overrides: dict[str, Any] | None = None) -> dict[str, Any]:
    """A sensor node's parameters in the GUM coverage study (:data:`GUM_SENSOR_FILES`), ``overrides`` on top."""
    from crane_stiffness.params.files import config_path, load_params
    params: dict[str, Any] = {}
    for name in GUM_SENSOR_FILES:
        params.update(load_params(config_path(name), node))
    return {**params, **(overrides or {})}


def _axis(params: dict[str, Any], i: int) -> dict[str, Any]:
    """A six-axis sensor's ``noise.*`` parameters of axis ``i`` alone (one channel: the one a one-axis test reads)."""
    return {key: (value[i] if isinstance(value, (list, tuple)) and len(value) == 6 else value)
            for key, value in params.items() if key.startswith('noise.')}


def _t3(u: Any) -> Any:
    """Chebyshev's T3 = 4u³ − 3u: a (non)linearity error bounded by ±1 over the stroke, no straight-line part."""
    return 4.0 * u ** 3 - 3.0 * u


def synthetic_gum_session(index: int, seed: int, stiffness: float, *, load_cell: dict[str, Any],
                          lvdt: dict[str, Any], rate_hz: float = 1000.0,
                          declared: dict[str, dict[str, Any]] | None = None) -> dict[str, Any]:
    """One synthetic side-force session of the GUM coverage study, without a bag: the sensors' readings at
    ``rate_hz`` over the program (:data:`GUM_LEVELS` of :data:`GUM_PEAK_N`), their hold means fitted per branch and
    stated with their GUM uncertainty by the analysis' own function (:func:`~crane_stiffness.uncertainty.measurement.
    measured_stiffness`, from the declared calibrations ``load_cell`` and ``lvdt``: node parameters).

    The truth is linear, k = ``stiffness`` [N/m]. The sensors' true errors are drawn from their declarations as the
    simulated rig draws them (:mod:`crane_stiffness.sim.truth`: the load cell's sensitivity and misalignment, the
    LVDT's sensitivity, DAQ gain and linearity as (1 + s)·d + L·FS·T3(d/FS)), and one more the rig's load cell does
    not have: its nonlinearity, N·FS·T3(F/FS) with N drawn from calibration.nonlinearity; both sensors carry the
    files' white and coloured noise with drift (:mod:`crane_stiffness.sim.noise`). Session ``index`` seeds its
    draws from ``seed`` alone, so a study is the same in every run. ``declared``: parameters by sensor ('load_cell',
    'lvdt') the analysis is given on top of the ones the truth is drawn from (a certificate that leaves something
    out).

    Returns {'truth': k, 'errors': the drawn errors, 'loading'/'unloading': {'k', 'U', 'k_factor', 'interval',
    'repeatability' (the hold means' fit's statistical 95 % interval), 'statistical' (the 95 % interval of the fit
    of the branch's samples, as the live estimator fits), 'budget' (names)}}.
    """
    import numpy as np
    from crane_stiffness.estimation.fit import fit_or_none
    from crane_stiffness.model.rotation import rotvec_to_matrix
    from crane_stiffness.sim.calibration import LOAD_CELL_COMPONENTS, calibration_of
    from crane_stiffness.sim.noise import ColouredNoise
    from crane_stiffness.sim.truth import load_cell_truth, lvdt_truth
    from crane_stiffness.uncertainty.measurement import SlopeStatistics, measured_stiffness
    load_cell = {**load_cell, 'truth.mode': 'drawn', 'truth.seed': 2 * index}
    lvdt = {**lvdt, 'truth.mode': 'drawn', 'truth.seed': 2 * index + 1}
    cell, channel = load_cell_truth(load_cell), lvdt_truth(lvdt)
    rng = np.random.default_rng((seed, index))
    nonlinearity = float(calibration_of(load_cell, LOAD_CELL_COMPONENTS)['nonlinearity'].draw(rng)[1]) / 100.0
    full_scale = float(np.atleast_1d(load_cell['full_scale'])[1])
    half_stroke = float(np.max(np.abs(lvdt['range_m'])))
    # the program: holds at the levels, ramps between; the true load and displacement at every sample
    edges = [0.0]
    for _ in GUM_LEVELS[1:]:
        edges += [edges[-1] + GUM_HOLD_S, edges[-1] + GUM_HOLD_S + GUM_RAMP_S]
    edges.append(edges[-1] + GUM_HOLD_S)
    t = np.arange(int(round(edges[-1] * rate_hz))) / rate_hz
    levels = GUM_PEAK_N * np.array(GUM_LEVELS)
    force = np.interp(t, edges, np.repeat(levels, 2))
    wrench = np.zeros((t.size, 6))
    wrench[:, 1] = force
    displacement = force / stiffness
    # the readings
    turned = wrench[:, :3] @ rotvec_to_matrix(cell.misalignment)  # Rᵀ·f per sample: the sensor's own axes
    f_read = ((1.0 + cell.sensitivity[1]) * turned[:, 1] + nonlinearity * full_scale * _t3(force / full_scale)
              + ColouredNoise.from_params(1, _axis(load_cell, 1), rng).sample(t)[:, 0]
              + float(np.atleast_1d(load_cell['noise_std'])[1]) * rng.standard_normal(t.size))
    x_read = ((1.0 + channel.sensitivity) * displacement + channel.linearity * half_stroke
              * _t3(displacement / half_stroke) + ColouredNoise.from_params(1, lvdt, rng).sample(t)[:, 0]
              + float(lvdt['noise_std']) * rng.standard_normal(t.size))
    out: dict[str, Any] = {'truth': stiffness, 'errors': {'load_cell': cell.as_dict(), 'lvdt': channel.as_dict(),
                                                          'load_cell_nonlinearity': 100.0 * nonlinearity}}
    holds = [(edges[2 * i] + GUM_SETTLE * GUM_HOLD_S, edges[2 * i] + GUM_HOLD_S) for i in range(len(GUM_LEVELS))]
    peak = int(np.argmax(GUM_LEVELS))
    turn = edges[2 * peak] + GUM_HOLD_S  # the end of the peak's hold: loading before, unloading after
    for branch, chosen in (('loading', range(0, peak + 1)), ('unloading', range(peak + 1, len(GUM_LEVELS)))):
        in_branch = (t < turn) if branch == 'loading' else (t >= turn)
        samples = fit_or_none(x_read[in_branch], f_read[in_branch])
        assert samples is not None
        means = [((t >= holds[i][0]) & (t < holds[i][1])) for i in chosen]
        forces = np.array([f_read[m].mean() for m in means])
        xs = np.array([x_read[m].mean() for m in means])
        fit = fit_or_none(xs, forces)
        assert fit is not None
        measured = measured_stiffness(
            SlopeStatistics(float(fit.stiffness), float(fit.stderr), float(fit.n - 2), 'hold means'), 'fy',
            load_cell={**load_cell, **(declared or {}).get('load_cell', {})},
            lvdt={**lvdt, **(declared or {}).get('lvdt', {})}, force_span=float(np.ptp(forces)),
            displacement_span=float(np.ptp(xs)))
        r = measured.result
        out[branch] = {'k': r.value, 'U': r.U, 'k_factor': r.k, 'interval': list(r.interval),
                       'repeatability': [float(fit.ci95_low), float(fit.ci95_high)],
                       'statistical': [float(samples.ci95_low), float(samples.ci95_high)],
                       'budget': [row.name for row in r.budget]}
    return out


def synthetic_gum_study(sessions: int, seed: int, *, rate_hz: float = 250.0,
                        declared: dict[str, dict[str, Any]] | None = None) -> dict[str, Any]:
    """The GUM coverage study in its synthetic form: ``sessions`` sessions (:func:`synthetic_gum_session`) of the
    lab model along fy (W = 50 N, l0 = 0.5 m; its exact tangent is the truth) with the study's sensors
    (:func:`gum_sensor_params`), the load cell with config/sensors.yaml's nonlinearity, declared and drawn.
    {quantity: :class:`~crane_stiffness.campaign.coverage.Coverage`} per branch:
    'k fy <branch>, GUM U' (k ± U), ', repeatability' (the hold means' fit's interval) and '' (the samples' fit's),
    as ``campaign analyze`` names them."""
    from crane_stiffness.campaign.coverage import Coverage
    from crane_stiffness.model import axis_stiffness, lab_model, rest_pose, tangent_stiffness
    geometry = lab_model(0.5, 50.0)
    truth = axis_stiffness(tangent_stiffness(geometry, rest_pose(geometry)), 'fy')
    from crane_stiffness.params.files import config_path, load_params
    # The synthetic load cell has a nonlinearity (the rig's simulated one has none): the data sheet's, declared.
    sheet = load_params(config_path(GUM_SENSOR_FILES[0]), 'load_cell')['calibration.nonlinearity']
    load_cell = gum_sensor_params('load_cell', {'calibration.nonlinearity': sheet})
    lvdt = gum_sensor_params('lvdt')
    counts: dict[str, int] = {}
    for index in range(sessions):
        result = synthetic_gum_session(index, seed, truth, load_cell=load_cell, lvdt=lvdt, rate_hz=rate_hz,
                                       declared=declared)
        for branch in ('loading', 'unloading'):
            for suffix, key in ((', GUM U', 'interval'), (', repeatability', 'repeatability'), ('', 'statistical')):
                low, high = result[branch][key]
                name = f'k fy {branch}{suffix}'
                counts[name] = counts.get(name, 0) + int(low <= truth <= high)
    return {name: Coverage(name, covered, sessions) for name, covered in counts.items()}
