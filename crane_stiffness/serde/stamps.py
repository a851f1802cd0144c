"""Header stamps in seconds and nanoseconds: the one rounding of ``sec + nanosec · 1e-9`` used everywhere, and
the exact integer conversions between a stamp's (sec, nanosec) and nanoseconds.

The nodes (one message at a time), the bulk decoder (numpy arrays of a whole bag) and the synthetic sessions all
turn stamps into seconds here, so that live and offline results agree bit for bit.
"""
from __future__ import annotations

from typing import overload

import numpy as np

NS_PER_S = 1_000_000_000


@overload
def stamp_seconds(sec: int, nanosec: int) -> float: ...
@overload
def stamp_seconds(sec: int | np.ndarray, nanosec: int | np.ndarray) -> float | np.ndarray: ...


def stamp_seconds(sec: int | np.ndarray, nanosec: int | np.ndarray) -> float | np.ndarray:
    """A header stamp in seconds, ``sec + nanosec · 1e-9`` (scalars, or numpy arrays element-wise)."""
    return sec + nanosec * 1e-9


def stamp_ns(sec: int, nanosec: int) -> int:
    """A header stamp in integer nanoseconds (exact)."""
    return sec * NS_PER_S + nanosec


def split_ns(t_ns: int) -> tuple[int, int]:
    """Integer nanoseconds as a header stamp's (sec, nanosec)."""
    sec, nanosec = divmod(t_ns, NS_PER_S)
    return sec, nanosec
