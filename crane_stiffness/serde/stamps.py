"""Header stamps in seconds: the one rounding of ``sec + nanosec · 1e-9`` used everywhere.

The nodes (one message at a time), the bulk decoder (numpy arrays of a whole bag) and the synthetic sessions all
turn stamps into seconds here, so that live and offline results agree bit for bit.
"""
from __future__ import annotations

from typing import overload

import numpy as np


@overload
def stamp_seconds(sec: int, nanosec: int) -> float: ...
@overload
def stamp_seconds(sec: int | np.ndarray, nanosec: int | np.ndarray) -> float | np.ndarray: ...


def stamp_seconds(sec: int | np.ndarray, nanosec: int | np.ndarray) -> float | np.ndarray:
    """A header stamp in seconds, ``sec + nanosec · 1e-9`` (scalars, or numpy arrays element-wise)."""
    return sec + nanosec * 1e-9
