"""Sessions side by side: each analysed (:func:`~crane_stiffness.analysis.analyze.analyze_session`, results only),
then a table of their headline numbers (Markdown/HTML, JSON) and an overlay figure of their quasi-static points with
each session's model curve.
"""
from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any, Iterable, Sequence

from crane_stiffness.analysis import report
from crane_stiffness.analysis.analyze import analyze_session
from crane_stiffness.analysis.mapping import SensorMapping
from crane_stiffness.analysis.results import SessionAnalysis, SessionComparison
from crane_stiffness.estimation.branch import LOADING, UNLOADING
from crane_stiffness.estimation.fit import LineFit


def comparison_row(a: SessionAnalysis) -> dict[str, Any]:
    """The headline numbers of one session (a row of the comparison table)."""
    def k(fit: LineFit | None, name: str = 'stiffness') -> float:
        return getattr(fit, name) if fit is not None else math.nan

    tangent = a.model.tangent_at_rest * a.model.lvdt_scale if a.model is not None and a.model.lvdt_scale else math.nan
    lk = k(a.branch_fits.get(LOADING))
    row = {
        'session': a.session, 'program': (a.program or {}).get('name', ''), 'axis': a.axis, 'unit': a.unit,
        'weight_N': (a.geometry or {}).get('weight', math.nan), 'height_m': (a.geometry or {}).get('height', math.nan),
        'l0_m': (a.geometry or {}).get('l0', math.nan),
        'loading_k': lk, 'loading_ci95_low': k(a.branch_fits.get(LOADING), 'ci95_low'),
        'loading_ci95_high': k(a.branch_fits.get(LOADING), 'ci95_high'),
        'unloading_k': k(a.branch_fits.get(UNLOADING)),
        'holds_loading_k': k(a.hold_fits.get(LOADING)), 'holds_unloading_k': k(a.hold_fits.get(UNLOADING)),
        'live_loading_k': a.live.live[LOADING]['stiffness'] if a.live is not None else math.nan,
        'model_tangent_k': tangent,
        'relative_error_loading': (lk - tangent) / tangent if math.isfinite(tangent) and tangent else math.nan,
        'nonlinearity_loading': k(a.branch_fits.get(LOADING), 'nonlinearity'),
        'steps': len(a.steps), 'problems': len(a.problems), 'mapping': a.mapping,
    }
    return row


def compare_sessions(bags: Iterable[str | Path], out_dir: str | Path | None = None, *,
                     formats: Sequence[str] = ('png',), reports: Sequence[str] = ('md',), write_json: bool = True,
                     axis: str | None = None, progress: bool = False,
                     mapping: SensorMapping | None = None) -> SessionComparison:
    """Analyse several sessions and set them side by side: a table (Markdown/HTML, JSON) and an overlay figure of
    their quasi-static force–displacement points with each session's nonlinear model curve.

    ``mapping`` (topics, displacement type and conversion, geometry: :class:`~crane_stiffness.analysis.mapping.
    SensorMapping`) applies to every bag; each row names what was used.

    Raises what :func:`analyze_session` raises, naming the bag.
    """
    paths = [Path(b) for b in bags]
    if len(paths) < 1:
        raise ValueError('compare needs at least one bag')
    analyses = []
    iterator: Iterable[Path] = paths
    if progress:
        from tqdm import tqdm
        iterator = tqdm(paths, desc='compare', unit='session', leave=False)
    for p in iterator:
        analyses.append(analyze_session(p, axis=axis, write_files=False, mapping=mapping))
    comparison = SessionComparison(rows=[comparison_row(a) for a in analyses], sessions=analyses)
    out = Path(out_dir) if out_dir is not None else Path('out') / 'compare'
    out.mkdir(parents=True, exist_ok=True)
    from crane_stiffness.analysis import figures
    comparison.files += figures.write_comparison_figures(analyses, out, formats)
    comparison.files += report.write_comparison_report(comparison, out, reports)
    if write_json:
        (out / 'compare.json').write_text(json.dumps(comparison.to_dict(), indent=1, allow_nan=False))
        comparison.files.append(str(out / 'compare.json'))
    return comparison
