"""``crane-stiffness campaign analyze DIR``: every session of a campaign analysed (crane_stiffness.analysis.analyze, in
parallel processes or on a Dask cluster: :mod:`.parallel`), grouped by series, W and l0, beside the nominal model.

Per session, ``DIR/analysis/<session>/`` holds the session's own analysis (figures, report, analysis.json) and
``source.json``: the bag's files (size, modification time) and the software version it was made from. A session
whose bag and software are unchanged is not analysed again.

The campaign's results (:func:`campaign_rows`): one row per session with the measured stiffness (the loading branch
fit over all pairs, as the live estimator fits; 95 % interval), the hold-means fit, the nominal model's exact tangent
at rest, eq. (18)/(19), the W = 0 elastic model and a single wire carrying W/6, all in the LVDT's reading units (N/m,
N·m/rad), the relative error, and the status: OK when the analysis found no problem and the estimator's last
loading status of the run was OK; else NOT OK with the reasons. Written by :func:`analyze_campaign` to
``DIR/campaign/``: figures (:mod:`.figures`), campaign.csv, campaign.json, report.md / report.html. No ROS.
"""
from __future__ import annotations

import csv
import json
import math
from pathlib import Path
from typing import Any, Callable, Sequence

from crane_stiffness import __version__
from crane_stiffness.campaign.errors import CampaignError
from crane_stiffness.campaign.rows import CampaignAnalysis, SessionRow
from crane_stiffness.campaign.runner import RESULT_FILE, read_plan

SOURCE_FILE = 'source.json'


def bag_fingerprint(bag: Path) -> dict[str, Any]:
    """The bag's files with their sizes and modification times, and this software's version: a session whose
    fingerprint is unchanged needs no new analysis."""
    files = sorted(p for p in bag.rglob('*') if p.is_file()) if bag.is_dir() else [bag]
    return {'software_version': __version__,
            'files': [[str(p.relative_to(bag) if bag.is_dir() else p.name), p.stat().st_size, p.stat().st_mtime_ns]
                      for p in files]}


def analysis_current(bag: Path, out: Path) -> bool:
    """``out`` holds an analysis of ``bag`` as it is now, by this software."""
    try:
        return (out / 'analysis.json').is_file() and \
            json.loads((out / SOURCE_FILE).read_text()) == bag_fingerprint(bag)
    except (OSError, ValueError):
        return False


def analyze_one(bag: str, out: str) -> str:
    """Analyse one session's bag into ``out`` (figures, report, analysis.json, source.json); '' or the reason it
    failed. A top-level function: it runs in worker processes and on Dask workers."""
    from crane_stiffness.analysis.analyze import analyze_session
    from crane_stiffness.errors import CraneStiffnessError
    try:
        analyze_session(bag, out, progress=False)
    except (CraneStiffnessError, OSError, ValueError) as exc:
        return f'{type(exc).__name__}: {exc}'
    (Path(out) / SOURCE_FILE).write_text(json.dumps(bag_fingerprint(Path(bag))))
    return ''


def _status(analysis: dict[str, Any], result: dict[str, Any] | None) -> list[str]:
    """Why a session is not OK ([] when it is)."""
    reasons = list(analysis.get('problems') or [])
    loading = ((result or {}).get('status') or {}).get('loading')
    if result is not None and (loading is None or loading.get('level') != 'OK'):
        level = loading.get('level') if loading else 'none'
        message = loading.get('message') if loading else 'no status received'
        reasons.append(f"the estimator's last loading status was {level}: {message}")
    if (analysis.get('branch_fits') or {}).get('loading') is None:
        reasons.append('no loading fit')
    return reasons


def _number(value: Any) -> float:
    return math.nan if value is None else float(value)


def session_row(plan: dict[str, Any], analysis: dict[str, Any], result: dict[str, Any] | None,
                analysis_dir: Path) -> SessionRow:
    """A session's row from its plan, its analysis.json and its run's result.json."""
    fit = (analysis.get('branch_fits') or {}).get('loading') or {}
    holds = (analysis.get('hold_fits') or {}).get('loading') or {}
    model = analysis.get('model') or {}
    scale = _number(model.get('lvdt_scale', 1.0))
    tangent = _number(model.get('tangent_at_rest')) * scale
    k = _number(fit.get('stiffness'))
    reasons = _status(analysis, result)
    return SessionRow(
        session=plan['id'], series=plan['series'], weight=plan['weight'], l0=plan['l0'], height=plan['height'],
        repeat=plan['repeat'], unit=str(analysis.get('unit', '')), status='OK' if not reasons else 'NOT OK',
        reasons=reasons, k=k, ci95_low=_number(fit.get('ci95_low')), ci95_high=_number(fit.get('ci95_high')),
        k_holds=_number(holds.get('stiffness')), model_tangent=tangent,
        model_eq18=_number(model.get('eq18')) * scale, model_elastic_w0=_number(model.get('elastic_w0')) * scale,
        model_single_wire=_number(model.get('single_wire_w6')) * scale,
        relative_error=(k - tangent) / tangent if tangent else math.nan, n=int(fit.get('n') or 0),
        analysis=str(analysis_dir), nominal=plan['nominal'], true=plan['true'])


def analyze_sessions(out: Path, plans: Sequence[dict[str, Any]], workers: int | None = None,
                     scheduler: str | None = None, progress: Callable[[str], None] | None = None
                     ) -> tuple[list[str], dict[str, str]]:
    """Analyse every session of ``plans`` run in ``out`` whose analysis is not current: (analysed, failed)."""
    from crane_stiffness.campaign.parallel import map_sessions
    jobs = []
    for plan in plans:
        bag = out / 'bags' / plan['id']
        if not (out / 'sessions' / plan['id'] / RESULT_FILE).is_file():
            continue
        target = out / 'analysis' / plan['id']
        if not analysis_current(bag, target):
            jobs.append((str(bag), str(target)))
    outcomes = map_sessions(analyze_one, jobs, workers=workers, scheduler=scheduler, progress=progress)
    failed = {Path(bag).name: why for (bag, _), why in zip(jobs, outcomes) if why}
    return [Path(bag).name for (bag, _), why in zip(jobs, outcomes) if not why], failed


def campaign_rows(out: str | Path) -> tuple[dict[str, Any], list[SessionRow], list[str]]:
    """(the plan, a row per analysed session, the sessions planned but not run or not analysed)."""
    out = Path(out)
    plan = read_plan(out)
    rows, missing = [], []
    for p in plan['sessions']:
        folder = out / 'analysis' / p['id']
        result_path = out / 'sessions' / p['id'] / RESULT_FILE
        if not (folder / 'analysis.json').is_file() or not result_path.is_file():
            missing.append(p['id'])
            continue
        analysis = json.loads((folder / 'analysis.json').read_text())
        rows.append(session_row(p, analysis, json.loads(result_path.read_text()), folder))
    return plan, rows, missing


def write_table(rows: Sequence[SessionRow], path: Path) -> None:
    """The rows as CSV (NaN as empty)."""
    names = [f for f in SessionRow.__dataclass_fields__ if f not in ('nominal', 'true')]
    with open(path, 'w', newline='') as f:
        writer = csv.writer(f)
        writer.writerow(names)
        for r in rows:
            values = []
            for name in names:
                v = getattr(r, name)
                if isinstance(v, float) and not math.isfinite(v):
                    v = ''
                elif isinstance(v, list):
                    v = '; '.join(v)
                values.append(v)
            writer.writerow(values)


def analyze_campaign(out: str | Path, *, workers: int | None = None, scheduler: str | None = None,
                     formats: Sequence[str] = ('png',), reports: Sequence[str] = ('md', 'html'),
                     progress: Callable[[str], None] | None = None) -> CampaignAnalysis:
    """Analyse the campaign in ``out`` (see the module docstring); writes ``out/campaign/``."""
    from crane_stiffness.campaign import figures, report
    out = Path(out)
    plan = read_plan(out)
    analysed, failed = analyze_sessions(out, plan['sessions'], workers=workers, scheduler=scheduler,
                                        progress=progress)
    _, rows, missing = campaign_rows(out)
    if not rows:
        raise CampaignError(f'{out}: no session of campaign {plan["campaign"]!r} could be analysed'
                            + (f' ({"; ".join(f"{k}: {v}" for k, v in failed.items())})' if failed else
                               ' (none has run yet)'))
    result = CampaignAnalysis(out=out, campaign=plan['campaign'], rows=rows, missing=missing, analysed=analysed,
                              failed=failed)
    target = out / 'campaign'
    target.mkdir(parents=True, exist_ok=True)
    result.files += figures.write_campaign_figures(rows, target, formats)
    write_table(rows, target / 'campaign.csv')
    result.files.append(str(target / 'campaign.csv'))
    result.files += report.write_campaign_report(result, target, reports)
    (target / 'campaign.json').write_text(json.dumps(result.to_dict(), indent=1, allow_nan=False))
    result.files.append(str(target / 'campaign.json'))
    return result
