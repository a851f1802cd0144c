"""The six load axes of the rig, in the one order used everywhere: wrench components [fx, fy, fz, mx, my, mz]
(N, N·m) and the matching displacements [u_x, u_y, u_z, θ_x, θ_y, θ_z] (m, rad) of the stiffness matrices, in the
paper's frame (``crane_base``: x, y horizontal, z down). Pure Python, no imports: every layer may use it.
"""
from __future__ import annotations

AXES: tuple[str, ...] = ('fx', 'fy', 'fz', 'mx', 'my', 'mz')
#: The force axes (stiffness in N/m); the others are moment axes (N·m/rad).
FORCE_AXES: tuple[str, ...] = AXES[:3]


def axis_index(axis: str) -> int:
    """Index 0..5 of an axis name fx fy fz mx my mz (the load component and the matching displacement)."""
    try:
        return AXES.index(axis)
    except ValueError:
        raise ValueError(f'axis = {axis!r}: must be one of {", ".join(AXES)}') from None


__all__ = ['AXES', 'FORCE_AXES', 'axis_index']
