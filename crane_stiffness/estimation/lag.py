"""The distribution of the live estimate's lag, kept in O(1) per estimate. Pure Python, no ROS."""
from __future__ import annotations

import math


class LagHistogram:
    """Distribution of the estimate's lag (publication time − stamp of its newest pair), s, in 0.1 ms bins up to
    ``limit_s`` (longer lags count in the last bin). O(1) per value, so the node can record every estimate."""

    BIN_S = 1e-4

    def __init__(self, limit_s: float = 10.0) -> None:
        self._counts = [0] * (int(round(limit_s / self.BIN_S)) + 1)
        self.n = 0
        self.max_s = math.nan

    def add(self, lag_s: float) -> None:
        if not math.isfinite(lag_s):
            return
        i = min(len(self._counts) - 1, max(0, int(lag_s / self.BIN_S)))
        self._counts[i] += 1
        self.n += 1
        if not lag_s <= self.max_s:  # also replaces the initial NaN
            self.max_s = lag_s

    def percentile(self, q: float) -> float:
        """The ``q`` % point (0–100), s, to the upper edge of its bin; NaN while empty."""
        if self.n == 0:
            return math.nan
        rank = max(1, math.ceil(q / 100.0 * self.n))
        seen = 0
        for i, count in enumerate(self._counts):
            seen += count
            if seen >= rank:
                return (i + 1) * self.BIN_S
        return math.inf  # not reached


__all__ = ['LagHistogram']
