"""The crane's geometry parameters (``geometry.*``), declared once: the nodes that hold a crane model declare them, the
offline CLI turns them into flags and reads them from the same files. No ROS import.

``geometry.wire_stiffness`` 0 means "derive k from wire_diameter and youngs_modulus" (ROS parameters cannot be
null); :func:`geometry_from_params` and :func:`geometry_to_params` are the one place that rule lives.
"""
from __future__ import annotations

from typing import Any, Mapping

from crane_stiffness.model.geometry import LAB_A, LAB_B, LAB_WIRE_DIAMETER, LAB_YOUNGS_MODULUS, CraneGeometry
from crane_stiffness.params.spec import ParamSpec

PREFIX = 'geometry.'

#: Geometry parameters shared by crane_model, session_recorder and the CLI (its flags).
GEOMETRY_PARAMS: tuple[ParamSpec, ...] = (
    ParamSpec('geometry.a', LAB_A, 'half side of the platform triangle [m]', above=0.0),
    ParamSpec('geometry.b', LAB_B, 'half side of the overhead triangle [m]', above=0.0),
    ParamSpec('geometry.height', 0.5, 'height h between the triangles at the unloaded rest pose [m]',
              above=0.0),
    ParamSpec('geometry.weight', 50.0, 'total suspended weight W, acting along +z (down) [N]', low=0.0),
    ParamSpec('geometry.wire_stiffness', 0.0, 'wire stiffness k; 0 = k = A*E/l0 from diameter and modulus [N/m]',
              low=0.0),
    ParamSpec('geometry.wire_diameter', LAB_WIRE_DIAMETER, 'wire diameter d, used when wire_stiffness is 0 [m]',
              above=0.0),
    ParamSpec('geometry.youngs_modulus', LAB_YOUNGS_MODULUS, "wire Young's modulus E [Pa]", above=0.0),
    ParamSpec('geometry.com_offset', [0.0, 0.0, 0.0], 'centre of mass from the platform centre, body frame [m]',
              rule='3 finite numbers'),
    ParamSpec('geometry.load_point', [0.0, 0.0, 0.0], 'external force application point, body frame [m]',
              rule='3 finite numbers'),
    ParamSpec('geometry.length_offsets', [0.0] * 6, 'change of unstretched length of wires 1..6 [m]',
              rule='6 finite numbers'),
)


def geometry_from_params(params: Mapping[str, Any], prefix: str = PREFIX) -> CraneGeometry:
    """Build a CraneGeometry from flat parameters (missing ones take the defaults of :data:`GEOMETRY_PARAMS`; a
    ``geometry.l0`` given instead of the height, as the CLI's --l0, sets the height). Raises GeometryError."""
    given = {key[len(prefix):]: value for key, value in params.items() if key.startswith(prefix)}
    values = {spec.name[len(PREFIX):]: spec.default for spec in GEOMETRY_PARAMS}
    if 'l0' in given:
        values.pop('height')
    values.update(given)
    k = float(values.pop('wire_stiffness'))
    if k != 0.0:  # else k = A·E/l0 from the diameter and the modulus
        values['wire_stiffness'] = k
        values.pop('wire_diameter')
        values.pop('youngs_modulus')
    return CraneGeometry.from_dict(values)


def geometry_to_params(geometry: CraneGeometry, prefix: str = PREFIX) -> dict[str, Any]:
    """Inverse of :func:`geometry_from_params`."""
    d = geometry.to_dict()
    if d['wire_stiffness'] is None:
        d['wire_stiffness'] = 0.0
    else:
        d['wire_diameter'] = LAB_WIRE_DIAMETER
        d['youngs_modulus'] = LAB_YOUNGS_MODULUS
    return {prefix + k: v for k, v in d.items()}
