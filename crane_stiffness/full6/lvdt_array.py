"""The platform's pose deflection from an array of LVDTs: n >= 6 displacement sensors touching the platform determine
the deflection 6-vector d = [u_x, u_y, u_z, θ_x, θ_y, θ_z] of crane_stiffness.full6.deflection. Pure numpy.

Frames and units: crane_base (fixed, z down), SI (m, rad). LVDT i touches the platform at the contact point p_i
(body frame, m) and measures along the unit direction n_i (fixed frame); it was zeroed at the rest pose (u0, R0),
the pose under the weight alone the deflection is taken from. Its reading is the displacement of its contact point
along n_i, lateral motion unseen (crane_stiffness.sim.sensors.LvdtModel)::

    r_i(d) = n_i · (δu + (exp([δθ]×) − I)·a_i),      a_i = R0·p_i  (the lever arm, fixed frame)

u0 cancels; R0 enters through the lever arms. To first order r = J0·d, row i of J0 = [n_iᵀ, (a_i × n_i)ᵀ] (the
Plücker coordinates of the measuring line). :meth:`LvdtArray.solve` takes the weighted least-squares solution
d = (J0ᵀ·W·J0)⁻¹·J0ᵀ·W·r, W = diag(σ_i⁻²), and with ``exact`` (the default) goes on with Gauss-Newton on the exact
model, J(d) row i = [n_iᵀ, ((exp([δθ]×)·a_i) × n_i)ᵀ·J_l(δθ)] (J_l the left Jacobian of SO(3)), until the step is
rounding. The covariance is (Jᵀ·W·J)⁻¹ at the solution: the sensors' noise propagated to first order.

The first-order solution alone is off by the second-order terms of the rotation: each reading differs from J0·d by
at most (|δθ|²/2 + |δθ|³/6)·|a_i|, so d by at most |P| times that, component-wise, P = (J0ᵀ·W·J0)⁻¹·J0ᵀ·W
(:meth:`LvdtArray.second_order_bound`). On the lab arrangement at |δθ| = 1 mrad the bound is 9e-8 m and 7e-7 rad,
about half the standard error the LVDTs' noise gives (1.6e-7 m, 1.2e-6 rad at 2e-7 m each): above a few tenths of a
milliradian the exact iteration matters.

**Determinability.** An arrangement is refused (:class:`~crane_stiffness.full6.errors.ArrangementError`, naming it)
with fewer than six LVDTs, when it leaves a motion unseen (rank < 6; the motion is named), or when its condition
number exceeds ``max_condition`` (:data:`MAX_CONDITION`, 100): the ratio of the largest to the smallest singular
value of J0 with each row weighted by σ_min/σ_i and the rotation columns multiplied by 1/L, L the RMS lever arm |a_i|.
A rotation then counts by the displacement it causes at the arrangement's radius and the number has no unit: 1 when
every motion is seen alike, 100 when some motion is seen a hundred times less well than the best seen (its standard
error a hundred times larger for the same displacement at the radius).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from crane_stiffness.full6.errors import ArrangementError, Full6InputError
from crane_stiffness.model.geometry import LAB_A, platform_vertices

#: The deflection's components, in order (topics.STIFFNESS6's columns).
DEFLECTION_NAMES = ('ux', 'uy', 'uz', 'thx', 'thy', 'thz')
#: Largest condition number of an accepted arrangement (module docstring).
MAX_CONDITION = 100.0
#: A singular value below this share of the largest is a motion the arrangement does not see (rank < 6).
RANK_TOLERANCE = 1e-10
#: The lab LVDTs' noise (crane_stiffness.sim.sensors.LVDT_PARAMS) [m].
LAB_LVDT_NOISE = 2.0e-7


def _matrix(field: str, value: ArrayLike, columns: int) -> NDArray[np.float64]:
    array = np.array(value, dtype=float)
    if array.ndim != 2 or array.shape[1] != columns:
        raise Full6InputError(field, np.asarray(value).tolist(), f'must be n rows of {columns} numbers')
    if not np.isfinite(array).all():
        raise Full6InputError(field, array.tolist(), 'must be finite')
    return array


def _skew_series(theta: NDArray[np.float64], closed, series) -> tuple[NDArray[np.float64], ...]:
    """[θ]× (…, 3, 3) and coefficients closed(angle) where the angle is >= 1e-2 rad, series(angle²) below (the
    closed forms cancel digits there; three terms of the series are exact to rounding)."""
    angle = np.linalg.norm(theta, axis=-1)[..., None, None]
    small = angle < 1e-2
    k = np.zeros(theta.shape[:-1] + (3, 3))
    k[..., 0, 1], k[..., 0, 2], k[..., 1, 2] = -theta[..., 2], theta[..., 1], -theta[..., 0]
    k[..., 1, 0], k[..., 2, 0], k[..., 2, 1] = theta[..., 2], -theta[..., 1], theta[..., 0]
    safe = np.where(small, 1.0, angle)
    return (k, *(np.where(small, s, c) for c, s in zip(closed(safe), series(angle * angle))))


def rotation_matrices(theta: NDArray[np.float64]) -> NDArray[np.float64]:
    """exp([θ]×) (…, 3, 3) of rotation vectors θ (…, 3) [rad] (Rodrigues, vectorised;
    crane_stiffness.model.rotation.rotvec_to_matrix one at a time)."""
    k, a, b = _skew_series(theta, lambda t: (np.sin(t) / t, (1.0 - np.cos(t)) / t ** 2),
                           lambda t2: (1.0 - t2 / 6.0 + t2 * t2 / 120.0, 0.5 - t2 / 24.0 + t2 * t2 / 720.0))
    return np.eye(3) + a * k + b * (k @ k)


def left_jacobian(theta: NDArray[np.float64]) -> NDArray[np.float64]:
    """Left Jacobians J_l (…, 3, 3) of SO(3) at rotation vectors θ (…, 3) [rad]: to first order in δ,
    exp([θ + δ]×) = exp([J_l·δ]×)·exp([θ]×)."""
    k, a, b = _skew_series(theta, lambda t: ((1.0 - np.cos(t)) / t ** 2, (t - np.sin(t)) / t ** 3),
                           lambda t2: (0.5 - t2 / 24.0 + t2 * t2 / 720.0, 1.0 / 6.0 - t2 / 120.0 + t2 * t2 / 5040.0))
    return np.eye(3) + a * k + b * (k @ k)


def _echelon(basis: NDArray[np.float64]) -> NDArray[np.float64]:
    """The reduced row echelon form of the rows of ``basis`` (k, 6): the same motions, each with as few components as
    the others allow (the unseen motions of an arrangement as 'ux', 'uy', 'thz·L', not rotated mixtures)."""
    rows = basis.copy()
    lead = 0
    for i in range(len(rows)):
        while lead < rows.shape[1] and np.abs(rows[i:, lead]).max() < 1e-9:
            lead += 1
        if lead == rows.shape[1]:
            break
        pivot = i + int(np.argmax(np.abs(rows[i:, lead])))
        rows[[i, pivot]] = rows[[pivot, i]]
        rows[i] /= rows[i, lead]
        others = np.arange(len(rows)) != i
        rows[others] -= np.outer(rows[others, lead], rows[i])
        lead += 1
    rows[np.abs(rows) < 1e-9] = 0.0
    return rows


def _motion(v: NDArray[np.float64]) -> str:
    """A motion (6,) in the scaled coordinates [u, L·θ] in words: 'thz·L', or 'ux +1.000, thz·L -0.500' (scaled
    to its largest component)."""
    names = [n + ('·L' if i >= 3 else '') for i, n in enumerate(DEFLECTION_NAMES)]
    v = v / np.abs(v).max()
    parts = [(name, c) for name, c in zip(names, v) if abs(c) >= 0.01]
    if len(parts) == 1:
        return parts[0][0]
    return ', '.join(f'{name} {c:+.3f}' for name, c in parts)


@dataclass(frozen=True)
class LvdtPoseSolution:
    """Deflections solved from LVDT readings: one (shapes as written) or a batch of m (a leading axis m)."""

    deflection: NDArray[np.float64]   #: d (6,) [m, m, m, rad, rad, rad], fixed frame
    covariance: NDArray[np.float64]   #: its covariance (6, 6) from the LVDTs' noise [m², m·rad, rad²]
    residuals: NDArray[np.float64]    #: readings minus the model's readings at d (n,) [m]
    iterations: int                   #: Gauss-Newton steps taken (0: the first-order solution)
    converged: bool                   #: the last step was rounding (always True for the first order)

    @property
    def stderr(self) -> NDArray[np.float64]:
        """Standard errors of the deflection's components (6,) [m, rad]."""
        return np.sqrt(np.diagonal(self.covariance, axis1=-2, axis2=-1))


class LvdtArray:
    """An arrangement of n >= 6 LVDTs on the platform (module docstring); refused if it cannot determine the pose."""

    def __init__(self, contact_points: ArrayLike, directions: ArrayLike, noise_std: ArrayLike = LAB_LVDT_NOISE, *,
                 name: str = 'LVDT array', rest_rotation: ArrayLike | None = None,
                 max_condition: float = MAX_CONDITION) -> None:
        """Create the arrangement.

        Args:
            contact_points: p_i, (n, 3) [m], body frame (from the platform centre).
            directions: n_i, (n, 3), fixed frame; normalised, each non-zero.
            noise_std: the LVDTs' white noise, one number or n, > 0 [m].
            name: what errors call the arrangement.
            rest_rotation: R0, body -> fixed, (3, 3), at which the LVDTs were zeroed (None: identity).
            max_condition: the largest condition number accepted (module docstring), >= 1.
        """
        self.name = str(name)
        self._points = _matrix('contact_points', contact_points, 3)
        directions = _matrix('directions', directions, 3)
        n = len(self._points)
        if directions.shape != (n, 3):
            raise Full6InputError('directions', directions.tolist(), f'must be {n} rows, one per contact point')
        norms = np.linalg.norm(directions, axis=1)
        if (norms == 0.0).any():
            raise Full6InputError('directions', directions.tolist(), f'row {int(np.argmin(norms))} is zero')
        self._directions = directions / norms[:, None]
        noise = np.asarray(noise_std, dtype=float)
        if noise.ndim == 0:
            noise = np.full(n, float(noise))
        if noise.shape != (n,) or not (np.isfinite(noise).all() and (noise > 0.0).all()):
            raise Full6InputError('noise_std', np.asarray(noise_std).tolist(), f'must be one or {n} numbers > 0')
        self._noise = noise.copy()
        r0 = np.eye(3) if rest_rotation is None else np.asarray(rest_rotation, dtype=float)
        if r0.shape != (3, 3) or not np.allclose(r0 @ r0.T, np.eye(3), atol=1e-9) or np.linalg.det(r0) <= 0.0:
            raise Full6InputError('rest_rotation', r0.tolist(), 'must be a 3×3 rotation matrix')
        self._arms = self._points @ r0.T
        if not max_condition >= 1.0:
            raise Full6InputError('max_condition', max_condition, 'must be >= 1')
        self.max_condition = float(max_condition)
        self._j0 = self._rows(self._directions[None], self._arms[None])[0]
        self.radius = float(np.sqrt(np.mean(np.sum(self._arms ** 2, axis=1))))
        self.rank, self.condition_number = self._check()
        weights = 1.0 / self._noise ** 2
        self._cov0 = np.linalg.inv(self._j0.T @ (weights[:, None] * self._j0))
        self._projection = self._cov0 @ self._j0.T * weights  # P = (J0ᵀWJ0)⁻¹J0ᵀW, (6, n)

    @staticmethod
    def _rows(directions: NDArray[np.float64], arms: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.concatenate([np.broadcast_to(directions, arms.shape), np.cross(arms, directions)], axis=-1)

    def _check(self) -> tuple[int, float]:
        n = len(self._points)
        if n < 6:
            raise ArrangementError(f"LVDT arrangement '{self.name}': {n} LVDTs cannot determine the 6 components of "
                                   'the pose (6 at least)', name=self.name, rank=n, condition=math.inf)
        scale = np.array([1.0] * 3 + [1.0 / self.radius if self.radius > 0.0 else 1.0] * 3)
        whitened = (self._noise.min() / self._noise)[:, None] * self._j0 * scale
        _, s, vt = np.linalg.svd(whitened)
        rank = int(np.sum(s > s[0] * RANK_TOLERANCE))
        condition = float(s[0] / s[-1]) if s[-1] > 0.0 else math.inf
        unseen = vt[-1] * np.sign(vt[-1][np.argmax(np.abs(vt[-1]))])
        where = f'(L = {self.radius:.4g} m, the RMS lever arm)'
        if rank < 6:
            unseen_rows = _echelon(vt[rank:])
            motions = ('the motion ' if len(unseen_rows) == 1 else 'the motions ') + '; '.join(map(_motion,
                                                                                                 unseen_rows))
            raise ArrangementError(f"LVDT arrangement '{self.name}': sees only {rank} of the 6 independent motions; "
                                   f'no LVDT reads {motions} {where}', name=self.name, rank=rank,
                                   condition=math.inf, unseen=unseen)
        if not condition <= self.max_condition:
            raise ArrangementError(f"LVDT arrangement '{self.name}': condition number {condition:.4g} exceeds "
                                   f'{self.max_condition:g}: the motion {_motion(unseen)} {where} is seen '
                                   f'{condition:.4g} times less well than the best seen', name=self.name, rank=rank,
                                   condition=condition, unseen=unseen)
        return rank, condition

    # --- the arrangement ---
    @property
    def n(self) -> int:
        """Number of LVDTs."""
        return len(self._points)

    @property
    def contact_points(self) -> NDArray[np.float64]:
        """p_i (n, 3) [m], body frame (a copy)."""
        return self._points.copy()

    @property
    def directions(self) -> NDArray[np.float64]:
        """Unit n_i (n, 3), fixed frame (a copy)."""
        return self._directions.copy()

    @property
    def noise_std(self) -> NDArray[np.float64]:
        """σ_i (n,) [m] (a copy)."""
        return self._noise.copy()

    @property
    def first_order_jacobian(self) -> NDArray[np.float64]:
        """J0 (n, 6): readings [m] per deflection [m, rad] at the rest pose (a copy)."""
        return self._j0.copy()

    @property
    def first_order_projection(self) -> NDArray[np.float64]:
        """P (6, n): the first-order solution d = P·r (a copy)."""
        return self._projection.copy()

    # --- forward model and solution ---
    def readings(self, deflection: ArrayLike) -> NDArray[np.float64]:
        """The exact, noise-free readings (n,) or (m, n) [m] of deflections (6,) or (m, 6) [m, rad]."""
        d = np.asarray(deflection, dtype=float)
        if d.shape[-1:] != (6,) or d.ndim > 2:
            raise Full6InputError('deflection', d.tolist(), 'must have shape (6,) or (m, 6)')
        moved = np.einsum('...ij,nj->...ni', rotation_matrices(d[..., 3:]), self._arms) - self._arms
        return np.einsum('...ni,ni->...n', d[..., None, :3] + moved, self._directions)

    def jacobian(self, deflection: ArrayLike) -> NDArray[np.float64]:
        """J(d) (n, 6) or (m, n, 6): the derivative of the exact readings by the deflection [m, rad] (J0 at d = 0)."""
        d = np.asarray(deflection, dtype=float)
        arms = np.einsum('...ij,nj->...ni', rotation_matrices(d[..., 3:]), self._arms)
        rows = self._rows(self._directions, arms)
        rows[..., 3:] = np.einsum('...ni,...ij->...nj', rows[..., 3:], left_jacobian(d[..., 3:]))
        return rows

    def solve(self, readings: ArrayLike, *, exact: bool = True, max_iterations: int = 10) -> LvdtPoseSolution:
        """The deflection from readings (n,) or a batch (m, n) [m] (module docstring).

        ``exact``: iterate on the exact rigid motion (to rounding; at most ``max_iterations`` steps); otherwise the
        first-order solution, whose covariance is exact. Batches give (m, 6), (m, 6, 6), (m, n).
        """
        r = np.asarray(readings, dtype=float)
        if r.shape[-1:] != (self.n,) or r.ndim > 2 or not np.isfinite(r).all():
            raise Full6InputError('readings', r.tolist(), f'must be {self.n} finite numbers, or m rows of them')
        d = r @ self._projection.T
        iterations, converged = 0, True
        if exact:
            weights = 1.0 / self._noise ** 2
            scale = np.array([1.0] * 3 + [self.radius] * 3)
            floor = 16.0 * np.finfo(float).eps * self.radius
            converged = False
            while iterations < max_iterations and not converged:
                j = self.jacobian(d)
                jw = np.swapaxes(j, -1, -2) * weights
                step = np.linalg.solve(jw @ j, (jw @ (r - self.readings(d))[..., None]))[..., 0]
                d = d + step
                iterations += 1
                # rounding: a step below 1e-13 of the motion at the arrangement's radius, or below the rounding of
                # the contact points' coordinates (a few ulps of the radius), which the readings carry
                size = np.max(np.abs(d * scale), axis=-1)
                converged = bool(np.all(np.max(np.abs(step * scale), axis=-1) <= 1e-13 * size + floor))
            j = self.jacobian(d)
            jw = np.swapaxes(j, -1, -2) * weights
            covariance: NDArray[np.float64] = np.linalg.inv(jw @ j).astype(float)
        else:
            covariance = np.broadcast_to(self._cov0, d.shape[:-1] + (6, 6)).copy()
        return LvdtPoseSolution(d, covariance, r - self.readings(d), iterations, converged)

    def second_order_bound(self, deflection: ArrayLike) -> NDArray[np.float64]:
        """Bound (6,) or (m, 6) on |first-order solution − d| of exact readings of ``deflection`` [m, rad]: |P| times
        the terms beyond the first order, (|δθ|²/2 + |δθ|³/6)·|a_i| (module docstring)."""
        d = np.asarray(deflection, dtype=float)
        angle = np.linalg.norm(d[..., 3:], axis=-1)[..., None]
        beyond = (angle ** 2 / 2.0 + angle ** 3 / 6.0) * np.linalg.norm(self._arms, axis=1)
        return beyond @ np.abs(self._projection).T


def lab_arrangement(a: float = LAB_A, noise_std: float = LAB_LVDT_NOISE, *,
                    rest_rotation: ArrayLike | None = None) -> LvdtArray:
    """Six LVDTs for the lab model: at each platform vertex D, E, F (crane_stiffness.model.geometry, half side ``a``
    [m]) one horizontal and tangential (z × the vertex's radial direction) and one vertical (+z, down), in that order
    (D, E, F tangential, then D, E, F vertical). The tangential ones see u_x, u_y, θ_z; the vertical ones u_z, θ_x,
    θ_y; condition number √2. ``noise_std`` [m]: each LVDT's; ``rest_rotation``: see :class:`LvdtArray`."""
    vertices = platform_vertices(a)
    radial = vertices / np.linalg.norm(vertices, axis=1)[:, None]
    tangential = np.cross([0.0, 0.0, 1.0], radial)
    vertical = np.tile([0.0, 0.0, 1.0], (3, 1))
    return LvdtArray(np.vstack([vertices, vertices]), np.vstack([tangential, vertical]), noise_std,
                     name='lab: tangential and vertical at D, E, F', rest_rotation=rest_rotation)


__all__ = ['DEFLECTION_NAMES', 'LAB_LVDT_NOISE', 'MAX_CONDITION', 'LvdtArray', 'LvdtPoseSolution', 'lab_arrangement',
           'left_jacobian', 'rotation_matrices']
