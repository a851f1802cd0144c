"""The geometry flags the command lines share (``crane-stiffness solve``, ``stiffness``, ``sweep``, ``workspace
...``): :func:`add_geometry` adds them to a parser, :func:`geometry_from_args` reads the geometry they describe."""
from __future__ import annotations

import argparse
from typing import Any

from crane_stiffness.errors import CraneStiffnessError
from crane_stiffness.model import CraneGeometry
from crane_stiffness.model.geometry import lab_model_fields
from crane_stiffness.nodes import NODES
from crane_stiffness.params.files import config_path, load_params
from crane_stiffness.params.geometry import GEOMETRY_PARAMS, PREFIX, geometry_from_params, geometry_to_params


class UsageError(CraneStiffnessError):
    """Bad command-line input."""


#: Short flags kept for geometry parameters (the long form, --com-offset, works too).
_FLAG_ALIASES = {'com_offset': '--com'}


def add_geometry(p: argparse.ArgumentParser) -> None:
    """--config, --lab-model, --l0 and one flag per geometry parameter (params.geometry: its description, rule and
    unit), e.g. ``geometry.wire_stiffness`` is ``--wire-stiffness``."""
    g = p.add_argument_group('geometry (SI units; flags override --config)')
    g.add_argument('--config', metavar='FILE', help='ROS parameter YAML with geometry.* parameters '
                   '(a path, or a name in the installed config/, e.g. crane_lab)')
    g.add_argument('--node', default=None, help='section of --config to read (default: all sections, /** first)')
    g.add_argument('--lab-model', action='store_true',
                   help="the paper's lab model: a = b = 0.1143 m, d = 1.08 mm, E = 206,831 MPa")
    for spec in GEOMETRY_PARAMS:
        name = spec.name[len(PREFIX):]
        flags = ['--' + name.replace('_', '-')] + ([_FLAG_ALIASES[name]] if name in _FLAG_ALIASES else [])
        rule = spec.rule_text()
        help_text = spec.description + (f' ({rule})' if rule else '')
        if isinstance(spec.default, list):
            g.add_argument(*flags, dest=name, type=float, nargs=len(spec.default), metavar='V', help=help_text)
        else:
            g.add_argument(*flags, dest=name, type=float, help=help_text)
    g.add_argument('--l0', type=float, help='unstretched wire length instead of --height [m]')


def config_geometry_params(config: str, node: str | None = None) -> dict[str, Any]:
    """Every geometry.* parameter of a ROS parameter YAML (a path, or a name in the installed config/), those the
    file does not set at their defaults: what ``--config`` reads, here and in ``analyze``/``compare``. Raises
    ConfigError / GeometryError naming the file or the bad value."""
    # (a section close to one of the package's nodes that applies to none can only be a typo: refused)
    return geometry_to_params(geometry_from_params(load_params(config_path(config), node, known_nodes=NODES)))


def geometry_from_args(args: argparse.Namespace) -> CraneGeometry:
    """The geometry the flags and --config describe, read as geometry parameters (params.geometry: the one reading of
    ``wire_stiffness`` 0). A flag beats --config; --wire-stiffness beats a diameter and modulus from --config, and
    --wire-diameter / --youngs-modulus beat a stiffness from it. Raises GeometryError / ConfigError / UsageError
    naming the bad value."""
    params: dict[str, Any] = {}
    if args.config:
        params = config_geometry_params(args.config, args.node)
    if args.lab_model:
        params.update({PREFIX + k: v for k, v in lab_model_fields().items()})
        params[PREFIX + 'wire_stiffness'] = 0.0
    given = {spec.name: getattr(args, spec.name[len(PREFIX):]) for spec in GEOMETRY_PARAMS}
    given = {k: v for k, v in given.items() if v is not None}
    if PREFIX + 'wire_stiffness' not in given and (PREFIX + 'wire_diameter' in given or
                                                   PREFIX + 'youngs_modulus' in given):
        given[PREFIX + 'wire_stiffness'] = 0.0  # k from the diameter and modulus given
    params.update(given)
    if args.l0 is not None:
        if args.height is not None:
            raise UsageError('give --height or --l0, not both')
        params.pop(PREFIX + 'height', None)
        params[PREFIX + 'l0'] = args.l0
    for name in ('a', 'b', 'weight'):
        if PREFIX + name not in params:
            raise UsageError(f'--{name} is required (or --config FILE / --lab-model)')
    if PREFIX + 'height' not in params and PREFIX + 'l0' not in params:
        raise UsageError('--height (or --l0) is required, or --config FILE')
    return geometry_from_params(params)
