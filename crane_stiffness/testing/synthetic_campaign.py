"""A synthetic campaign directory, as ``crane-stiffness campaign run`` leaves it, without ROS: every planned session a
synthetic bag (crane_stiffness.testing.synthetic) made with the campaign's true crane and recording the nominal one,
its result.json saying the run's statuses were OK. For the campaign tests (analysis, calibration statistics, Dask)
and the campaign benchmark.
"""
from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from crane_stiffness.campaign.runner import RESULT_FILE, prepare_campaign, campaign_entry
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


def write_synthetic_plan(out: Path, campaign: Campaign, plan: SessionPlan, seed: int,
                         sample_rate_hz: float = 1000.0, repeats: int = 1) -> None:
    """One session of a synthetic campaign: its bag and its result.json."""
    program, estimator = session_program(plan, repeats)
    # A moment series' LVDT reads the rotation itself here (no lever arm): no LVDT arrangement recorded.
    estimator.pop('lever_arm_m', None)
    entry = campaign_entry(campaign, plan, hardware=False, confirmed=None)
    write_synthetic_session(out / 'bags' / plan.id, program, geometry=geometry_from_params(plan.true),
                            recorded_geometry=geometry_from_params(plan.nominal), axis=plan.series,
                            estimator=estimator, seed=seed, sample_rate_hz=sample_rate_hz,
                            force_noise=FORCE_NOISE, displacement_noise=DISPLACEMENT_NOISE,
                            campaign=entry, notes=f'synthetic session {plan.id}')
    folder = out / 'sessions' / plan.id
    folder.mkdir(parents=True, exist_ok=True)
    status = {part: {'level': 'OK', 'message': 'synthetic'} for part in ('loading', 'unloading', 'input')}
    result = {'session': plan.id, 'plan': plan.to_dict(), 'campaign_entry': entry, 'status': status,
              'bag': str(out / 'bags' / plan.id)}
    tmp = folder / (RESULT_FILE + '.tmp')
    tmp.write_text(json.dumps(result))
    os.replace(tmp, folder / RESULT_FILE)


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
