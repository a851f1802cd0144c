"""Many equilibria of one geometry at once, on every core: :func:`solve_batch_parallel`.

Same contract as :func:`crane_stiffness.model.equilibrium.solve_batch` (each case solved from the rest pose under
the weight, cases Newton cannot reach finished by load continuation), several times faster: a linear predictor
from the tangent at rest, plain Newton without allocation, the cases split over numba's threads (kernels in
:mod:`._batch_kernels`). Frames and units as in :mod:`.equilibrium` (z down; m, rad, N, N·m).

Why two solvers: ``solve_batch`` runs, case by case and in no threads of its own, the robust damped Newton of
:func:`~crane_stiffness.model.equilibrium.solve_equilibrium` (``_kernels.solve_step``); calibration uses it, and
the campaign's analysis workers, which already share the cores, load it ahead. This one trades that path for speed
on large batches (maps, benchmarks) and hands the cases its fast path cannot take to the robust one. Both share the
balance and the 6×6 elimination (:mod:`._kernels`), the outputs (:func:`~.equilibrium.batch_outputs`) and the
finishing of unconverged cases (:func:`~.equilibrium.finish_batch`).
"""
from __future__ import annotations

import numpy as np

from crane_stiffness.model import _batch_kernels as bk
from crane_stiffness.model.equilibrium import (DEFAULT_MAX_ITER, DEFAULT_XTOL, MIN_LOAD_FRACTION, BatchEquilibrium,
                                               _rest, batch_outputs, checked_loads, finish_batch, geometry_arrays,
                                               wrench_jacobian)
from crane_stiffness.model.geometry import CraneGeometry

#: Cases per parallel block: large enough that a block's scratch allocation is negligible, small enough that the
#: threads share the work evenly.
CHUNK = 512
#: Continuation steps per case before it is handed to solve_equilibrium (its own bound is 2000).
MAX_STEPS = 2000


def _threads() -> int:
    try:
        import numba
        return int(numba.get_num_threads())
    except ImportError:  # pragma: no cover - exercised only without numba
        return 1


def rest_compliance(geometry: CraneGeometry, xtol: float = DEFAULT_XTOL) -> np.ndarray:
    """C0 = K0⁻¹ (6, 6) at the rest pose under W [m/N, rad/(N·m)], cached on the geometry."""
    key = ('rest_compliance', xtol)
    if key not in geometry._derived:
        u0, q0 = _rest(geometry, xtol)
        _, k0 = wrench_jacobian(geometry, u0, q0, np.zeros(6))
        try:
            c0 = np.linalg.inv(k0)
        except np.linalg.LinAlgError:  # W = 0: no stiffness sideways at rest; predict nothing, Newton does it
            c0 = np.zeros((6, 6))
        geometry._derived[key] = np.ascontiguousarray(c0 if np.all(np.isfinite(c0)) else np.zeros((6, 6)))
    return geometry._derived[key]


def solve_batch_parallel(geometry: CraneGeometry, loads, *, xtol: float = DEFAULT_XTOL,
                         max_iter: int = DEFAULT_MAX_ITER, chunk: int = CHUNK) -> BatchEquilibrium:
    """Equilibria for many load cases of one geometry, spread over numba's threads.

    Args:
        geometry: the crane.
        loads: (N, 6) array of [fx, fy, fz, mx, my, mz] [N, N·m], fixed frame.
        xtol: tolerance on the pose [m] (as :func:`~crane_stiffness.model.equilibrium.solve_equilibrium`).
        max_iter: iterations of the robust solver for the cases the fast path hands over.
        chunk: cases per parallel block.

    Returns the same :class:`BatchEquilibrium` as ``solve_batch``. Raises NoEquilibriumError naming the first
    inadmissible case (an upward force above W) and ValueError for a non-finite load.
    """
    loads = checked_loads(geometry, loads)
    arr = geometry_arrays(geometry)
    u0, q0 = _rest(geometry, xtol)
    c0 = rest_compliance(geometry, xtol)
    n = loads.shape[0]
    out = batch_outputs(n)
    chunks = max(1, min(-(-n // max(1, int(chunk))), 64 * _threads())) if n else 0
    if n:
        bk.batch_solve_parallel(*arr.args(), loads, u0, q0, c0, xtol, max_iter, arr.lc, arr.max_move,
                                arr.min_cos_turn, arr.max_shift, MAX_STEPS, MIN_LOAD_FRACTION, chunks, *out)
    return finish_batch(geometry, loads, out, xtol, max_iter)  # the path ended: solve_equilibrium says why
