"""The layout of the 6×6 topics /stiffness6/stiffness, /stiffness6/stiffness_expanded and /stiffness6/compliance
(:mod:`crane_stiffness.contract.topics` STIFFNESS6, STIFFNESS6_EXPANDED, COMPLIANCE6), both directions: the one place
that writes it (the stiffness6_estimator node) and reads it (the live view, the rig's six-axis summary, the tests).

A message is a std_msgs/Float64MultiArray of 3 × 6 × 6 = 108 float64 values, row-major, ``data_offset`` 0, its
``layout.dim`` (:data:`DIMS`, label, size, stride) ``('quantity', 3, 108), ('row', 6, 36), ('column', 6, 6)``: the
MultiArrayLayout convention of std_msgs, where ``dim[0].stride`` is the whole size and entry (q, i, j) is
``data[dim[1].stride·q + dim[2].stride·i + j]`` (:func:`index`; a Foxglove message path ``.data[n]`` takes it).

- quantity (:data:`QUANTITIES`): the value, then the low and the high end of its 95 % confidence interval, entry by
  entry.
- K (/stiffness6/stiffness): rows the loads fx fy fz mx my mz (:data:`crane_stiffness.contract.axes.AXES`), columns the
  platform centre's deflections u_x u_y u_z θ_x θ_y θ_z (:data:`crane_stiffness.full6.reference.DISPLACEMENTS`),
  both in ``crane_base`` (z down); units N/m (force by translation), N/rad (force by rotation), N·m/m (moment by
  translation), N·m/rad (moment by rotation).
- K ∓ U (/stiffness6/stiffness_expanded): the same K (value) with its expanded uncertainty: the low and the high end
  are value − U and value + U (GUM, 95 %, crane_stiffness.full6.live_uncertainty), where the other topics have the
  statistical interval (the repeatability); NaN ends where no U is stated.
- C = K⁻¹ (/stiffness6/compliance): rows the deflections, columns the loads; units m/N, m/(N·m), rad/N, rad/(N·m).

Pure: numpy only. No rclpy or message package is imported at module level; :func:`to_message` imports std_msgs'
classes when it is called (or takes them as arguments), so the offline tools can import this module without ROS.
"""
from __future__ import annotations

from typing import Any, Sequence

import numpy as np
from numpy.typing import ArrayLike

from crane_stiffness.contract.axes import AXES
from crane_stiffness.errors import CraneStiffnessError

#: The three quantities along the first dimension, in order.
QUANTITIES: tuple[str, ...] = ('value', 'ci95_low', 'ci95_high')
#: The matrix side [-].
SIZE = len(AXES)
#: The data's length, 3 × 6 × 6 [-].
LENGTH = len(QUANTITIES) * SIZE * SIZE
#: ``layout.dim`` as (label, size, stride), outermost first (std_msgs/MultiArrayLayout's convention).
DIMS: tuple[tuple[str, int, int], ...] = (
    ('quantity', len(QUANTITIES), LENGTH),
    ('row', SIZE, SIZE * SIZE),
    ('column', SIZE, SIZE),
)


class LayoutError(CraneStiffnessError, ValueError):
    """Data or a layout that is not a /stiffness6/* matrix with its interval (a foreign publisher)."""


def index(quantity: str | int, row: int, column: int) -> int:
    """The position in ``data`` of entry (``row``, ``column``) of ``quantity`` (a name of :data:`QUANTITIES` or its
    index), by :data:`DIMS`' strides: what a Foxglove message path ``/stiffness6/stiffness.data[n]`` needs."""
    q = QUANTITIES.index(quantity) if quantity in QUANTITIES else quantity
    if not isinstance(q, int) or not (0 <= q < len(QUANTITIES) and 0 <= row < SIZE and 0 <= column < SIZE):
        raise LayoutError(f'entry ({quantity!r}, {row}, {column}): out of {len(QUANTITIES)} x {SIZE} x {SIZE}')
    return q * DIMS[1][2] + row * DIMS[2][2] + column


def entry(position: int) -> tuple[str, int, int]:
    """(quantity name, row, column) at ``position`` of ``data``: the inverse of :func:`index`."""
    if not 0 <= position < LENGTH:
        raise LayoutError(f'position {position}: a /stiffness6 matrix has {LENGTH} values')
    q, rest = divmod(position, DIMS[1][2])
    row, column = divmod(rest, DIMS[2][2])
    return QUANTITIES[q], row, column


def encode(value: ArrayLike, low: ArrayLike, high: ArrayLike) -> list[float]:
    """The message's ``data``: ``value`` (6, 6) and its 95 % interval ``low``, ``high`` (6, 6 each; units of the
    matrix, see the module docstring), as :data:`LENGTH` Python floats in the layout's order."""
    parts = [np.asarray(m, dtype=float) for m in (value, low, high)]
    for name, m in zip(QUANTITIES, parts):
        if m.shape != (SIZE, SIZE):
            raise LayoutError(f'{name} has shape {m.shape}: a /stiffness6 matrix is {SIZE} x {SIZE}')
    return np.concatenate([m.ravel() for m in parts]).tolist()


def decode(data: Sequence[float] | ArrayLike) -> np.ndarray:
    """(3, 6, 6) float array of a message's ``data``: [0] the value, [1] the 95 % low end, [2] the high end
    (LayoutError when it is not :data:`LENGTH` values)."""
    cube = np.asarray(data, dtype=float)
    if cube.size != LENGTH:
        raise LayoutError(f'{cube.size} values: a /stiffness6 matrix has {len(QUANTITIES)} x {SIZE} x {SIZE} = '
                          f'{LENGTH}')
    return cube.reshape(len(QUANTITIES), SIZE, SIZE)


def dims_of(msg: Any) -> tuple[tuple[str, int, int], ...]:
    """A Float64MultiArray's ``layout.dim`` as (label, size, stride) tuples (compare with :data:`DIMS`)."""
    return tuple((str(d.label), int(d.size), int(d.stride)) for d in msg.layout.dim)


def decode_message(msg: Any) -> np.ndarray:
    """(3, 6, 6) of a std_msgs/Float64MultiArray (any object with ``layout`` and ``data``), its layout checked
    against :data:`DIMS` and a zero ``data_offset`` (LayoutError otherwise)."""
    dims = dims_of(msg)
    if dims != DIMS or int(msg.layout.data_offset) != 0:
        raise LayoutError(f'layout {dims} offset {msg.layout.data_offset}: a /stiffness6 matrix is laid out as '
                          f'{DIMS} offset 0')
    return decode(msg.data)


def to_message(value: ArrayLike, low: ArrayLike, high: ArrayLike, message_type: Any = None,
               dimension_type: Any = None) -> Any:
    """A std_msgs/Float64MultiArray of ``value`` with its interval (see :func:`encode`), its layout :data:`DIMS`.
    ``message_type`` and ``dimension_type`` default to std_msgs' Float64MultiArray and MultiArrayDimension, imported
    here (the module itself imports no ROS)."""
    if message_type is None or dimension_type is None:
        from std_msgs.msg import Float64MultiArray, MultiArrayDimension
        message_type = message_type or Float64MultiArray
        dimension_type = dimension_type or MultiArrayDimension
    msg = message_type()
    msg.layout.dim = [dimension_type(label=label, size=size, stride=stride) for label, size, stride in DIMS]
    msg.layout.data_offset = 0
    msg.data = encode(value, low, high)
    return msg


__all__ = ['DIMS', 'LENGTH', 'LayoutError', 'QUANTITIES', 'SIZE', 'decode', 'decode_message',
           'dims_of', 'encode', 'entry', 'index', 'to_message']
