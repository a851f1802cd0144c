"""Config files in the ROS 2 parameter YAML format, read the same way by the nodes and by the offline CLI.

A file holds ``<node name or /**>: ros__parameters: {name: value}``; nested mappings flatten to dotted names the way
rclpy does (``geometry: {a: 0.1}`` is the parameter ``geometry.a``); crane_stiffness.param_files reads them. The
crane's geometry parameters are defined here once (name, type, unit, description) so the nodes declare exactly what
the CLI reads.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

import yaml

from crane_stiffness import PACKAGE
from crane_stiffness.errors import CraneStiffnessError
from crane_stiffness.model.geometry import LAB_A, LAB_B, LAB_WIRE_DIAMETER, LAB_YOUNGS_MODULUS, CraneGeometry
from crane_stiffness.param_files import ParamFile, applicable_sections, flatten_params  # noqa: F401 (re-exported)


class ConfigError(CraneStiffnessError, ValueError):
    """A config file that cannot be read or holds a bad value; the message names the file and the key."""


@dataclass(frozen=True)
class ParamSpec:
    """One ROS parameter: name, default (its type is the parameter's type), description with the unit.

    ``low``/``high`` bound a number (inclusive; they become the descriptor's ``floating_point_range`` or
    ``integer_range``, which rclpy enforces too); ``rule`` is the remaining rule in words (the descriptor's
    ``additional_constraints``, e.g. '> 0'), checked by the node's own validation.
    """

    name: str
    default: Any
    description: str
    low: float | int | None = None
    high: float | int | None = None
    rule: str = ''


#: Geometry parameters shared by crane_model, stiffness_estimator and the CLI. wire_stiffness = 0 means "derive k
#: from wire_diameter and youngs_modulus" (ROS parameters cannot be null).
GEOMETRY_PARAMS: tuple[ParamSpec, ...] = (
    ParamSpec('geometry.a', LAB_A, 'half side of the platform triangle [m]', rule='> 0'),
    ParamSpec('geometry.b', LAB_B, 'half side of the overhead triangle [m]', rule='> 0'),
    ParamSpec('geometry.height', 0.5, 'height h between the triangles at the unloaded rest pose [m]',
              rule='> 0'),
    ParamSpec('geometry.weight', 50.0, 'total suspended weight W, acting along +z (down) [N]', low=0.0),
    ParamSpec('geometry.wire_stiffness', 0.0, 'wire stiffness k [N/m]; 0 = k = A*E/l0 from diameter and modulus',
              low=0.0),
    ParamSpec('geometry.wire_diameter', LAB_WIRE_DIAMETER, 'wire diameter d [m] (used when wire_stiffness is 0)',
              rule='> 0'),
    ParamSpec('geometry.youngs_modulus', LAB_YOUNGS_MODULUS, "wire Young's modulus E [Pa]", rule='> 0'),
    ParamSpec('geometry.com_offset', [0.0, 0.0, 0.0], 'centre of mass from the platform centre, body frame [m]',
              rule='3 finite numbers'),
    ParamSpec('geometry.load_point', [0.0, 0.0, 0.0], 'external force application point, body frame [m]',
              rule='3 finite numbers'),
    ParamSpec('geometry.length_offsets', [0.0] * 6, 'change of unstretched length of wires 1..6 [m]',
              rule='6 finite numbers'),
)


def geometry_from_params(params: Mapping[str, Any], prefix: str = 'geometry.') -> CraneGeometry:
    """Build a CraneGeometry from flat parameters (missing ones take the defaults above). Raises GeometryError."""
    values = {spec.name[len('geometry.'):]: spec.default for spec in GEOMETRY_PARAMS}
    for key, value in params.items():
        if key.startswith(prefix):
            values[key[len(prefix):]] = value
    k = float(values.pop('wire_stiffness'))
    if k != 0.0:
        values['wire_stiffness'] = k
        values.pop('wire_diameter')
        values.pop('youngs_modulus')
    return CraneGeometry.from_dict(values)


def geometry_to_params(geometry: CraneGeometry, prefix: str = 'geometry.') -> dict[str, Any]:
    """Inverse of :func:`geometry_from_params`."""
    d = geometry.to_dict()
    if d['wire_stiffness'] is None:
        d['wire_stiffness'] = 0.0
    else:
        d['wire_diameter'] = LAB_WIRE_DIAMETER
        d['youngs_modulus'] = LAB_YOUNGS_MODULUS
    return {prefix + k: v for k, v in d.items()}


def load_params(path: str | os.PathLike, node_name: str | None = None) -> dict[str, Any]:
    """Flat parameters of a ROS parameter YAML file for the node ``node_name`` (its name, or its fully qualified
    name), the sections applied the way ROS applies them (crane_stiffness.param_files: ``/**`` and other
    wildcards first, then the node's own). Without ``node_name`` every section is merged in file order.
    """
    path = Path(path)
    try:
        file = ParamFile.read(path)
    except FileNotFoundError:
        raise ConfigError(f'{path}: no such config file') from None
    except yaml.YAMLError as exc:
        raise ConfigError(f'{path}: not valid YAML: {exc}') from None
    if not file.is_mapping:
        raise ConfigError(f'{path}: expected "<node>: ros__parameters: ..." at the top level')
    keys = applicable_sections(file.sections, node_name)
    for key in keys:
        if file.sections[key] is None:
            raise ConfigError(f'{path}: section {key!r} has no ros__parameters mapping')
    return file.params(keys)


def share_dir() -> Path:
    """The package's share directory: via the ament index when available, else next to the sources."""
    try:
        from ament_index_python.packages import PackageNotFoundError, get_package_share_directory
        try:
            share = Path(get_package_share_directory(PACKAGE))
            if (share / 'config').is_dir():
                return share
        except PackageNotFoundError:
            pass
    except ImportError:  # offline analysis without ROS
        pass
    candidate = Path(os.sys.prefix) / 'share' / PACKAGE
    if (candidate / 'config').is_dir():
        return candidate
    return Path(__file__).resolve().parent.parent


def config_path(name: str) -> Path:
    """A file of the installed config/ directory (``name`` with or without .yaml), or ``name`` itself if it exists."""
    p = Path(name)
    if p.exists():
        return p
    fname = name if name.endswith('.yaml') else name + '.yaml'
    found = share_dir() / 'config' / fname
    if not found.exists():
        raise ConfigError(f'{name}: not a file, and no {fname} in {share_dir() / "config"}')
    return found
