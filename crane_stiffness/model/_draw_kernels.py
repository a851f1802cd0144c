"""Compiled kernel for many cranes at once: the rest pose and tangent stiffness of each (one per Monte Carlo draw of
uncertain dimensions, wires and weight). Drives :func:`._kernels.solve_step` and :func:`._kernels.assemble_into`
(the one implementation of the balance and its Jacobian); no physics of its own.

Units and frames as in :mod:`._kernels`: fixed frame, z down, u [m], Q body→fixed, stiffness [N/m, N·m/rad].
"""
from __future__ import annotations

import numpy as np

from crane_stiffness.model import _kernels as kern
from crane_stiffness.model._kernels import njit


@njit(cache=True)
def rest_tangents(top, plat, l0, kw, weight, com, u0, q0, xtol, max_iter, lc, max_move, min_cos_turn, max_shift,
                  k_out, u_out, status_out):
    """For each crane n (top (N,6,3), plat (N,6,3), l0 (N,6), kw (N,6), weight (N,), com (N,3)): damped Newton
    under the weight alone from the pose (u0, q0) (a nearby crane's rest pose), then K = −∂w/∂x there into
    k_out[n] (6, 6), the centre's displacement into u_out[n] (3,) and the solver status into status_out[n]
    (kern.CONVERGED, or the case is left to the robust solver)."""
    n_cases = top.shape[0]
    ploc = np.zeros(3)
    load = np.zeros(6)
    u = np.empty(3)
    q = np.empty((3, 3))
    lengths = np.empty(6)
    tensions = np.empty(6)
    w = np.empty(6)
    m33 = np.empty((3, 3, 3))
    v3 = np.empty((4, 3))
    for n in range(n_cases):
        for i in range(3):
            u[i] = u0[i]
            for j in range(3):
                q[i, j] = q0[i, j]
        status, _ = kern.solve_step(top[n], plat[n], l0[n], kw[n], weight[n], com[n], ploc, load, u, q, xtol,
                                    max_iter, lc, max_move, min_cos_turn, max_shift, lengths, tensions, w)
        status_out[n] = status
        kern.assemble_into(top[n], plat[n], l0[n], kw[n], weight[n], com[n], ploc, load, u, q, w, k_out[n],
                           lengths, tensions, True, m33, v3)
        for i in range(3):
            u_out[n, i] = u[i]
