"""Reports of an analysed session and of a comparison of sessions (:mod:`crane_stiffness.analysis.results`): one
document model rendered as Markdown and as HTML.

A document is a list of blocks ``(kind, ...)``: ``('h1'|'h2', text)``, ``('p', text)``, ``('ul', [items])``,
``('table', headers, rows)`` and ``('img', relative path, caption)``. Numbers are formatted here; NaN shows as '–'.
"""
from __future__ import annotations

import html
import math
from pathlib import Path
from typing import Any, Sequence

from crane_stiffness.analysis.results import SessionAnalysis, SessionComparison
from crane_stiffness.analysis.stiffness_uncertainty import uncertainty_lines
from crane_stiffness.estimation.fit import LineFit
from crane_stiffness.estimation.settings import noise_text, pairing_text

Block = tuple


def fmt(value: Any, digits: int = 6) -> str:
    if value is None:
        return '–'
    if isinstance(value, bool):
        return 'yes' if value else 'no'
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return '–' if not math.isfinite(value) else f'{value:.{digits}g}'
    return str(value)


def _um(value: float) -> str:
    return fmt(value * 1e6 if value is not None else None, 5)


def _fit_cells(fit: LineFit | None) -> list[str]:
    if fit is None:
        return ['–'] * 5
    return [fmt(fit.stiffness), f'{fmt(fit.ci95_low)} … {fmt(fit.ci95_high)}', fmt(fit.r2, 7), fmt(fit.n),
            fmt(fit.nonlinearity, 3)]


def _mapping_rows(m: dict[str, Any]) -> list[list[Any]]:
    """The report's rows of what was read and how (analysis.mapping.MappingUsed as a dict)."""
    if not m:
        return []
    src = m.get('sources', {})
    return [['load', f'{m["wrench_topic"]} [{m["wrench_msg_type"]}]'],
            ['displacement', f'{m["displacement_topic"]} [{m["displacement_msg_type"]}], displacement_type '
                             f'{m["displacement_type"]} ({src.get("displacement_type", "?")}): {m["conversion"]}; '
                             f'{m["sample_instant"]}'],
            ['displacement_gain, _offset', f'{fmt(m["displacement_gain"])} m/V ({src.get("displacement_gain", "?")}), '
                                           f'{fmt(m["displacement_offset"])} m '
                                           f'({src.get("displacement_offset", "?")})'],
            ['geometry from', m['geometry_source']]]


def mapping_text(m: dict[str, Any]) -> str:
    """One line: the topics, type, gain and offset a session was read with (the comparison's table)."""
    if not m:
        return '–'
    text = f'{m["wrench_topic"]}, {m["displacement_topic"]} ({m["displacement_type"]}'
    if m['displacement_type'] == 'float64':
        text += f', {fmt(m["displacement_gain"])} m/V, {fmt(m["displacement_offset"])} m'
    return text + f'); geometry {m["geometry_source"]}'


def verdict_text(a: SessionAnalysis) -> str:
    """'Verdict: OK' or 'Verdict: NOT OK: …' (the reasons are listed under Problems)."""
    v = a.verdict
    if v.get('level', 'OK') == 'OK':
        return 'Verdict: OK (no fit refused, none far from the model; the problems below, if any, do not change it).'
    return f"Verdict: NOT OK: {len(v['reasons'])} reason(s), listed first under Problems."


def session_blocks(a: SessionAnalysis, images: Sequence[str] = ()) -> list[Block]:
    """The report of one session as blocks."""
    unit = a.unit
    blocks: list[Block] = [('h1', f'Stiffness test session {a.session}'), ('p', verdict_text(a))]
    rows: list[list[Any]]  # table cells, str() of each (numbers for the later tables)
    rows = [['bag', a.bag], ['recorded (UTC)', a.start_time_utc or '–'], ['duration', f'{fmt(a.duration_s, 5)} s'],
            ['messages', fmt(sum(a.counts.values()))], ['software', f'recorded with {a.recorded_with or "?"}, '
                                                                    f'analysed with {a.analysed_with}'],
            ['load axis', f'{a.axis} (stiffness in {unit} of LVDT reading)']]
    if a.notes:
        rows.append(['notes', a.notes])
    if a.program:
        p = a.program
        rows.append(['program', f'{p["name"]}: {len(p["segments.kind"])} segments × {p["repeats"]}, '
                                f'{fmt(p["duration_s"], 5)} s, levels {", ".join(fmt(v, 4) for v in p["levels"])}'
                                f'; final state {p.get("final_state") or "unknown"}'])
    else:
        rows.append(['program', 'not recorded'])
    if a.geometry:
        g = a.geometry
        rows.append(['geometry', f'a = {fmt(g["a"])} m, b = {fmt(g["b"])} m, h = {fmt(g["height"])} m, '
                                 f'W = {fmt(g["weight"])} N, l0 = {fmt(g["l0"])} m, k = {fmt(g["k"])} N/m'])
    rows += _mapping_rows(a.mapping)
    s = a.settings
    pairing = pairing_text(s.get('pairing', 'nearest'), s['slop_s'], s.get('max_interpolation_gap_s', math.nan))
    noise = noise_text(s.get('displacement_noise', 0.0), 'm' if a.axis.startswith('f') else 'rad')
    rows.append(['estimator settings', f'pairing: {pairing}, max age {fmt(s["max_age_s"])} s, window '
                                       f'{s["window"]} pairs, hysteresis {fmt(s["hysteresis"])}, branch from '
                                       f'{s["branch_source"]}; fits: {noise}'])
    blocks.append(('table', ['', ''], rows))
    blocks.append(('h2', 'Stiffness'))
    headers = ['fit', 'branch', f'k [{unit}]', '95 % CI', 'R²', 'n', 'nonlinearity']
    rows = []
    for branch in ('loading', 'unloading'):
        rows.append(['all pairs of the branch', branch] + _fit_cells(a.branch_fits.get(branch)))
    for branch in ('loading', 'unloading'):
        rows.append(['hold means (quasi-static)', branch] + _fit_cells(a.hold_fits.get(branch)))
    blocks.append(('table', headers, rows))
    if a.model is not None:
        m = a.model
        sc = m.lvdt_scale
        blocks.append(('p', f'Model of the recorded geometry along {m.axis}' + (
            '' if sc == 1.0 else f' (converted to LVDT reading: reading = {fmt(sc, 4)} × displacement along the axis)')
            + ':'))
        rows = [['exact tangent at the loaded rest pose (other DOFs free)',
                 fmt(m.tangent_at_rest * sc if sc else None)],
                ['linearized, eq. (18)', fmt(m.eq18 * sc if sc else None)],
                ['W = 0, elastic only, eq. (28)', fmt(m.elastic_w0 * sc if sc else None)],
                ['single wire carrying W/6', fmt(m.single_wire_w6 * sc if sc else None)],
                ['published live by crane_model', fmt(m.recorded_prediction * sc if sc else None)]]
        loading = a.branch_fits.get('loading')
        if loading is not None and sc and math.isfinite(m.tangent_at_rest):
            rows.append(['relative error of the loading fit vs the tangent',
                         f'{100 * (loading.stiffness - m.tangent_at_rest * sc) / (m.tangent_at_rest * sc):+.3f} %'])
        blocks.append(('table', ['model', f'k [{unit}]'], rows))
    if a.uncertainty:
        blocks.append(('p', 'Measurement uncertainty (GUM; docs/uncertainty.md, "The measured stiffness"):'))
        blocks.append(('ul', uncertainty_lines(a.uncertainty, unit)))
        budget = [Path(f).name for f in a.files if Path(f).stem == 'budget']
        if budget:
            blocks.append(('p', f'The budget of each estimate: {", ".join(budget)} (the contributions |c_i|·u(x_i), '
                                'largest first, u_c and U marked).'))
    if a.live is not None:
        live = a.live
        blocks.append(('h2', 'Live estimate reproduced'))
        blocks.append(('p', f'The last estimate published by stiffness_estimator (newest pair stamped '
                            f'{fmt(live.sample_stamp_s, 15)} s) beside the same window fitted offline from the bag.'))
        rows = []
        for branch in ('loading', 'unloading'):
            for f in ('stiffness', 'ci95_low', 'ci95_high', 'r2', 'n', 'rls_stiffness'):
                rows.append([branch, f, fmt(live.live[branch][f], 10), fmt(live.offline[branch][f], 10)])
            rows.append([branch, 'largest relative difference', '', fmt(live.max_rel_diff[branch], 3)])
        blocks.append(('table', ['branch', 'value', 'live', 'offline'], rows))
        if live.inputs:
            i = live.inputs
            blocks.append(('p', f'Over the {i["to_s"] - i["from_s"]:.1f} s between its first and last recorded '
                                f'report, the estimator received {i["live_force_received"]} load-cell samples and '
                                f'paired {i["live_pairs"]}; the bag holds {i["bag_force_messages"]} and pairs '
                                f'{i["offline_pairs"]}. The estimate is reproduced exactly only when both saw the '
                                'same samples.'))
    if a.steps:
        blocks.append(('h2', f'Test steps ({len(a.steps)} holds)'))
        rows = [[s.index, fmt(s.level, 5), s.approach, '–' if s.repeat is None else s.repeat,
                 f'{s.start_s:.2f}–{s.end_s:.2f}', s.n, fmt(s.force_mean, 6), fmt(s.force_std, 3),
                 _um(s.displacement_mean), _um(s.displacement_std), _um(s.model_displacement)] for s in a.steps]
        blocks.append(('table', ['#', 'level', 'approach', 'repeat', 't [s]', 'n', 'load mean', 'load std',
                                 'LVDT mean [µm]', 'LVDT std [µm]', 'model [µm]'], rows))
    if a.cycle_fits:
        blocks.append(('h2', 'Per repeat'))
        rows = [[c.repeat, f'{c.start_s:.2f}–{c.end_s:.2f}', fmt(c.loading.stiffness if c.loading else None),
                 fmt(c.unloading.stiffness if c.unloading else None)] for c in a.cycle_fits]
        blocks.append(('table', ['repeat', 't [s]', f'loading k [{unit}]', f'unloading k [{unit}]'], rows))
    blocks.append(('h2', 'Pairing'))
    blocks.append(('table', ['counter', 'value'], [[k, fmt(v)] for k, v in a.pairing.items()]))
    if a.stream_delay:
        blocks.append(('table', ['stream delay (displacement against force)', 'value'],
                       [[k, v] for k, v in a.stream_delay.items()]))
    for image in images:
        blocks.append(('img', image, Path(image).stem.replace('_', ' ')))
    if a.problems:
        blocks.append(('h2', 'Problems'))
        reasons = list(a.verdict.get('reasons', []))
        blocks.append(('ul', reasons + [p for p in a.problems if p not in reasons]))
    return blocks


def comparison_blocks(c: SessionComparison, images: Sequence[str] = ()) -> list[Block]:
    headers = ['session', 'program', 'axis', 'W [N]', 'l0 [m]', 'loading k', '95 % CI', 'unloading k',
               'holds loading k', 'live loading k', 'model tangent k', 'error vs model', 'nonlinearity', 'problems']
    rows = []
    for r in c.rows:
        err = r['relative_error_loading']
        rows.append([r['session'], r['program'], r['axis'], fmt(r['weight_N'], 5), fmt(r['l0_m'], 5),
                     fmt(r['loading_k']), f'{fmt(r["loading_ci95_low"])} … {fmt(r["loading_ci95_high"])}',
                     fmt(r['unloading_k']), fmt(r['holds_loading_k']), fmt(r['live_loading_k']),
                     fmt(r['model_tangent_k']), '–' if not math.isfinite(err) else f'{100 * err:+.3f} %',
                     fmt(r['nonlinearity_loading'], 3), r['problems']])
    blocks: list[Block] = [('h1', f'Comparison of {len(c.rows)} session(s)'),
                           ('p', 'Stiffness in N/m (N·m/rad for moment axes) of LVDT reading; fits over all pairs of '
                                 'each branch unless noted.'),
                           ('table', headers, rows)]
    blocks += uncertainty_comparison_blocks(c)
    for image in images:
        blocks.append(('img', image, Path(image).stem.replace('_', ' ')))
    problems = [f'{a.session}: {p}' for a in c.sessions for p in a.problems]
    blocks += [('h2', 'Topics and units read'),
               ('table', ['session', 'load, displacement (type, gain, offset); geometry'],
                [[a.session, mapping_text(a.mapping)] for a in c.sessions])]
    if problems:
        blocks += [('h2', 'Problems'), ('ul', problems)]
    return blocks


def _k_with_u(k: float, big_u: float, factor: float) -> str:
    """'53786 ± 799 (k = 1.96)', or '–'."""
    if not math.isfinite(k):
        return '–'
    return f'{fmt(k)} ± {fmt(big_u, 4)} (k = {factor:.2f})' if math.isfinite(big_u) else fmt(k)


def _en(en: float) -> str:
    return '–' if not math.isfinite(en) else f"{en:+.2f} ({'agree' if abs(en) <= 1.0 else 'DISAGREE'})"


def uncertainty_comparison_blocks(c: SessionComparison) -> list[Block]:
    """Each session's k ± U (coverage factor k) per branch and E_n with the model; every two sessions' E_n."""
    rows = []
    for r in c.rows:
        for branch in ('loading', 'unloading'):
            rows.append([r['session'], f"{branch} ({r[f'{branch}_fit'] or '–'})",
                         _k_with_u(r[f'{branch}_measured_k'], r[f'{branch}_U'], r[f'{branch}_coverage_factor']),
                         _k_with_u(r['model_k'], r['model_U'], r['model_coverage_factor']),
                         _en(r[f'{branch}_En_model'])])
    blocks: list[Block] = [('h2', 'Measurement uncertainty and agreement'),
                           ('p', 'k ± U (expanded uncertainty, 95 %, GUM, coverage factor k) of each branch and of the '
                                 'model\'s prediction; E_n = (k − k_model)/√(U² + U_model²), |E_n| <= 1 agrees.'),
                           ('table', ['session', 'branch (fit)', 'k ± U', 'model ± U', 'E_n vs model'], rows)]
    if c.agreement:
        blocks += [('p', 'Sessions against each other: E_n = (k_b − k_a)/√(U_a² + U_b²), both measurements\' U.'),
                   ('table', ['a', 'b', 'branch', 'k_a ± U_a', 'k_b ± U_b', 'E_n'],
                    [[p['a'], p['b'], p['branch'], f"{fmt(p['k_a'])} ± {fmt(p['U_a'], 4)}",
                      f"{fmt(p['k_b'])} ± {fmt(p['U_b'], 4)}", _en(p['En'])] for p in c.agreement])]
    return blocks


def _md_cell(value: Any) -> str:
    return str(value).replace('|', '\\|').replace('\n', ' ')


def to_markdown(blocks: Sequence[Block]) -> str:
    out: list[str] = []
    for block in blocks:
        kind = block[0]
        if kind == 'h1':
            out.append(f'# {block[1]}\n')
        elif kind == 'h2':
            out.append(f'## {block[1]}\n')
        elif kind == 'p':
            out.append(f'{block[1]}\n')
        elif kind == 'ul':
            out.append('\n'.join(f'- {_md_cell(item)}' for item in block[1]) + '\n')
        elif kind == 'table':
            headers, rows = block[1], block[2]
            lines = ['| ' + ' | '.join(_md_cell(h) for h in headers) + ' |',
                     '|' + '|'.join('---' for _ in headers) + '|']
            lines += ['| ' + ' | '.join(_md_cell(v) for v in row) + ' |' for row in rows]
            out.append('\n'.join(lines) + '\n')
        elif kind == 'img':
            out.append(f'![{block[2]}]({block[1]})\n')
    return '\n'.join(out)


def to_html(blocks: Sequence[Block], title: str) -> str:
    e = html.escape
    body: list[str] = []
    for block in blocks:
        kind = block[0]
        if kind in ('h1', 'h2'):
            body.append(f'<{kind}>{e(str(block[1]))}</{kind}>')
        elif kind == 'p':
            body.append(f'<p>{e(str(block[1]))}</p>')
        elif kind == 'ul':
            body.append('<ul>' + ''.join(f'<li>{e(str(i))}</li>' for i in block[1]) + '</ul>')
        elif kind == 'table':
            head = ''.join(f'<th>{e(str(h))}</th>' for h in block[1])
            rows = ''.join('<tr>' + ''.join(f'<td>{e(str(v))}</td>' for v in row) + '</tr>' for row in block[2])
            body.append(f'<table><thead><tr>{head}</tr></thead><tbody>{rows}</tbody></table>')
        elif kind == 'img':
            body.append(f'<figure><img src="{e(str(block[1]))}" alt="{e(str(block[2]))}">'
                        f'<figcaption>{e(str(block[2]))}</figcaption></figure>')
    style = ('body{font-family:sans-serif;max-width:1100px;margin:2em auto;color:#222}'
             'table{border-collapse:collapse;margin:1em 0;font-size:0.9em}'
             'td,th{border:1px solid #bbb;padding:3px 8px;text-align:left}th{background:#eee}'
             'img{max-width:100%}figure{margin:1em 0}')
    return (f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8"><title>{e(title)}</title>'
            f'<style>{style}</style></head><body>\n' + '\n'.join(body) + '\n</body></html>\n')


def write_blocks(blocks: list[Block], out: Path, stem: str, reports: Sequence[str], title: str) -> list[str]:
    """``<stem>.md`` / ``<stem>.html`` (``reports``) of ``blocks`` in ``out``; returns the paths written."""
    written = []
    for kind in reports:
        path = out / f'{stem}.{kind}'
        path.write_text(to_markdown(blocks) if kind == 'md' else to_html(blocks, title), encoding='utf-8')
        written.append(str(path))
    return written


def write_session_report(a: SessionAnalysis, out: Path, reports: Sequence[str]) -> list[str]:
    """report.md / report.html in ``out`` (figures already written there are linked)."""
    images = [Path(f).name for f in a.files if Path(f).suffix in ('.png', '.svg')]
    return write_blocks(session_blocks(a, images), Path(out), 'report', reports, f'session {a.session}')


def write_comparison_report(c: SessionComparison, out: Path, reports: Sequence[str]) -> list[str]:
    images = [Path(f).name for f in c.files if Path(f).suffix in ('.png', '.svg')]
    return write_blocks(comparison_blocks(c, images), Path(out), 'compare', reports, 'sessions compared')
