"""The crane's uncertain inputs: their names, their default uncertainties (each with its source) and their file.

The inputs of the model's prediction are the crane's measured quantities: the half sides a and b, the height h, the
suspended weight W, the wire (diameter d and Young's modulus E, or the stiffness k when the crane file gives k), the
change of unstretched length of each wire and the centre-of-mass offset. Their values are the crane file's
(``geometry.*``, :mod:`crane_stiffness.params.geometry`); their uncertainties come from a file of their own, so
that every existing command reads the crane file as before:

.. code-block:: yaml

    crane_uncertainty:           # a section no node reads (nodes refuse parameters they do not know)
      ros__parameters:
        uncertainty:
          wire_diameter: {U: 2.0e-5, k: 2}                          # a micrometer's certificate [m]
          youngs_modulus: {half_width: 10.0e9, distribution: rectangular}   # [Pa]
          weight: {u: 0.05, dof: 9}                                 # 10 weighings, Type A [N]

(``config/uncertainty_lab.yaml`` holds the defaults below for the lab model.) Each entry is the flat form of
:func:`.inputs.input_from_mapping` without ``value``; an input the file leaves out keeps its default. The defaults
are typical values for a lab rig like the paper's, not a certificate: replace them with your instruments'.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any, Mapping

from crane_stiffness.model.geometry import CraneGeometry
from crane_stiffness.params.files import load_params
from crane_stiffness.uncertainty.errors import InputError
from crane_stiffness.uncertainty.inputs import InputQuantity, entries_from_params, input_from_mapping

#: The section of the uncertainty file (ROS parameters ``uncertainty.<input>.<key>``).
PREFIX = 'uncertainty.'
LENGTH_OFFSETS = tuple(f'length_offset_{i}' for i in range(1, 7))
COM_OFFSETS = ('com_offset_x', 'com_offset_y', 'com_offset_z')


@dataclass(frozen=True)
class DefaultUncertainty:
    """One input's default uncertainty (the flat form without value) and where it comes from, for the docs."""

    entry: dict[str, Any]
    source: str


def input_names(geometry: CraneGeometry) -> tuple[str, ...]:
    """The crane's uncertain inputs in order: a, b, height, weight, the wire (wire_diameter and youngs_modulus, or
    wire_stiffness), length_offset_1..6, com_offset_x/y/z."""
    wire = ('wire_stiffness',) if geometry.wire_stiffness is not None else ('wire_diameter', 'youngs_modulus')
    return ('a', 'b', 'height', 'weight', *wire, *LENGTH_OFFSETS, *COM_OFFSETS)


def input_values(geometry: CraneGeometry) -> dict[str, float]:
    """The estimate of each input: the crane's own values [m, N, Pa, N/m]."""
    values: dict[str, float] = {'a': geometry.a, 'b': geometry.b, 'height': geometry.height,
                                'weight': geometry.weight}
    if geometry.wire_stiffness is not None:
        values['wire_stiffness'] = geometry.wire_stiffness
    else:
        assert geometry.wire_diameter is not None and geometry.youngs_modulus is not None
        values['wire_diameter'] = geometry.wire_diameter
        values['youngs_modulus'] = geometry.youngs_modulus
    values.update(zip(LENGTH_OFFSETS, geometry.length_offsets))
    values.update(zip(COM_OFFSETS, geometry.com_offset))
    return values


UNITS = {'a': 'm', 'b': 'm', 'height': 'm', 'weight': 'N', 'wire_diameter': 'm', 'youngs_modulus': 'Pa',
         'wire_stiffness': 'N/m', **{name: 'm' for name in LENGTH_OFFSETS + COM_OFFSETS}}


def default_uncertainty(geometry: CraneGeometry) -> dict[str, DefaultUncertainty]:
    """The default uncertainty of each input of ``geometry`` (docs/uncertainty.md lists them with their sources)."""
    ruler = 'steel rule or tape between the wire attachment points: ±0.5 mm, rectangular (GUM 4.3.7)'
    out = {
        'a': DefaultUncertainty({'half_width': 0.5e-3, 'distribution': 'rectangular'}, ruler),
        'b': DefaultUncertainty({'half_width': 0.5e-3, 'distribution': 'rectangular'}, ruler),
        'height': DefaultUncertainty({'half_width': 0.5e-3, 'distribution': 'rectangular'},
                                     'height between the triangles by tape: ±0.5 mm, rectangular'),
        'weight': DefaultUncertainty({'U': 0.1, 'k': 2.0},
                                     'weighed on a calibrated scale: certificate U = 0.1 N at k = 2'),
    }
    if geometry.wire_stiffness is not None:
        out['wire_stiffness'] = DefaultUncertainty(
            {'half_width': 0.05 * geometry.wire_stiffness, 'distribution': 'rectangular'},
            'k = A·E/l0 known as well as E: ±5 %, rectangular')
    else:
        out['wire_diameter'] = DefaultUncertainty(
            {'half_width': 0.01e-3, 'distribution': 'rectangular'},
            'micrometer reading of the wire, 1.08 mm ± 0.01 mm (resolution and ovality), rectangular')
        assert geometry.youngs_modulus is not None
        out['youngs_modulus'] = DefaultUncertainty(
            {'half_width': 0.05 * geometry.youngs_modulus, 'distribution': 'rectangular'},
            "handbook Young's modulus of steel wire, 190–210 GPa about the paper's 206.8 GPa: ±5 %, rectangular")
    for name in LENGTH_OFFSETS:
        out[name] = DefaultUncertainty(
            {'half_width': 5e-6, 'distribution': 'rectangular'},
            'wires set to equal tension within about ±20 % of their static stretch (~24 µm at W = 50 N): '
            '±5 µm of unstretched length, rectangular')
    for name in COM_OFFSETS:
        out[name] = DefaultUncertainty({'half_width': 1e-3, 'distribution': 'rectangular'},
                                       'centre of mass located by balancing: ±1 mm per axis, rectangular')
    return out


def crane_inputs(geometry: CraneGeometry, uncertainty: Mapping[str, Mapping[str, Any]] | None = None
                 ) -> list[InputQuantity]:
    """The crane's inputs (:func:`input_names` order) with the crane's values and the default uncertainties, each
    replaced by ``uncertainty[name]`` where given (flat form without value). Unknown names are refused."""
    names = input_names(geometry)
    given = dict(uncertainty or {})
    unknown = sorted(set(given) - set(names))
    if unknown:
        raise InputError(f'{PREFIX}{unknown[0]}', given[unknown[0]],
                         f'is not an input of this crane (inputs: {", ".join(names)})')
    defaults = default_uncertainty(geometry)
    values = input_values(geometry)
    out = []
    for name in names:
        entry = given.get(name, defaults[name].entry)
        if isinstance(entry, Mapping) and 'value' in entry:
            raise InputError(f'{PREFIX}{name}.value', entry['value'],
                             "the value is the crane file's (geometry.*); the uncertainty file gives only its "
                             'uncertainty')
        out.append(input_from_mapping(name, entry, value=values[name], unit=UNITS[name]))
    return out


def load_uncertainty_file(path: str | os.PathLike) -> dict[str, dict[str, Any]]:
    """The ``uncertainty.*`` entries of a ROS parameter file (every section that applies to any node)."""
    return entries_from_params(load_params(path), PREFIX)
