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

Sessions of the series ``full`` are analysed by the 6×6 analysis (crane_stiffness.analysis.full6: ``full6.json``
and its figures in the session's folder) into :class:`~crane_stiffness.campaign.rows.Full6Row` (:func:`full_row`):
K's diagonal and K2 against the tangent, how many of K's 36 intervals hold the tangent, and the live fit's last K
against the offline one. OK when the offline fit's status and the live estimator's last 6×6 status are OK, the
analysis found no problem and the live K equals the offline one (to :data:`LIVE_TOLERANCE`); their figures are
:mod:`.full_figures`, their table full.csv.
"""
from __future__ import annotations

import csv
import json
import math
from pathlib import Path
from typing import Any, Callable, Sequence

from crane_stiffness import __version__
from crane_stiffness.campaign.errors import CampaignError
from crane_stiffness.campaign.full_series import FULL
from crane_stiffness.campaign.rows import CampaignAnalysis, Full6Row, SessionRow, uncertainty_fields
from crane_stiffness.campaign.runner import read_plan
from crane_stiffness.campaign.session import RESULT_FILE

SOURCE_FILE = 'source.json'
#: The analysis file of a one-axis session and of a session of the series full.
ANALYSIS_FILES = {'one_axis': 'analysis.json', 'full': 'full6.json'}
#: The live 6×6 fit's last K must equal the offline fit of the bag to this fraction of K's largest entry.
LIVE_TOLERANCE = 1e-6


def bag_fingerprint(bag: Path) -> dict[str, Any]:
    """The bag's files with their sizes and modification times, and this software's version: a session whose
    fingerprint is unchanged needs no new analysis."""
    files = sorted(p for p in bag.rglob('*') if p.is_file()) if bag.is_dir() else [bag]
    return {'software_version': __version__,
            'files': [[str(p.relative_to(bag) if bag.is_dir() else p.name), p.stat().st_size, p.stat().st_mtime_ns]
                      for p in files]}


def _kind(series: str) -> str:
    return 'full' if series == FULL else 'one_axis'


def analysis_current(bag: Path, out: Path, kind: str = 'one_axis') -> bool:
    """``out`` holds an analysis (of ``kind``: one_axis or full) of ``bag`` as it is now, by this software."""
    try:
        return (out / ANALYSIS_FILES[kind]).is_file() and \
            json.loads((out / SOURCE_FILE).read_text()) == bag_fingerprint(bag)
    except (OSError, ValueError):
        return False


def analyze_one(bag: str, out: str, kind: str = 'one_axis') -> str:
    """Analyse one session's bag into ``out`` (figures, report, analysis.json or full6.json for ``kind`` full,
    source.json); '' or the reason it failed. A top-level function: it runs in worker processes and on Dask
    workers."""
    from crane_stiffness.analysis.analyze import analyze_session
    from crane_stiffness.analysis.full6 import analyze_full6
    from crane_stiffness.errors import CraneStiffnessError
    try:
        if kind == 'full':
            analyze_full6(bag, out)
        else:  # the measured k with the GUM alone (faster); the prediction's Monte Carlo (once per set-up and
            # process) sets E_n's reference U as `analyze` has it
            analyze_session(bag, out, progress=False, monte_carlo=False, prediction_monte_carlo=True)
    except (CraneStiffnessError, OSError, ValueError) as exc:
        return f'{type(exc).__name__}: {exc}'
    (Path(out) / SOURCE_FILE).write_text(json.dumps(bag_fingerprint(Path(bag))))
    return ''


def _status(analysis: dict[str, Any], result: dict[str, Any] | None) -> list[str]:
    """Why a session is not OK ([] when it is)."""
    # A session far from the nominal model (|E_n| > 1) is the campaign's finding, in its tables: not a broken session.
    finding = set(analysis.get('model_disagreements') or [])
    reasons = [p for p in analysis.get('problems') or [] if p not in finding]
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
        analysis=str(analysis_dir), nominal=plan['nominal'], true=plan['true'], **uncertainty_fields(analysis))


def _live_difference(offline: Any, live: Any) -> float:
    """Largest |live K − offline K| over K's largest entry (NaN without a live K)."""
    import numpy as np
    from crane_stiffness.contract.stiffness6_layout import decode
    if live is None:
        return math.nan
    k_live = decode(live)[0]
    k = np.asarray(offline, dtype=float)
    if not (np.all(np.isfinite(k_live)) and np.all(np.isfinite(k))):
        return math.nan
    return float(np.max(np.abs(k_live - k)) / np.max(np.abs(k)))


def full_row(plan: dict[str, Any], analysis: dict[str, Any], result: dict[str, Any] | None,
             analysis_dir: Path) -> Full6Row:
    """A session of the series full: its row from its plan, its full6.json and its run's result.json."""
    reasons = list(analysis.get('problems') or [])
    status = analysis.get('status') or {}
    if status.get('level') != 'OK':
        reasons.append(f"the offline 6x6 fit is {status.get('level')}: {status.get('message')}")
    live = (result or {}).get('status6')
    if result is not None and (live is None or live.get('level') != 'OK'):
        reasons.append("the live 6x6 estimator's last status was "
                       + (f"{live['level']}: {live['message']}" if live else 'never received'))
    difference = _live_difference(analysis['stiffness']['value'], (result or {}).get('stiffness6'))
    if result is not None and not difference <= LIVE_TOLERANCE:
        reasons.append('the live 6x6 fit published no K' if math.isnan(difference) else
                       f'the live K differs from the offline fit of the bag by {difference:.2g} of its largest entry')
    k2 = analysis.get('k2') or {}
    covered = ((analysis.get('comparison') or {}).get('covered') or {}).get('stiffness')
    return Full6Row(
        session=plan['id'], weight=plan['weight'], l0=plan['l0'], height=plan['height'], repeat=plan['repeat'],
        status='OK' if not reasons else 'NOT OK', reasons=reasons, diagonal=list(analysis.get('diagonal') or []),
        k2=_number(k2.get('value')), k2_low=_number(k2.get('low')), k2_high=_number(k2.get('high')),
        k2_tangent=_number(k2.get('tangent')), k2_eq18=_number(k2.get('paper')),
        covered=int(covered) if covered is not None else 0, live_difference=difference,
        pairs=int((analysis.get('pairs') or {}).get('n') or 0), analysis=str(analysis_dir), nominal=plan['nominal'],
        true=plan['true'])


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
        kind = _kind(plan['series'])
        if not analysis_current(bag, target, kind):
            jobs.append((str(bag), str(target), kind))
    outcomes = map_sessions(analyze_one, jobs, workers=workers, scheduler=scheduler, progress=progress)
    failed = {Path(job[0]).name: why for job, why in zip(jobs, outcomes) if why}
    return [Path(job[0]).name for job, why in zip(jobs, outcomes) if not why], failed


def _analysed(out: Path) -> tuple[dict[str, Any], list[SessionRow], list[Full6Row], list[str]]:
    out = Path(out)
    plan = read_plan(out)
    rows: list[SessionRow] = []
    full: list[Full6Row] = []
    missing: list[str] = []
    for p in plan['sessions']:
        folder = out / 'analysis' / p['id']
        kind = _kind(p['series'])
        result_path = out / 'sessions' / p['id'] / RESULT_FILE
        if not (folder / ANALYSIS_FILES[kind]).is_file() or not result_path.is_file():
            missing.append(p['id'])
            continue
        analysis = json.loads((folder / ANALYSIS_FILES[kind]).read_text())
        result = json.loads(result_path.read_text())
        if kind == 'full':
            full.append(full_row(p, analysis, result, folder))
        else:
            rows.append(session_row(p, analysis, result, folder))
    return plan, rows, full, missing


def campaign_rows(out: str | Path) -> tuple[dict[str, Any], list[SessionRow], list[str]]:
    """(the plan, a row per analysed one-axis session, the sessions planned but not run or not analysed)."""
    plan, rows, _, missing = _analysed(Path(out))
    return plan, rows, missing


def full_rows(out: str | Path) -> list[Full6Row]:
    """A row per analysed session of the series full."""
    return _analysed(Path(out))[2]


def write_full_table(rows: Sequence[Full6Row], path: Path) -> None:
    """The series full's rows as CSV: K's diagonal (measured, interval, tangent, error) and K2 per session."""
    from crane_stiffness.contract.axes import AXES
    head = ['session', 'weight', 'l0', 'height', 'repeat', 'status', 'pairs']
    for a in AXES:
        head += [f'K_{a}', f'K_{a}_ci95_low', f'K_{a}_ci95_high', f'K_{a}_tangent', f'K_{a}_relative_error']
    head += ['K2', 'K2_ci95_low', 'K2_ci95_high', 'K2_tangent', 'K2_eq18', 'K2_relative_error', 'covered_of_36',
             'live_difference', 'reasons']

    def cell(v: Any) -> Any:
        return '' if v is None or (isinstance(v, float) and not math.isfinite(v)) else v
    with open(path, 'w', newline='') as f:
        writer = csv.writer(f)
        writer.writerow(head)
        for r in rows:
            values: list[Any] = [r.session, r.weight, r.l0, r.height, r.repeat, r.status, r.pairs]
            for d in r.diagonal:
                values += [d['measured'], d['low'], d['high'], d['tangent'], d['relative_error']]
            values += [r.k2, r.k2_low, r.k2_high, r.k2_tangent, r.k2_eq18, r.k2_relative_error, r.covered,
                       r.live_difference, '; '.join(r.reasons)]
            writer.writerow([cell(v) for v in values])


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
    _, rows, full, missing = _analysed(out)
    if not rows and not full:
        raise CampaignError(f'{out}: no session of campaign {plan["campaign"]!r} could be analysed'
                            + (f' ({"; ".join(f"{k}: {v}" for k, v in failed.items())})' if failed else
                               ' (none has run yet)'))
    result = CampaignAnalysis(out=out, campaign=plan['campaign'], rows=rows, full=full, missing=missing,
                              analysed=analysed, failed=failed)
    target = out / 'campaign'
    target.mkdir(parents=True, exist_ok=True)
    if rows:
        result.files += figures.write_campaign_figures(rows, target, formats)
        write_table(rows, target / 'campaign.csv')
        result.files.append(str(target / 'campaign.csv'))
    if full:
        from crane_stiffness.campaign import full_figures
        result.files += full_figures.write_full_figures(full, target, formats)
        write_full_table(full, target / 'full.csv')
        result.files.append(str(target / 'full.csv'))
    from crane_stiffness.campaign.coverage import campaign_coverage, write_coverage
    result.coverage = campaign_coverage(rows, full)
    result.files += write_coverage(result.coverage, target, formats, full)
    result.files += report.write_campaign_report(result, target, reports)
    (target / 'campaign.json').write_text(json.dumps(result.to_dict(), indent=1, allow_nan=False))
    result.files.append(str(target / 'campaign.json'))
    return result
