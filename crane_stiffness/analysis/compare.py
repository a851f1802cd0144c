"""Sessions side by side: each analysed (:func:`~crane_stiffness.analysis.analyze.analyze_session`, results only),
then a table of their headline numbers (Markdown/HTML, JSON) and an overlay figure of their quasi-static points with
each session's model curve.

Each branch's measured k is stated with its expanded uncertainty U (GUM, with its coverage factor k) beside it, and
its E_n against the model's prediction (with the prediction's own U); every two sessions are compared branch by
branch by E_n = (k_b − k_a)/√(U_a² + U_b²) (ISO 13528: both are measurements, so both U count; |E_n| <= 1 agrees).
The sessions are analysed with the GUM alone (no Monte Carlo: the comparison states U and E_n, not the intervals).
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
from crane_stiffness.uncertainty.agreement import en_number
from crane_stiffness.uncertainty.errors import InputError


def _measured(a: SessionAnalysis, branch: str) -> tuple[float, float, float]:
    """(k, U, coverage factor) of a branch's measured stiffness with its GUM uncertainty (NaN when none)."""
    u = (a.uncertainty.get(branch) or {}).get('uncertainty')
    if not u:
        return math.nan, math.nan, math.nan
    return float(u['value']), float(u['U']), float(u['k'])


def _uncertainty_columns(a: SessionAnalysis) -> dict[str, Any]:
    """Each branch's k with U and k (the coverage factor), the model's prediction with its U, and E_n between them."""
    out: dict[str, Any] = {}
    prediction = a.uncertainty.get('prediction')
    model_k = model_u = model_factor = math.nan
    if prediction is not None:
        scale = float(prediction['lvdt_scale'])
        model_k = float(prediction['uncertainty']['value']) * scale
        model_u = float(prediction['uncertainty']['U']) * abs(scale)
        model_factor = float(prediction['uncertainty']['k'])
    out['model_k'], out['model_U'], out['model_coverage_factor'] = model_k, model_u, model_factor
    for branch in (LOADING, UNLOADING):
        k, big_u, factor = _measured(a, branch)
        en = ((a.uncertainty.get(branch) or {}).get('En') or {}).get('en', math.nan)
        out.update({f'{branch}_measured_k': k, f'{branch}_U': big_u, f'{branch}_coverage_factor': factor,
                    f'{branch}_fit': (a.uncertainty.get(branch) or {}).get('fit', ''), f'{branch}_En_model': en})
    return out


def session_agreement(analyses: Sequence[SessionAnalysis]) -> list[dict[str, Any]]:
    """Every two sessions (a before b, in the order given), branch by branch: both k with their U and
    E_n = (k_b − k_a)/√(U_a² + U_b²); a pair where either has no U is left out."""
    out = []
    for i, a in enumerate(analyses):
        for b in analyses[i + 1:]:
            for branch in (LOADING, UNLOADING):
                ka, ua, _ = _measured(a, branch)
                kb, ub, _ = _measured(b, branch)
                if not all(math.isfinite(v) for v in (ka, ua, kb, ub)):
                    continue
                try:
                    agreement = en_number(kb, ub, ka, ua, unit=a.unit)
                except InputError:  # both U zero: nothing to weigh the difference with
                    continue
                out.append({'a': a.session, 'b': b.session, 'branch': branch, 'k_a': ka, 'U_a': ua, 'k_b': kb,
                            'U_b': ub, 'En': agreement.en, 'agrees': agreement.agrees, 'unit': a.unit})
    return out


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
        'verdict': a.verdict.get('level', 'OK'), **_uncertainty_columns(a),
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
        analyses.append(analyze_session(p, axis=axis, write_files=False, mapping=mapping, monte_carlo=False,
                                         prediction_monte_carlo=True))  # E_n as `analyze` has it
    comparison = SessionComparison(rows=[comparison_row(a) for a in analyses], sessions=analyses,
                                   agreement=session_agreement(analyses))
    out = Path(out_dir) if out_dir is not None else Path('out') / 'compare'
    out.mkdir(parents=True, exist_ok=True)
    from crane_stiffness.analysis import figures
    comparison.files += figures.write_comparison_figures(analyses, out, formats)
    comparison.files += report.write_comparison_report(comparison, out, reports)
    if write_json:
        (out / 'compare.json').write_text(json.dumps(comparison.to_dict(), indent=1, allow_nan=False))
        comparison.files.append(str(out / 'compare.json'))
    return comparison
