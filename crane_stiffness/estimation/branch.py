"""Loading and unloading branches of a load cycle: the live :class:`BranchTracker`, sample by sample, and
:func:`branch_labels`, the same rule over a whole recorded sequence at once (numpy).

Both work on the magnitude ``|load|`` (commanded or measured, N or N·m) with a dead band ``threshold``: while
loading, a drop of more than ``threshold`` below the running maximum switches to unloading; while unloading, a rise
of more than ``threshold`` above the running minimum switches back. They label every sequence alike (the tests pin
one to the other).
"""
from __future__ import annotations

import math
from typing import Iterable, Literal

import numpy as np

from crane_stiffness.estimation.errors import DataError, ParameterError

Branch = Literal['loading', 'unloading']
LOADING: Branch = 'loading'
UNLOADING: Branch = 'unloading'
BRANCHES: tuple[Branch, Branch] = (LOADING, UNLOADING)


def _follow(magnitudes: Iterable[float], loading: bool, extreme: float, threshold: float,
            labels: list[bool]) -> tuple[bool, float]:
    """The tracker's rule, sample by sample, from the state (``loading``, running ``extreme`` of |load|): appends
    each sample's branch (True: loading) to ``labels`` and returns the state after the last sample."""
    append = labels.append
    for m in magnitudes:
        if loading:
            if m > extreme:
                extreme = m
            elif extreme - m > threshold:
                loading, extreme = False, m
        elif m < extreme:
            extreme = m
        elif m - extreme > threshold:
            loading, extreme = True, m
        append(loading)
    return loading, extreme


class BranchTracker:
    """Labels samples as on the loading or the unloading branch of a load cycle, with hysteresis.

    Works on the magnitude ``|load|`` (commanded or measured, N or N·m), so a program that crosses zero into
    negative loads counts the move away from zero as loading. A peak detector with a dead band:

    - while loading, the running maximum of |load| is tracked; a drop of more than ``threshold`` below it switches
      to unloading;
    - while unloading, the running minimum is tracked; a rise of more than ``threshold`` above it switches back.

    Holds and noise smaller than ``threshold`` keep the previous branch. The price of the dead band is a lag: the
    samples between a turning point and the switch (a load change of up to ``threshold``) keep the old label. With
    the commanded load, which has no noise, ``threshold`` can be tiny.
    """

    def __init__(self, threshold: float, initial: Branch = LOADING) -> None:
        """Args: threshold: dead band in load units, ≥ 0. initial: branch before the first reversal."""
        threshold = float(threshold)
        if not (math.isfinite(threshold) and threshold >= 0.0):
            raise ParameterError('threshold', threshold, 'must be finite and >= 0')
        if initial not in BRANCHES:
            raise ParameterError('initial', initial, f'must be one of {", ".join(BRANCHES)}')
        self._threshold = threshold
        self._initial: Branch = initial
        self.reset()

    def reset(self) -> None:
        """Back to the initial branch with no history."""
        self._branch: Branch = self._initial
        self._extreme: float | None = None

    @property
    def branch(self) -> Branch:
        """Branch of the last sample."""
        return self._branch

    @property
    def threshold(self) -> float:
        """Dead band, in load units."""
        return self._threshold

    def update(self, load: float) -> Branch:
        """Classify one sample of the load (N or N·m) and return its branch. Raises DataError on NaN/Inf."""
        magnitude = abs(float(load))
        if not math.isfinite(magnitude):
            raise DataError(f'load must be finite, got {load!r}')
        if self._extreme is None:
            self._extreme = magnitude
        else:
            loading, self._extreme = _follow((magnitude,), self._branch == LOADING, self._extreme, self._threshold,
                                             [])
            self._branch = LOADING if loading else UNLOADING
        return self._branch


# ------------------------------------------------------------------------------------------------ vectorized --
def _first_switch(m: np.ndarray, start: int, loading: bool, threshold: float) -> int:
    """Index of the sample after ``start`` at which BranchTracker leaves its branch (len(m) if never)."""
    n = m.size
    extreme = m[start]
    pos = start + 1
    size = 4096
    while pos < n:
        stop = min(n, pos + size)
        seg = m[pos:stop]
        if loading:
            run = np.maximum(np.maximum.accumulate(seg), extreme)
            hit = run - seg > threshold
        else:
            run = np.minimum(np.minimum.accumulate(seg), extreme)
            hit = seg - run > threshold
        if hit.any():
            return pos + int(np.argmax(hit))
        extreme = run[-1]
        pos = stop
        size *= 2
    return n


def branch_labels(load: np.ndarray, threshold: float) -> np.ndarray:
    """Loading (True) / unloading (False) of each sample, exactly as :class:`BranchTracker` labels the sequence
    ``load`` (N or N·m), vectorized: one numpy search per branch switch (a noisy load that switches all the time
    goes sample by sample)."""
    m = np.abs(np.asarray(load, dtype=float))
    out = np.empty(m.size, bool)
    start, loading, switches = 0, True, 0
    while start < m.size:
        if switches > 2000 and start < 50 * switches:  # a switch every < 50 samples: numpy calls would dominate
            out[start] = loading
            rest: list[bool] = []
            _follow(m[start + 1:].tolist(), loading, float(m[start]), threshold, rest)
            out[start + 1:] = rest
            break
        switch = _first_switch(m, start, loading, threshold)
        out[start:switch] = loading
        start, loading = switch, not loading
        switches += 1
    return out
