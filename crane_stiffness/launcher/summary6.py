"""The six-axis run's summary: the 6×6 K the live estimator published last, against the exact tangent and eq. (18)
of the session's crane at rest, entry by entry, and the coupling K2 with its sign (crane_stiffness.full6)."""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from crane_stiffness.contract import stiffness6_layout
from crane_stiffness.contract.axes import AXES
from crane_stiffness.full6.reference import k2_of, reference_at_rest
from crane_stiffness.params.files import load_params
from crane_stiffness.params.geometry import geometry_from_params

#: The demo signs a six-axis result when its status is OK, every diagonal entry of K is this close to the tangent,
#: and K2 has the tangent's sign and is K2_TOLERANCE close to it.
DIAGONAL_TOLERANCE = 0.01
K2_TOLERANCE = 0.03


def summarize6(crane_file: str | Path, stiffness: Any, status: tuple[str, str, dict[str, str]] | None
               ) -> dict[str, Any]:
    """The summary of a six-axis run: ``stiffness`` the last /stiffness6/stiffness data (None: none published; laid
    out as crane_stiffness.contract.stiffness6_layout says), ``status`` (level name, message, values) of the last
    /stiffness6/status."""
    g = geometry_from_params(load_params(crane_file))
    ref = reference_at_rest(g)
    out: dict[str, Any] = {'status': None if status is None else {'level': status[0], 'message': status[1],
                                                                   'values': status[2]},
                           'tangent': ref.tangent.tolist(), 'k2_tangent': ref.k2,
                           'eq18': None if ref.paper is None else ref.paper.tolist()}
    if stiffness is None:
        return {**out, 'stiffness': None}
    k, low, high = stiffness6_layout.decode(stiffness)
    diag = np.diag(k) / np.diag(ref.tangent) - 1.0
    k2 = k2_of(k)
    out.update(stiffness=k.tolist(), ci95_low=low.tolist(), ci95_high=high.tolist(),
               diagonal={axis: {'measured': float(k[i, i]), 'tangent': float(ref.tangent[i, i]),
                                'relative_error': float(diag[i]),
                                'covers': bool(low[i, i] <= ref.tangent[i, i] <= high[i, i])}
                         for i, axis in enumerate(AXES)},
               k2={'measured': k2, 'tangent': ref.k2, 'relative_error': k2 / ref.k2 - 1.0 if ref.k2 else None,
                   'same_sign': bool(np.sign(k2) == np.sign(ref.k2))},
               covered=int(np.count_nonzero((low <= ref.tangent) & (ref.tangent <= high))))
    return out


def verdict6(summary: dict[str, Any]) -> str:
    """'' when the six-axis result is one to sign (status OK, the diagonal within DIAGONAL_TOLERANCE, K2 of the
    tangent's sign within K2_TOLERANCE), else why."""
    status = summary.get('status')
    if summary.get('stiffness') is None:
        return 'stiffness6_estimator published no 6x6 stiffness'
    if status is None or status['level'] != 'OK':
        return f"the 6x6 status is {status['level'] if status else 'missing'}: {status['message'] if status else ''}"
    bad = {a: f"{100 * d['relative_error']:+.2f} %" for a, d in summary['diagonal'].items()
           if not abs(d['relative_error']) <= DIAGONAL_TOLERANCE}
    if bad:
        return f'diagonal entries of K off the tangent by more than {100 * DIAGONAL_TOLERANCE:g} %: {bad}'
    k2 = summary['k2']
    if not k2['same_sign'] or k2['relative_error'] is None or not abs(k2['relative_error']) <= K2_TOLERANCE:
        return (f"K2 = {k2['measured']:.4g} N/rad against the tangent's {k2['tangent']:.4g} (sign and "
                f"{100 * K2_TOLERANCE:g} % asked)")
    return ''


__all__ = ['DIAGONAL_TOLERANCE', 'K2_TOLERANCE', 'summarize6', 'verdict6']
