"""The rest pose's tangent stiffness of many cranes at once: one per draw of uncertain inputs (Monte Carlo).

:func:`rest_stiffness_draws` takes the inputs of N cranes as arrays (dimensions, weight, wires, unstretched length
offsets, centre of mass) and returns each one's exact tangent stiffness K (6 × 6) at its rest pose under its
weight, as ``tangent_stiffness(g, rest_pose(g))`` gives for one :class:`~.geometry.CraneGeometry` g, about a
thousand times cheaper per crane: the wire attachment points, unstretched lengths and wire stiffnesses are built
for all cranes with numpy (the points from :func:`~.geometry.overhead_vertices` and
:func:`~.geometry.platform_vertices`, which are linear in b, h and a; the lengths as the distances between them,
eq. 3; k_i = A·E/l0_i as :attr:`~.geometry.CraneGeometry.wire_stiffnesses`), each crane's rest pose is found by
compiled damped Newton from the nominal crane's (kernel in :mod:`._draw_kernels`), and a crane the fast path does
not settle is solved by the robust path (:func:`~.equilibrium.rest_pose`) on its own CraneGeometry.

Frames and units as in :mod:`.geometry` (z down; m, N, Pa; K in N/m, N/rad, N·m/rad).
"""
from __future__ import annotations

import numpy as np

from crane_stiffness.model import _draw_kernels as dk
from crane_stiffness.model import _kernels as kern
from crane_stiffness.model.equilibrium import DEFAULT_MAX_ITER, DEFAULT_XTOL, geometry_arrays, rest_pose
from crane_stiffness.model.errors import GeometryError
from crane_stiffness.model.geometry import WIRE_ENDS, CraneGeometry, overhead_vertices, platform_vertices
from crane_stiffness.model.stiffness import tangent_stiffness

_TOP = {'A': 0, 'B': 1, 'C': 2}
_PLATFORM = {'D': 0, 'E': 1, 'F': 2}
#: The fields of one row per crane, and their widths.
_ROWS = {'length_offsets': 6, 'com_offset': 3}
#: The arrays rest_stiffness_draws takes, and their shapes for N cranes.
DRAW_FIELDS = {'a': '(N,)', 'b': '(N,)', 'height': '(N,)', 'weight': '(N,)', 'wire_diameter': '(N,)',
               'youngs_modulus': '(N,)', 'wire_stiffness': '(N,)', 'length_offsets': '(N, 6)',
               'com_offset': '(N, 3)'}


def _wire_points(a: np.ndarray, b: np.ndarray, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Overhead (N, 6, 3) [fixed frame] and platform (N, 6, 3) [body frame] attachment points of wires 1..6."""
    top_b = overhead_vertices(1.0, 0.0)[[_TOP[t] for t, _ in WIRE_ENDS]]            # per unit b
    top_h = overhead_vertices(0.0, 1.0)[[_TOP[t] for t, _ in WIRE_ENDS]]            # per unit h
    plat_a = platform_vertices(1.0)[[_PLATFORM[p] for _, p in WIRE_ENDS]]           # per unit a
    top = b[:, None, None] * top_b + h[:, None, None] * top_h
    plat = a[:, None, None] * plat_a
    return np.ascontiguousarray(top), np.ascontiguousarray(plat)


def _column(name: str, value, n: int, width: int | None = None) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    shape = (n,) if width is None else (n, width)
    try:
        arr = np.broadcast_to(arr, shape)
    except ValueError:
        raise GeometryError(name, arr.shape, f'must broadcast to {shape}') from None
    if not np.all(np.isfinite(arr)):
        first = int(np.flatnonzero(~np.isfinite(arr.reshape(len(arr), -1)).any(axis=1))[0])
        raise GeometryError(name, arr[first].tolist(), f'every draw must be finite (draw {first} is not)')
    # A copy, always: a broadcast view of one draw is contiguous but read-only, and a read-only array is another
    # type to the compiled kernels (a signature compiled at run time, outside the install-time cache).
    return np.array(arr, dtype=float, order='C')


def geometry_of_draw(nominal: CraneGeometry, draws: dict[str, np.ndarray], n: int) -> CraneGeometry:
    """The CraneGeometry of draw n (validated), for the robust path and for checks."""
    changes = {'a': float(draws['a'][n]), 'b': float(draws['b'][n]), 'height': float(draws['height'][n]),
               'weight': float(draws['weight'][n]), 'length_offsets': tuple(draws['length_offsets'][n]),
               'com_offset': tuple(draws['com_offset'][n])}
    if nominal.wire_stiffness is not None:
        changes['wire_stiffness'] = float(draws['wire_stiffness'][n])
    else:
        changes['wire_diameter'] = float(draws['wire_diameter'][n])
        changes['youngs_modulus'] = float(draws['youngs_modulus'][n])
    return nominal.replace(**changes)


def rest_stiffness_draws(nominal: CraneGeometry, *, xtol: float = DEFAULT_XTOL, **inputs) -> np.ndarray:
    """Tangent stiffness at the rest pose of N cranes, (N, 6, 6) [N/m, N/rad, N·m/rad; order of :data:`AXES`].

    Args:
        nominal: the crane the draws scatter about (its rest pose starts each crane's Newton; the fields not
            given take its values; its load point plays no part at rest).
        **inputs: arrays of :data:`DRAW_FIELDS` (scalars broadcast): a, b, height [m], weight [N],
            wire_diameter [m] and youngs_modulus [Pa] (or wire_stiffness [N/m] when the nominal crane gives k),
            length_offsets (N, 6) [m], com_offset (N, 3) [m, body frame].

    Raises GeometryError naming a field that is not finite or positive where it must be (as CraneGeometry does).
    """
    unknown = sorted(set(inputs) - set(DRAW_FIELDS))
    if unknown:
        raise GeometryError(unknown[0], f'array of shape {np.shape(inputs[unknown[0]])}',
                            f'is not a draw field (known: {", ".join(DRAW_FIELDS)})')
    # N: the length of the 1-D fields, the first dimension of the 2-D ones (scalars and single rows broadcast)
    sizes = {np.shape(v)[0] for k, v in inputs.items() if np.ndim(v) == (2 if k in _ROWS else 1)}
    n = max(sizes | {1})
    base = nominal.to_dict()
    draws: dict[str, np.ndarray] = {}
    for name in ('a', 'b', 'height', 'weight', 'wire_diameter', 'youngs_modulus', 'wire_stiffness'):
        if base[name] is None:  # the wire the nominal crane does not give (k, or d and E)
            if name in inputs:
                raise GeometryError(name, f'array of shape {np.shape(inputs[name])}',
                                    'the nominal crane gives the wire the other way (k, or d and E)')
            draws[name] = np.full(n, np.nan)
        else:
            draws[name] = _column(name, inputs.get(name, base[name]), n)
    for name, width in _ROWS.items():
        draws[name] = _column(name, inputs.get(name, base[name]), n, width)
    for name in ('a', 'b', 'height'):
        if np.any(draws[name] <= 0.0):
            raise GeometryError(name, float(draws[name].min()), 'must be > 0 in every draw')
    if np.any(draws['weight'] <= 0.0):
        raise GeometryError('weight', float(draws['weight'].min()), 'must be > 0 in every draw (no rest pose '
                                                                    'to perturb without it)')
    top, plat = _wire_points(draws['a'], draws['b'], draws['height'])
    l0 = np.linalg.norm(top - plat, axis=2) + draws['length_offsets']  # eq. 3: the span at the rest height
    if nominal.wire_stiffness is not None:
        kw = np.repeat(draws['wire_stiffness'][:, None], 6, axis=1)
    else:
        area = np.pi * draws['wire_diameter'] ** 2 / 4.0
        kw = (area * draws['youngs_modulus'])[:, None] / l0
    if not np.all(kw > 0.0):
        raise GeometryError('wire_stiffness', float(np.nanmin(kw)), 'must be > 0 in every draw')
    rest = rest_pose(nominal, xtol=xtol)
    arr = geometry_arrays(nominal)
    k_out = np.empty((n, 6, 6))
    u_out = np.empty((n, 3))
    status = np.empty(n, dtype=np.int64)
    dk.rest_tangents(top, plat, np.ascontiguousarray(l0), np.ascontiguousarray(kw), draws['weight'],
                     draws['com_offset'], np.ascontiguousarray(rest.displacement, dtype=float),
                     np.ascontiguousarray(rest.rotation, dtype=float), xtol, DEFAULT_MAX_ITER, arr.lc, arr.max_move,
                     arr.min_cos_turn, arr.max_shift, k_out, u_out, status)
    for i in np.flatnonzero(status != kern.CONVERGED):  # far from the nominal crane: the robust path
        g = geometry_of_draw(nominal, draws, int(i))
        k_out[i] = tangent_stiffness(g, rest_pose(g, xtol=xtol))
    return k_out
