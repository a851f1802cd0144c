"""The campaign's report (Markdown and HTML, the document model of crane_stiffness.analysis.report): the table of
sessions measured against the nominal model, the figures, the sessions not OK and why, the sessions missing."""
from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Sequence

from crane_stiffness.analysis.report import Block, fmt, to_html, to_markdown

if TYPE_CHECKING:
    from crane_stiffness.campaign.analyze import CampaignAnalysis, SessionRow


def _pct(value: float) -> str:
    return '–' if not math.isfinite(value) else f'{100 * value:+.3f} %'


def session_table(rows: Sequence[SessionRow]) -> Block:
    headers = ['session', 'series', 'W [N]', 'l0 [m]', 'measured k', '95 % interval', 'holds k', 'model tangent',
               'eq. (18)/(19)', 'W = 0', 'single wire W/6', 'measured vs tangent', 'status']
    body = [[r.session, r.series, fmt(r.weight, 4), fmt(r.l0, 4), fmt(r.k), f'{fmt(r.ci95_low)} … {fmt(r.ci95_high)}',
             fmt(r.k_holds), fmt(r.model_tangent), fmt(r.model_eq18), fmt(r.model_elastic_w0),
             fmt(r.model_single_wire), _pct(r.relative_error), r.status] for r in rows]
    return ('table', headers, body)


def campaign_blocks(result: CampaignAnalysis, images: Sequence[str]) -> list[Block]:
    rows = result.rows
    worst = max((abs(r.relative_error) for r in rows if math.isfinite(r.relative_error)), default=math.nan)
    blocks: list[Block] = [
        ('h1', f'Campaign {result.campaign}: {len(rows)} session(s)'),
        ('p', 'Measured stiffness: the loading branch fitted over all its pairs (as the live estimator fits), in the '
              "LVDT's reading units (N/m for fy and fz, N·m/rad for mz), with its 95 % interval; the models are the "
              "nominal crane's (the recorded geometry) at each session's W and l0. Largest |measured − tangent| / "
              f'tangent: {_pct(worst)}.'),
        session_table(rows)]
    for image in images:
        blocks.append(('img', image, Path(image).stem.replace('_', ' ')))
    bad = [f'{r.session}: ' + '; '.join(r.reasons) for r in rows if not r.ok]
    blocks += [('h2', 'Sessions not OK (drawn hollow)'), ('ul', bad or ['none'])]
    if result.missing:
        blocks += [('h2', 'Sessions planned but not run or not analysed'), ('ul', result.missing)]
    if result.failed:
        blocks += [('h2', 'Analyses that failed'), ('ul', [f'{k}: {v}' for k, v in result.failed.items()])]
    return blocks


def write_campaign_report(result: CampaignAnalysis, out: Path, reports: Sequence[str]) -> list[str]:
    """report.md / report.html in ``out``, linking the figures written there."""
    images = [Path(f).name for f in result.files if Path(f).suffix in ('.png', '.svg')]
    blocks = campaign_blocks(result, images)
    written = []
    for kind in reports:
        path = out / f'report.{kind}'
        path.write_text(to_markdown(blocks) if kind == 'md' else to_html(blocks, f'campaign {result.campaign}'),
                        encoding='utf-8')
        written.append(str(path))
    return written
