"""The campaign series ``full``: the whole 6×6 stiffness of every set-up (weight W, wire length l0) from one
designed multi-axis test each (crane_stiffness.full6). No ROS.

A campaign's program for ``full`` is either

- ``design``: for each set-up, the D-optimal program of the nominal crane at that W and l0
  (crane_stiffness.full6.design.d_optimal_design), with the campaign's ``design.*`` keys (steps, hold, settling,
  baselines, safety factor, peak fraction, seed); its peaks are ``design.peak_fraction`` times each axis' largest
  admissible load alone (crane_stiffness.full6.admissible.axis_peaks), so that every set-up is loaded as hard as its
  own slack margins allow. The margins shrink with W and l0 (the lighter crane slackens first), which is why one
  fixed program cannot serve a campaign. The peaks are then capped at ``design.full_scale_fraction`` of the load
  cell's full scale (a saturated reading is no measurement) and the design scaled down until the lack of fit the
  nonlinear model predicts for it is at most ``design.max_lack_of_fit`` (crane_stiffness.full6.linearity: the
  6×6 status is never OK on a bent response, and at l0 = 1.5 m half the slack margins bend it twenty times more
  than the noise); or
- a six-axis program file (one with a ``stiffness6_estimator`` section, e.g. ``full6`` = config/program_full6.yaml):
  played as written in every set-up, and checked against every set-up's slack margins before the campaign starts.

Either way a set-up whose program would bring a wire closer to slack than ``design.safety_factor`` is refused
before anything runs: :class:`~crane_stiffness.campaign.errors.CampaignFileError` naming the set-up, the step, the
direction and the wire.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from crane_stiffness.campaign.errors import CampaignFileError

#: The series' name, and the program value that designs one program per set-up.
FULL = 'full'
DESIGN = 'design'


@dataclass(frozen=True)
class DesignSettings:
    """The campaign's ``design.*`` keys: the program designed for each set-up. Times in s."""

    steps: int
    hold_s: float
    settle_s: float
    baseline_s: float
    safety_factor: float
    peak_fraction: float
    seed: int
    full_scale_fraction: float = 0.9
    """The peaks at most this fraction of the load cell's full scale (config/sensors.yaml's load_cell)."""
    max_lack_of_fit: float = 1.2
    """The design scaled down until the lack of fit the model predicts is at most this."""


def _where(weight: float, size: float, by_length: bool) -> str:
    return f'W = {weight:g} N, {"l0" if by_length else "h"} = {size:g} m'


def design_program_text(nominal: Mapping[str, Any], settings: DesignSettings, where: str) -> str:
    """The D-optimal program file (its YAML text, with the ``stiffness6_estimator`` section) of the nominal crane
    ``nominal`` (geometry.* parameters) under ``settings``, kept within the load cell's full scale and the linear
    range (crane_stiffness.full6.linearity.linear_design); CampaignFileError naming the set-up ``where`` when the
    design cannot keep the slack rule."""
    from crane_stiffness.full6.admissible import axis_peaks
    from crane_stiffness.full6.errors import Full6Error
    from crane_stiffness.full6.linearity import linear_design, load_cell_full_scale
    from crane_stiffness.full6.program import program_yaml
    from crane_stiffness.params.geometry import geometry_from_params
    g = geometry_from_params(dict(nominal))
    peaks = settings.peak_fraction * axis_peaks(g, settings.safety_factor)
    if not np.all(np.isfinite(peaks)):
        raise CampaignFileError(f'series full at {where}: an axis no wire goes slack along has no peak load '
                                f'(peaks {np.round(peaks, 4).tolist()}); give a program file instead of design')
    full_scale = settings.full_scale_fraction * load_cell_full_scale()
    try:
        made = linear_design(g, peaks, full_scale=full_scale, max_lack_of_fit=settings.max_lack_of_fit,
                             n_steps=settings.steps, hold_s=settings.hold_s, settle_s=settings.settle_s,
                             baseline_s=settings.baseline_s, safety_factor=settings.safety_factor,
                             seed=settings.seed)
    except Full6Error as exc:
        raise CampaignFileError(f'series full at {where}: no admissible design: {exc}') from None
    design = made.design
    how = (f'Designed by crane-stiffness campaign for the set-up {where} (a = {g.a:g} m, b = {g.b:g} m, '
           f'h = {g.height:.6g} m, k = {g.k:.6g} N/m);\npeaks {settings.peak_fraction:g} x each axis\' largest '
           f'admissible load alone: ' + ', '.join(f'{v:.4g}' for v in peaks)
           + f';\ncapped at {settings.full_scale_fraction:g} x the load cell\'s full scale ('
           + ', '.join(f'{v:.4g}' for v in full_scale) + f') and scaled by {made.scale:.4g} to keep the predicted '
           f'lack of fit at {made.lack_of_fit:.3f} <= {settings.max_lack_of_fit:g}\n(crane_stiffness.full6.linearity);'
           f' seed {settings.seed}; D-efficiency {design.efficiency:.3f}.')
    return program_yaml(design, name='full6_campaign', title='The whole 6x6 stiffness of one set-up of a '
                        'campaign (crane_stiffness.campaign.full_series).', how=how)


def check_program(program: Path, nominal: Mapping[str, Any], safety_factor: float, where: str) -> None:
    """CampaignFileError naming the set-up, step, direction and wire when a six-axis program file's held wrenches
    (or the straight paths between them) would come closer to slack than ``safety_factor`` on the nominal crane
    ``nominal`` (crane_stiffness.full6.admissible.check_steps)."""
    from crane_stiffness.full6.admissible import check_steps
    from crane_stiffness.full6.errors import SlackDesignError
    from crane_stiffness.full6.program import held_steps
    from crane_stiffness.params.geometry import geometry_from_params
    from crane_stiffness.sim.program import load_program_file
    steps = np.array([h.wrench for h in held_steps(load_program_file(program, 'load_program'))])
    try:
        check_steps(geometry_from_params(dict(nominal)), steps, safety_factor)
    except SlackDesignError as exc:
        raise CampaignFileError(f'series full at {where}: program {program.name} refused: {exc}') from None


def full_program(program: str, nominal: Mapping[str, Any], settings: DesignSettings, weight: float, size: float,
                 by_length: bool) -> str | None:
    """The program text of one set-up of the series: the designed one for ``design``; None for a file (played as
    written) after checking it against the set-up's slack margins. CampaignFileError naming the set-up."""
    where = _where(weight, size, by_length)
    if program == DESIGN:
        return design_program_text(nominal, settings, where)
    check_program(Path(program), nominal, settings.safety_factor, where)
    return None


__all__ = ['DESIGN', 'DesignSettings', 'FULL', 'check_program', 'design_program_text',
           'full_program']
