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
