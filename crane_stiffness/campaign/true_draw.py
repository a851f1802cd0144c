"""A session's true crane drawn from the crane inputs' uncertainties (a campaign's ``true.crane: drawn``): what a
coverage study of the model's prediction needs, a crane whose truth differs from the nominal one as much as the
prediction's uncertainty says it may. No ROS.

Each input of the prediction (:func:`crane_stiffness.uncertainty.crane_inputs.crane_inputs`: a, b, the height h,
W, the wire's d and E (or its k), the six unstretched length offsets, the centre-of-mass offset) is drawn once per
session from its stated distribution about the nominal value (:meth:`InputQuantity.draws`, the draws of the
prediction's own Monte Carlo), so the true cranes scatter exactly as the prediction's measurement function assumes.
The draw is seeded per session from the campaign's seed: a campaign is planned the same every time. The true
crane is the simulation's secret: the plan and the session's campaign entry (``true_geometry``) record it for
studies; the analysis models the nominal crane.
"""
from __future__ import annotations

import os
from typing import Any, Mapping

import numpy as np

from crane_stiffness.model.geometry import CraneGeometry
from crane_stiffness.params.files import load_params
from crane_stiffness.params.geometry import geometry_from_params, geometry_to_params
from crane_stiffness.uncertainty.crane_inputs import (COM_OFFSETS, LENGTH_OFFSETS, crane_inputs,
                                                      load_uncertainty_file)

#: The stream of a session's seed the true crane is drawn from (the sensors' noise takes the seed itself).
TRUE_CRANE_STREAM = 3


def uncertainty_entries(path: str | os.PathLike, geometry: CraneGeometry) -> dict[str, dict[str, Any]]:
    """The file's ``uncertainty.*`` entries that are inputs of ``geometry`` (a file written for a crane given by d
    and E also states k's; the others keep their defaults)."""
    from crane_stiffness.uncertainty.crane_inputs import input_names
    known = set(input_names(geometry))
    return {name: entry for name, entry in load_uncertainty_file(path).items() if name in known}


def check_uncertainty_file(path: str | os.PathLike, crane: str | os.PathLike) -> None:
    """Refuse (ValueError or the uncertainty room's InputError) an uncertainty file that cannot scatter ``crane``'s
    inputs: an entry without a valid uncertainty, or no entry at all."""
    geometry = geometry_from_params({k: v for k, v in load_params(crane).items() if k.startswith('geometry.')})
    entries = uncertainty_entries(path, geometry)
    if not entries:
        raise ValueError(f'{path}: states no uncertainty of an input of the crane')
    crane_inputs(geometry, entries)


def draw_true_crane(nominal: Mapping[str, Any], entries: Mapping[str, Mapping[str, Any]],
                    rng: np.random.Generator) -> dict[str, Any]:
    """The ``geometry.*`` parameters of one true crane drawn about ``nominal`` (see the module docstring)."""
    geometry = geometry_from_params(nominal)
    quantities = crane_inputs(geometry, entries)
    drawn = {q.name: float(q.draws(rng, 1)[0]) for q in quantities}  # in the inputs' fixed order
    changes: dict[str, Any] = {name: drawn[name] for name in ('a', 'b', 'height', 'weight', 'wire_diameter',
                                                              'youngs_modulus', 'wire_stiffness') if name in drawn}
    changes['length_offsets'] = tuple(drawn[name] for name in LENGTH_OFFSETS)
    changes['com_offset'] = tuple(drawn[name] for name in COM_OFFSETS)
    return geometry_to_params(geometry.replace(**changes))


__all__ = ['TRUE_CRANE_STREAM', 'check_uncertainty_file', 'draw_true_crane', 'uncertainty_entries']
