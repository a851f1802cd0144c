"""The paper's models beside a recorded session: the stiffness predictions of the recorded geometry on the tested
axis and the force-displacement curves up to the program's peak, in the LVDT's reading units. Pure: no ROS import."""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from crane_stiffness.analysis.load import SessionData
from crane_stiffness.analysis.results import ModelSummary, Step
from crane_stiffness.contract.axes import AXES
from crane_stiffness.estimation.inputs import CommandSeries
from crane_stiffness.params.geometry import geometry_from_params


def accepted_commands(commands: CommandSeries) -> tuple[np.ndarray, np.ndarray]:
    """(stamps, loads) of the accepted commands: the program's steps (absurd and rejected ones left out)."""
    if commands.rejected is None:
        return commands.stamp, commands.value
    return commands.stamp[~commands.rejected], commands.value[~commands.rejected]


def lvdt_scale(axis: str, lvdt: dict[str, Any] | None) -> float | None:
    """LVDT reading per unit displacement (m) or rotation (rad) along ``axis`` for small motions.

    The reading is ``a · (δu + δθ × p)`` for the unit measuring direction ``a`` and contact point ``p``; None when
    the LVDT parameters were not recorded.
    """
    if not lvdt or 'axis' not in lvdt:
        return None
    a = np.asarray(lvdt.get('axis'), dtype=float)
    if a.shape != (3,) or not np.isfinite(a).all() or not np.linalg.norm(a):
        return None
    a = a / np.linalg.norm(a)
    p = np.asarray(lvdt.get('contact_point', [0.0, 0.0, 0.0]), dtype=float)
    i = AXES.index(axis)
    return float(a[i]) if i < 3 else float(np.cross(p, a)[i - 3])


def model_summary(data: SessionData, steps: list[Step], commands: CommandSeries | None, points: int,
           problems: list[str]) -> ModelSummary | None:
    if data.geometry_params is None:
        return None
    from crane_stiffness.analysis.sweep import force_displacement, unit
    from crane_stiffness.model import (ModelError, axis_stiffness, directional_stiffness, elastic_stiffness,
                                       paper_stiffness, rest_pose, single_wire_pendulum_stiffness,
                                       tangent_stiffness)
    axis = data.settings.force_axis
    try:
        g = geometry_from_params(data.geometry_params)
        d = unit(axis)
        tangent = axis_stiffness(tangent_stiffness(g, rest_pose(g)), axis)
        eq18 = directional_stiffness(paper_stiffness(g), d)
        elastic = directional_stiffness(elastic_stiffness(g), d)
        pendulum = single_wire_pendulum_stiffness(g) if axis in ('fx', 'fy') and g.weight > 0 else math.nan
    except (ModelError, ValueError) as exc:
        problems.append(f'model of the recorded geometry failed: {exc}')
        return None
    recorded = math.nan
    if data.prediction is not None and data.prediction.size:
        recorded = float(data.prediction['data'][0])
    if steps:
        levels = np.array([s.level for s in steps])
    else:
        levels = accepted_commands(commands)[1] if commands else np.zeros(0)
    peak = float(levels[np.argmax(np.abs(levels))]) if levels.size and np.abs(levels).max() > 0 else 0.0
    lvdt = data.sensors.get('lvdt') or data.sensors.get('/lvdt')
    scale = lvdt_scale(axis, lvdt)
    if scale is not None and data.settings.lever_arm_m > 0.0:
        scale /= data.settings.lever_arm_m  # readings converted to angles (LiveSettings.reading_to_displacement)
    if scale is None:
        scale = 1.0
        if lvdt is not None:
            problems.append('the recorded LVDT parameters are incomplete: readings taken as displacement along '
                            f'{axis}')
    elif abs(scale) < 1e-9:
        assert lvdt is not None  # a scale comes from recorded LVDT parameters
        problems.append(f'the LVDT (axis {lvdt.get("axis")}, contact point {lvdt.get("contact_point")}) does not see '
                        f'motion along {axis}: measured points are not comparable with the model curves')
    summary = ModelSummary(axis=axis, unit=data.settings.stiffness_unit, tangent_at_rest=tangent,
                           eq18=eq18, elastic_w0=elastic, single_wire_w6=pendulum, recorded_prediction=recorded,
                           lvdt_scale=scale)
    if peak != 0.0:
        try:
            curves = force_displacement(g, axis, peak, points)
            summary.curves = {k: np.asarray(v, dtype=float).tolist() for k, v in curves.columns().items()}
            for step in steps:  # in LVDT reading units, comparable with displacement_mean
                same_side = step.level * peak >= 0
                step.model_displacement = float(np.interp(abs(step.level), np.abs(curves.load), curves.nonlinear)) \
                    * scale if same_side else math.nan
        except (ModelError, ValueError) as exc:
            problems.append(f'model curves up to {peak:g} on {axis} failed: {exc}')
    return summary


__all__ = ['accepted_commands', 'lvdt_scale', 'model_summary']
