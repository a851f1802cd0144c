"""The sufficient statistics of the 6×6 identification, vectorised and streaming side by side
(:func:`pair_statistics` on arrays, :class:`PairAccumulator` one pair at a time, as a live estimator adds them; the
tests pin them together).

A pair is z = [w; d] (12,): the wrench w [fx, fy, fz, mx, my, mz] (N, N·m) and the pose deflection d
[u_x, u_y, u_z, θ_x, θ_y, θ_z] (m, rad) of :mod:`crane_stiffness.full6.deflection`, fixed frame, z down, labelled
with its load step (an integer: the commanded step in effect, as the load program numbers its held stretches,
crane_stiffness.full6.program.held_steps). Everything the fit needs (crane_stiffness.full6.identify) follows from the
count of all pairs and their scatter within the steps, and the count and mean of each step: the wrench design, the
fit, the pure error (the scatter within the steps, which is sensor noise alone when the true load is constant over a
step) and the lack of fit (the scatter of the step means about the fit).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from crane_stiffness.full6.errors import Full6InputError


@dataclass(frozen=True)
class PairStatistics:
    """Sufficient statistics of n labelled pairs.

    Attributes:
        n: number of pairs.
        mean: mean pair z̄ (12,) [N, N·m, m, rad].
        within: the pure-error scatter Σ_k Σ_{i in k} (z_i − z̄_k)(z_i − z̄_k)ᵀ (12, 12), summed step by step (it is
            sensor noise, a millionth of the whole scatter: taking it as a difference of the whole and the between
            scatter would cost it six digits).
        steps: the step labels seen (K,), ascending.
        step_counts: pairs of each step (K,).
        step_means: mean pair of each step (K, 12).
    """

    n: int
    mean: NDArray[np.float64]
    within: NDArray[np.float64]
    steps: NDArray[np.int64]
    step_counts: NDArray[np.int64]
    step_means: NDArray[np.float64]

    def between(self) -> NDArray[np.float64]:
        """Scatter of the step means, Σ_k n_k (z̄_k − z̄)(z̄_k − z̄)ᵀ (12, 12)."""
        c = self.step_means - self.mean
        return (c * self.step_counts[:, None]).T @ c

    @property
    def scatter(self) -> NDArray[np.float64]:
        """Scatter of all pairs, Σ (z − z̄)(z − z̄)ᵀ (12, 12) = within + between."""
        return self.within + self.between()


def _labels(step: ArrayLike, n: int) -> NDArray[np.int64]:
    s = np.asarray(step)
    if s.shape != (n,) or not (np.issubdtype(s.dtype, np.integer) or s.size == 0):
        raise Full6InputError('step', s.tolist() if s.size < 10 else f'array {s.shape} {s.dtype}',
                              f'must be {n} integer step labels, one per pair')
    return s.astype(np.int64)


def pair_statistics(wrench: ArrayLike, deflection: ArrayLike, step: ArrayLike) -> PairStatistics:
    """:class:`PairStatistics` of pairs given as arrays: wrench (n, 6), deflection (n, 6), step labels (n,)."""
    w = np.asarray(wrench, dtype=float)
    d = np.asarray(deflection, dtype=float)
    if w.ndim != 2 or w.shape[1] != 6 or d.shape != w.shape:
        raise Full6InputError('wrench, deflection', f'shapes {w.shape}, {d.shape}', 'must both be (n, 6)')
    if not (np.all(np.isfinite(w)) and np.all(np.isfinite(d))):
        raise Full6InputError('wrench, deflection', 'non-finite', 'every component must be finite')
    n = w.shape[0]
    labels = _labels(step, n)
    z = np.hstack([w, d])
    steps, inverse, counts = np.unique(labels, return_inverse=True, return_counts=True)
    sums = np.zeros((len(steps), 12))
    np.add.at(sums, inverse, z)
    means = sums / np.maximum(counts, 1)[:, None]
    residual = z - means[inverse]
    mean = counts @ means / n if n else np.zeros(12)
    return PairStatistics(n, mean, residual.T @ residual, steps, counts, means)


class PairAccumulator:
    """The same statistics, one pair at a time (:meth:`add`): per step label a count, and sums of the pairs and
    of their outer products about the step's first pair (shifted data), so a large offset costs no precision."""

    def __init__(self) -> None:
        self._n = 0
        self._steps: dict[int, tuple[list[int], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]] = {}

    @property
    def n(self) -> int:
        """Pairs added."""
        return self._n

    def reset(self) -> None:
        """Forget every pair."""
        self._n = 0
        self._steps.clear()

    def add(self, wrench: ArrayLike, deflection: ArrayLike, step: int) -> None:
        """Add one pair: wrench (6,) [N, N·m], deflection (6,) [m, rad], its step label (an integer)."""
        z = np.concatenate([np.asarray(wrench, dtype=float).reshape(6), np.asarray(deflection, dtype=float).reshape(6)])
        if not np.all(np.isfinite(z)):
            raise Full6InputError('pair', z.tolist(), 'every component must be finite')
        if isinstance(step, (bool, np.bool_)) or not isinstance(step, (int, np.integer)):
            raise Full6InputError('step', step, 'must be an integer step label')
        entry = self._steps.get(int(step))
        if entry is None:
            entry = self._steps[int(step)] = ([0], z.copy(), np.zeros(12), np.zeros((12, 12)))
        count, origin, total, total2 = entry
        s = z - origin
        count[0] += 1
        total += s
        total2 += np.outer(s, s)
        self._n += 1

    def statistics(self) -> PairStatistics:
        """The :class:`PairStatistics` of the pairs added so far."""
        if not self._n:
            return pair_statistics(np.zeros((0, 6)), np.zeros((0, 6)), np.zeros(0, dtype=np.int64))
        labels = np.array(sorted(self._steps), dtype=np.int64)
        counts = np.array([self._steps[k][0][0] for k in labels], dtype=np.int64)
        shifts = np.array([self._steps[k][2] for k in labels]) / counts[:, None]
        means = np.array([self._steps[k][1] for k in labels]) + shifts
        within = sum(self._steps[k][3] - c * np.outer(h, h) for k, c, h in zip(labels, counts, shifts))
        return PairStatistics(self._n, counts @ means / self._n, np.asarray(within), labels, counts, means)


__all__ = ['PairAccumulator', 'PairStatistics', 'pair_statistics']
