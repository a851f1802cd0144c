"""The campaign's report (Markdown and HTML, the document model of crane_stiffness.analysis.report): the table of
sessions measured against the nominal model, the figures, the sessions not OK and why, the sessions missing."""
from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Sequence

from crane_stiffness.analysis.report import Block, fmt, write_blocks

if TYPE_CHECKING:
    from crane_stiffness.campaign.rows import CampaignAnalysis, Calibration, Full6Row, SessionRow


#: Sessions per quantity from which the report shows the intervals' coverage (a coverage study's campaign).
COVERAGE_STUDY = 10


def _pct(value: float) -> str:
    return '–' if not math.isfinite(value) else f'{100 * value:+.3f} %'


def _en(row: SessionRow) -> str:
    return '–' if not math.isfinite(row.en) else f'{row.en:+.2f}: {row.agreement}'


def _u(row: SessionRow) -> str:
    if not math.isfinite(row.U):
        return '–'
    return f'{fmt(row.U, 4)} (k = {row.coverage_factor:.2f})' + (' statistical only' if row.statistical_only else '')


def session_table(rows: Sequence[SessionRow]) -> Block:
    """Per session: the samples' fit and its statistical interval, the stiffness as the GUM states it with U (k)
    and the repeatability it starts from, E_n against the model, the models, the status."""
    headers = ['session', 'series', 'W [N]', 'l0 [m]', 'measured k', '95 % interval (statistical)', 'holds k',
               'k (GUM)', 'U (k)', 'repeatability (95 %)', 'E_n vs model', 'model tangent', 'eq. (18)/(19)',
               'W = 0', 'single wire W/6', 'measured vs tangent', 'status']
    body = [[r.session, r.series, fmt(r.weight, 4), fmt(r.l0, 4), fmt(r.k), f'{fmt(r.ci95_low)} … {fmt(r.ci95_high)}',
             fmt(r.k_holds), fmt(r.k_gum) if math.isfinite(r.k_gum) else '–', _u(r),
             f'{fmt(r.repeatability_low)} … {fmt(r.repeatability_high)}' if math.isfinite(r.repeatability_low)
             else '–', _en(r), fmt(r.model_tangent), fmt(r.model_eq18), fmt(r.model_elastic_w0),
             fmt(r.model_single_wire), _pct(r.relative_error), r.status] for r in rows]
    return ('table', headers, body)


def _true_note(rows: Sequence[SessionRow]) -> str:
    """A word on E_n when the simulated crane is not the nominal one: there the disagreement is the finding."""
    if not any(r.true and r.true != r.nominal for r in rows):
        return ''
    disagree = sum(r.agreement == 'disagree' for r in rows)
    return (f' The simulated crane differs from the nominal one here on purpose (the campaign\'s true.*): E_n says '
            f'how far the nominal model is from it ({disagree} of {len(rows)} session(s) disagree), which is the '
            'finding a calibration uses, not a fault of the session: the status does not count it.')


def _interval(value: float, low: float, high: float) -> str:
    return f'{fmt(value)} [{fmt(low)} … {fmt(high)}]'


def full_table(rows: Sequence[Full6Row]) -> Block:
    """The series full: K's diagonal against the tangent (relative error, * where the interval misses it), K2 with
    its interval against the tangent and eq. (18), the intervals covering the tangent, the status."""
    from crane_stiffness.contract.axes import AXES
    headers = ['session', 'W [N]', 'l0 [m]', *(f'K {a} vs tangent' for a in AXES), 'K2 [N/rad] (95 %)',
               'K2 tangent', 'K2 eq. (18)', 'K2 vs tangent', 'intervals covering', 'status']
    body = []
    for r in rows:
        diag = [_pct(d['relative_error'] if d['relative_error'] is not None else math.nan)
                + ('' if d.get('covers') in (True, None) else ' *') for d in r.diagonal]
        body.append([r.session, fmt(r.weight, 4), fmt(r.l0, 4), *diag, _interval(r.k2, r.k2_low, r.k2_high),
                     fmt(r.k2_tangent), fmt(r.k2_eq18), _pct(r.k2_relative_error), f'{r.covered}/36', r.status])
    return ('table', headers, body)


def campaign_blocks(result: CampaignAnalysis, images: Sequence[str]) -> list[Block]:
    rows = result.rows
    worst = max((abs(r.relative_error) for r in rows if math.isfinite(r.relative_error)), default=math.nan)
    blocks: list[Block] = [('h1', f'Campaign {result.campaign}: {len(rows) + len(result.full)} session(s)')]
    if rows:
        blocks += [
            ('p', 'Measured stiffness: the loading branch fitted over all its pairs (as the live estimator fits), in '
                  "the LVDT's reading units (N/m for fy and fz, N·m/rad for mz), with its 95 % interval (statistical "
                  'only); k (GUM) with its expanded uncertainty U (coverage factor k; the fit and the sensors\' '
                  'declared calibrations) and the repeatability it starts from (the 95 % interval of that fit, '
                  'statistical only), and E_n against the model\'s prediction with its own U (|E_n| <= 1: agree). The '
                  "models are the nominal crane's (the recorded geometry) at each session's W and l0. Largest "
                  f'|measured − tangent| / tangent: {_pct(worst)}.' + _true_note(rows)),
            session_table(rows)]
    if result.full:
        worst6 = max((r.worst_diagonal_error for r in result.full if math.isfinite(r.worst_diagonal_error)),
                     default=math.nan)
        blocks += [
            ('h2', 'The whole 6x6 stiffness (series full)'),
            ('p', "Each session's 6x6 K from its designed multi-axis test (errors in both variables, the bag's "
                  "offline fit, equal to the live one), against the nominal crane's exact tangent at its W and l0: "
                  "K's diagonal as measured / tangent − 1 (* where the 95 % interval misses the tangent), the "
                  'side–tilt coupling K2 with its interval and sign. Largest |diagonal error|: '
                  f'{_pct(worst6)}. Per session: full6 report and figures in its analysis folder.'),
            full_table(result.full)]
    if any(c.total >= COVERAGE_STUDY for c in result.coverage):
        departures = [c.quantity for c in result.coverage if not c.consistent]
        blocks += [('h2', 'Coverage of the 95 % intervals'),
                   ('p', 'How often each quantity\'s 95 % interval covers the truth (the true crane\'s exact '
                         'tangent, its inverse for C: the crane the simulated rig ran), with the fraction\'s '
                         'Clopper–Pearson 95 % interval (coverage.csv, coverage figure). "k <series> <branch>" is the '
                         'samples\' fit\'s statistical interval, ", repeatability" the statistical interval of the '
                         'fit U starts from, ", GUM U" the expanded interval k ± U; "prediction" the model\'s '
                         'interval for the nominal crane (± U as E_n uses it, and the Monte Carlo\'s). A statistical-'
                         'only interval counts no calibration error, so with sensors that have them it covers far '
                         'less than 0.95. Outside 0.95: ' + (', '.join(departures) or 'none') + '.'),
                   ('table', ['quantity', 'covered', 'fraction', '95 % interval'],
                    [[c.quantity, f'{c.covered}/{c.total}', f'{c.fraction:.3f}',
                      f'{c.interval[0]:.3f} … {c.interval[1]:.3f}'] for c in result.coverage])]
    for image in images:
        blocks.append(('img', image, Path(image).stem.replace('_', ' ')))
    every: list[SessionRow | Full6Row] = [*rows, *result.full]
    bad = [f'{r.session}: ' + '; '.join(r.reasons) for r in every if not r.ok]
    blocks += [('h2', 'Sessions not OK (drawn hollow)'), ('ul', bad or ['none'])]
    if result.missing:
        blocks += [('h2', 'Sessions planned but not run or not analysed'), ('ul', result.missing)]
    if result.failed:
        blocks += [('h2', 'Analyses that failed'), ('ul', [f'{k}: {v}' for k, v in result.failed.items()])]
    return blocks


def calibration_blocks(cal: Calibration, left_out: Sequence[SessionRow | Full6Row],
                       images: Sequence[str]) -> list[Block]:
    """The calibration's report: parameters with 95 % intervals, correlations, fit, per-session residuals."""
    headers = ['parameter', 'value', 'std. error', '95 % interval', 'unit', 'what']
    params = [[p.name, fmt(p.value, 7), fmt(p.stderr, 3), f'{fmt(p.ci95_low, 7)} … {fmt(p.ci95_high, 7)}', p.unit,
               p.description] for p in cal.parameters]
    names = [p.name for p in cal.parameters]
    corr = [[n, *(fmt(v, 3) for v in row)] for n, row in zip(names, cal.correlation)]
    per = [[s['session'], s['series'], s['holds'], fmt(s['rms_normalised_residual'], 3), fmt(s['measured_hold_slope']),
            fmt(s['nominal_tangent']), fmt(s['calibrated_tangent'])] for s in cal.sessions]
    blocks: list[Block] = [
        ('h1', 'Calibration of the model on the campaign'),
        ('p', f'Nonlinear least squares on the exact model over the hold means of {len(cal.sessions)} session(s): '
              f'χ² = {cal.chi2:.4g} on {cal.dof} degrees of freedom (the covariance scaled by χ²/dof).'),
        ('table', headers, params),
        ('h2', 'Wire'), ('ul', [f'{k}: {fmt(v, 7)}' for k, v in cal.wire.items()]),
        ('h2', 'Correlations'), ('table', ['', *names], corr),
        ('h2', 'Residuals per session'),
        ('table', ['session', 'series', 'holds', 'rms normalised residual', 'measured slope (holds)',
                   'nominal tangent', 'calibrated tangent'], per)]
    for image in images:
        blocks.append(('img', image, Path(image).stem.replace('_', ' ')))
    if left_out:
        blocks += [('h2', 'Sessions left out'), ('ul', [f'{r.session}: ' + ('; '.join(r.reasons) or 'no holds')
                                                        for r in left_out])]
    return blocks


def write_campaign_report(result: CampaignAnalysis, out: Path, reports: Sequence[str]) -> list[str]:
    """report.md / report.html in ``out``, linking the figures written there."""
    images = [Path(f).name for f in result.files if Path(f).suffix in ('.png', '.svg')]
    return write_blocks(campaign_blocks(result, images), out, 'report', reports, f'campaign {result.campaign}')
