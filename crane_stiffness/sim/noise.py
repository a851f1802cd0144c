"""Coloured noise and zero drift of a simulated sensor, per channel (the load cell's six axes, an LVDT's one). No ROS.

On top of a sensor model's white noise, one reading at time t [s] of channel i carries::

    e_i(t) = x_i(t) + f_i(t) + A_i·sin(2π·f_mains·t + φ_i) + w_i(t)

- x: AR(1) (a first-order Gauss-Markov process, e.g. floor vibration through the rig): stationary standard
  deviation ``ar1_std``, correlation time ``ar1_tau_s``; between samples Δt apart
  ``x ← φ·x + sqrt(1 − φ²)·ar1_std·n`` with ``φ = exp(−Δt/ar1_tau_s)``, so its autocorrelation at lag Δt is φ.
- f: 1/f (flicker) noise of standard deviation ``flicker_std``: the sum of :data:`FLICKER_POLES` AR(1) processes of
  equal variance with correlation times one decade apart (1 ms to 100 s), whose spectrum falls as 1/f between
  about 0.002 Hz and 200 Hz.
- the mains line: amplitude ``mains_amplitude`` at ``mains_hz`` (50 or 60 Hz), phase φ_i drawn once per channel.
- w: zero drift as a random walk, ``random_walk`` per sqrt(second): ``w ← w + random_walk·sqrt(Δt)·n``, from 0.

Units are the channel's (N, N·m, m). Every sample draws the same numbers (one per AR(1) process and one for the walk,
per channel) from the noise's own seeded :class:`numpy.random.Generator`, so a seed gives the same series however
the samples are batched, and a sensor's white-noise stream is the same with the coloured noise on or off. With every
level zero the noise is off and draws nothing.

Two forms of one recursion, side by side: :meth:`ColouredNoise.sample` carries the state from batch to batch (the
live sensor); :func:`ar1_filter` runs it over a whole batch (vectorised by ``scipy.signal.lfilter`` where the
samples are evenly spaced). A test pins them together.
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from crane_stiffness.params.spec import ParamSpec
from crane_stiffness.sim.errors import ParameterError

#: Correlation times of the AR(1) processes whose sum is the 1/f noise [s].
FLICKER_POLES = (1e-3, 1e-2, 1e-1, 1.0, 10.0, 100.0)
_PROCESSES = 1 + len(FLICKER_POLES)  # AR(1) + the flicker poles; the random walk draws one more
PARAM_NAMES = ('ar1_std', 'ar1_tau_s', 'flicker_std', 'mains_amplitude', 'mains_hz', 'random_walk')


def ar1_filter(phi: NDArray[np.float64], innovations: NDArray[np.float64], x0: NDArray[np.float64]
               ) -> NDArray[np.float64]:
    """The AR(1) recursion ``x_n = phi_n·x_(n−1) + innovations_n`` over a batch, from ``x0``.

    Args:
        phi: Per-sample coefficients, shape (n, c) (or (n, 1), shared by the channels).
        innovations: Shape (n, c).
        x0: The state before the first sample, shape (c,).

    Returns:
        x, shape (n, c). Each run of evenly spaced samples (one phi per channel) goes through ``lfilter``: the same
        products and sums in the same order as the loop ``x = phi·x + e``, so bit-identical to it.
    """
    n, channels = innovations.shape
    out = np.empty((n, channels))
    if n == 0:
        return out
    phi = np.broadcast_to(phi, (n, channels))
    changes = np.flatnonzero((phi[1:] != phi[:-1]).any(axis=1)) + 1  # where a run of one spacing ends
    x = np.array(x0, dtype=float)
    if len(changes) > n // 16:  # mostly uneven: the loop is faster than many short filters
        for i in range(n):
            x = phi[i] * x + innovations[i]
            out[i] = x
        return out
    # (imported here: scipy.signal costs a sensor node ~2 s of CPU at start, and only coloured noise needs it)
    from scipy.signal import lfilter
    for start, stop in zip([0, *changes.tolist()], [*changes.tolist(), n]):
        for c in range(channels):
            out[start:stop, c] = lfilter([1.0], [1.0, -phi[start, c]], innovations[start:stop, c],
                                         zi=[phi[start, c] * x[c]])[0]
        x = out[stop - 1]
    return out


class ColouredNoise:
    """Coloured noise and random-walk drift of ``channels`` channels (see the module docstring); streaming."""

    def __init__(self, channels: int, *, ar1_std: ArrayLike = 0.0, ar1_tau_s: ArrayLike = 0.1,
                 flicker_std: ArrayLike = 0.0, mains_amplitude: ArrayLike = 0.0, mains_hz: float = 50.0,
                 random_walk: ArrayLike = 0.0, rng: np.random.Generator | int | None = None) -> None:
        """Create the noise of ``channels`` channels. Per-channel arguments: one number or ``channels`` numbers.

        Args:
            ar1_std: Stationary standard deviation of the AR(1) part, channel units, >= 0.
            ar1_tau_s: Its correlation time, s, > 0.
            flicker_std: Standard deviation of the 1/f part, channel units, >= 0.
            mains_amplitude: Amplitude of the mains line, channel units, >= 0.
            mains_hz: Mains frequency, Hz, > 0 (50 or 60).
            random_walk: Zero drift, channel units per sqrt(s), >= 0.
            rng: Seed or Generator of this noise (not the sensor's white-noise one).
        """
        self.channels = channels
        self.ar1_std = self._levels('ar1_std', ar1_std)
        self.ar1_tau_s = self._levels('ar1_tau_s', ar1_tau_s, positive=True)
        self.flicker_std = self._levels('flicker_std', flicker_std)
        self.mains_amplitude = self._levels('mains_amplitude', mains_amplitude)
        if isinstance(mains_hz, bool) or not isinstance(mains_hz, (int, float)) or not math.isfinite(mains_hz) \
                or mains_hz <= 0:
            raise ParameterError('mains_hz', mains_hz, 'must be a finite number > 0')
        self.mains_hz = float(mains_hz)
        self.random_walk = self._levels('random_walk', random_walk)
        self._rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
        self.enabled = bool(self.ar1_std.any() or self.flicker_std.any() or self.mains_amplitude.any()
                            or self.random_walk.any())
        # One phase per channel, drawn whether or not the line is on: the draws after it do not depend on it.
        self._phase = 2.0 * math.pi * self._rng.random(channels) if self.enabled else np.zeros(channels)
        self._taus = np.column_stack([self.ar1_tau_s, *(np.full(channels, t) for t in FLICKER_POLES)])  # (c, p)
        per_pole = self.flicker_std / math.sqrt(len(FLICKER_POLES))
        self._stds = np.column_stack([self.ar1_std, *([per_pole] * len(FLICKER_POLES))])  # (c, p)
        self._state: NDArray[np.float64] | None = None  # the processes' values at _t (c, p); None before a sample
        self._walk = np.zeros(channels)
        self._t = 0.0

    def _levels(self, field: str, value: ArrayLike, *, positive: bool = False) -> NDArray[np.float64]:
        array = np.atleast_1d(np.array(value, dtype=float))
        if array.ndim != 1 or array.size not in (1, self.channels):
            raise ParameterError(field, value, f'must be 1 or {self.channels} numbers')
        if not np.isfinite(array).all() or ((array <= 0.0) if positive else (array < 0.0)).any():
            raise ParameterError(field, value, f'every entry must be finite and {"> 0" if positive else ">= 0"}')
        return np.broadcast_to(array, (self.channels,)).copy()

    @classmethod
    def from_params(cls, channels: int, params: Mapping[str, Any], rng: np.random.Generator | int | None = None
                    ) -> ColouredNoise:
        """Build from ``noise.<name>`` parameter values (:data:`PARAM_NAMES`); raises ParameterError naming the
        full parameter."""
        try:
            return cls(channels, **{n: params['noise.' + n] for n in PARAM_NAMES}, rng=rng)
        except ParameterError as exc:
            raise ParameterError('noise.' + exc.field, exc.value, exc.rule) from None

    def sample(self, t_s: ArrayLike) -> NDArray[np.float64]:
        """The noise at the instants ``t_s`` [s] (ascending; an instant before the last one sampled counts as the
        same instant), continuing from the last call: shape (n, channels) for n instants (zeros when off)."""
        t = np.atleast_1d(np.asarray(t_s, dtype=float))
        n = t.size
        if not self.enabled or n == 0:
            return np.zeros((n, self.channels))
        draws = self._rng.standard_normal((n, self.channels, _PROCESSES + 1))
        if self._state is None:  # the first sample: the processes in their stationary state, the walk at 0
            self._state = self._stds * draws[0, :, :_PROCESSES]
            self._t = float(t[0])
            dt = np.diff(t, prepend=t[0])
        else:
            dt = np.diff(t, prepend=self._t)
        # Whole picoseconds: instants on a clock grid (k/rate, or ns stamps in s) are evenly spaced to rounding, and
        # then exactly, so the recursion runs through lfilter.
        dt = np.round(np.maximum(dt, 0.0), 12)
        processes = np.zeros((n, self.channels))
        new_state = np.empty_like(self._state)
        for p in range(_PROCESSES):
            phi = np.exp(-dt[:, None] / self._taus[None, :, p])  # (n, c)
            innovations = np.sqrt(1.0 - phi ** 2) * self._stds[None, :, p] * draws[:, :, p]
            x = ar1_filter(phi, innovations, self._state[:, p])
            new_state[:, p] = x[-1]
            processes += x
        steps = self.random_walk * np.sqrt(dt)[:, None] * draws[:, :, _PROCESSES]
        walk = np.cumsum(np.vstack([self._walk, steps]), axis=0)[1:]  # summed in one order however it is batched
        self._state, self._walk, self._t = new_state, walk[-1].copy(), float(max(self._t, t[-1]))
        mains = self.mains_amplitude * np.sin(2.0 * math.pi * self.mains_hz * t[:, None] + self._phase)
        return processes + mains + walk


def noise_params(unit: str, channels: int) -> tuple[ParamSpec, ...]:
    """The ``noise.*`` parameters of a simulated sensor of ``channels`` channels in ``unit`` (the load_cell and lvdt
    nodes): every level 0 (off) by default."""
    per = f', {channels} values (one = all)' if channels > 1 else ''
    walk_unit = ', '.join(u + '/sqrt(s)' for u in unit.split(', '))

    def level(name: str, default: float, text: str, unit_text: str, positive: bool = False) -> ParamSpec:
        if channels == 1:  # one channel: a number
            if positive:
                return ParamSpec(name, default, f'{text} [{unit_text}]', above=0.0)
            return ParamSpec(name, default, f'{text} [{unit_text}]', at_least=0.0)
        return ParamSpec(name, [default] * channels, f'{text}{per} [{unit_text}]',
                         rule='finite, > 0' if positive else 'finite, >= 0')

    return (
        level('noise.ar1_std', 0.0, 'AR(1) (Gauss-Markov) noise: stationary standard deviation; 0 = none', unit),
        level('noise.ar1_tau_s', 0.1, 'AR(1) noise: correlation time', 's', positive=True),
        level('noise.flicker_std', 0.0, '1/f (flicker) noise: standard deviation; 0 = none', unit),
        level('noise.mains_amplitude', 0.0, 'mains hum: amplitude of the line; 0 = none', unit),
        ParamSpec('noise.mains_hz', 50.0, 'mains frequency (50 or 60) [Hz]', above=0.0),
        level('noise.random_walk', 0.0, 'zero drift as a random walk: growth per sqrt(second); 0 = none', walk_unit),
    )


__all__ = ['FLICKER_POLES', 'PARAM_NAMES', 'ColouredNoise', 'ar1_filter', 'noise_params']
