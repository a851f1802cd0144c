"""The 6×6 analysis of a session for people: the short table ``crane-stiffness analyze`` prints
(:func:`summary_lines`) and the report ``full6_report.md`` / ``.html`` (:func:`write_full6_report`, the blocks of
crane_stiffness.analysis.report). Numbers come from :class:`~crane_stiffness.analysis.full6.Full6Analysis`; NaN
shows as '–'.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Any, Sequence

import numpy as np

from crane_stiffness.analysis.report import Block, fmt, write_blocks
from crane_stiffness.contract.axes import AXES
from crane_stiffness.full6.reference import DISPLACEMENTS

if TYPE_CHECKING:
    from crane_stiffness.analysis.full6_result import Full6Analysis


def _pct(value: Any) -> str:
    return '–' if value is None or not math.isfinite(value) else f'{100.0 * value:+.3f} %'


def _yes(value: Any) -> str:
    return '–' if value is None else ('yes' if value else 'NO')


def headline(a: Full6Analysis) -> str:
    """One line: the session, its pairs and where they came from."""
    p = a.pairs
    return (f'six-axis session {a.session} ({a.bag}): {p["n"]} pairs in {p["steps"]} steps, from {p["poses"]} poses, '
            f'{p["wrench_samples"]} load-cell samples and {p["commands"]} commands')


def settings_line(a: Full6Analysis) -> str:
    """The pairing and fit settings, and where they were read."""
    s = a.settings
    noise = 'from the steps' if s['wrench_noise'] is None else ', '.join(f'{v:g}' for v in s['wrench_noise'])
    return (f'settle {fmt(s["settle_s"])} s, max gap {fmt(s["max_gap_s"])} s, max age {fmt(s["max_age_s"])} s, '
            f'wrench noise {noise}, {100 * s["confidence"]:g} % intervals ({s["source"]}); load cell mounting from '
            f'{s["mount_source"]}')


def k2_line(a: Full6Analysis) -> str:
    """K2 with its sign and interval, against the tangent and eq. (18)."""
    k = a.k2
    if not math.isfinite(k['value']):
        return 'K2: – (no numbers from the fit)'
    line = (f'K2 = {k["value"]:+.6g} N/rad (95 % CI {fmt(k["low"])} … {fmt(k["high"])}), sign {k["sign"]}')
    if 'tangent' in k:
        line += (f' ({"as" if k["sign_as_tangent"] else "NOT as"} the tangent\'s); tangent {fmt(k["tangent"])} '
                 f'({_pct(k["relative_error_tangent"])}, CI holds it: {_yes(k["covers_tangent"])})')
        if k.get('paper') is not None:
            line += f', eq. (18) {fmt(k["paper"])} ({_pct(k["relative_error_paper"])})'
    return line


def fit_line(a: Full6Analysis) -> str:
    """Coverage, condition number and lack of fit."""
    parts = []
    if a.fit is not None and not np.all(np.isfinite(a.fit.stiffness)):
        parts.append('no numbers to compare with the model')
    elif a.comparison is not None:
        c = a.comparison['covered']
        parts.append(f'{c["stiffness"]} of 36 intervals of K hold the tangent\'s entry (C: {c["compliance"]} of 36)')
    parts.append(f'condition number {fmt(a.condition, 4)}, lack of fit {fmt(a.lack_of_fit, 4)} '
                 f'(p = {fmt(a.lack_of_fit_p, 3)})')
    return '; '.join(parts)


def status_text(a: Full6Analysis) -> str:
    """'OK: 26 steps, …', 'WARN nonlinear: …', 'ERROR undetermined: …'."""
    level, message = a.status['level'], a.status['message']
    return message if message.startswith(level) else f'{level} {message}'


def diagonal_rows(a: Full6Analysis) -> list[list[str]]:
    """K's diagonal: entry, unit, measured, 95 % CI, tangent, error, whether the CI holds the tangent."""
    return [[d['entry'], d['unit'], fmt(d['measured']), f'{fmt(d["low"])} … {fmt(d["high"])}', fmt(d['tangent']),
             _pct(d['relative_error']), _yes(d['covers'])] for d in a.diagonal]


_HEADERS = ['entry', 'unit', 'measured', '95 % CI', 'tangent', 'error', 'CI holds tangent']


def summary_lines(a: Full6Analysis) -> list[str]:
    """What ``crane-stiffness analyze`` prints for a six-axis session."""
    rows = [_HEADERS] + diagonal_rows(a)
    widths = [max(len(r[i]) for r in rows) for i in range(len(_HEADERS))]
    table = ['  ' + '  '.join(f'{v:<{w}}' if i < 2 else f'{v:>{w}}' for i, (v, w) in enumerate(zip(r, widths)))
             for r in rows]
    out = [headline(a), '  ' + settings_line(a), f'status {status_text(a)}',
           'K diagonal (each axis with the other five displacements held at zero):'] + table
    out += [k2_line(a), fit_line(a)]
    gum = gum_rows(a)
    if gum:
        rows = [_GUM_HEADERS] + gum
        widths = [max(len(r[i]) for r in rows) for i in range(len(_GUM_HEADERS))]
        out += ['measurement uncertainty (GUM, 95 %):'] + [
            '  ' + '  '.join(f'{v:<{w}}' if i == 0 else f'{v:>{w}}' for i, (v, w) in enumerate(zip(r, widths)))
            for r in rows]
    out.append(gum_line(a))
    out += [f'  ! {p}' for p in a.problems]
    return out


_GUM_HEADERS = ['entry', 'measured', 'U (k)', 'statistical 95 % CI', 'model ± U', 'E_n']


def _num(value: Any, digits: int = 6) -> str:
    return '–' if value is None or value == 'inf' else fmt(float(value), digits)


def gum_rows(a: Full6Analysis) -> list[list[str]]:
    """K's diagonal and K2 with their GUM uncertainty: entry, measured, U with k, the statistical interval, the
    model's tangent ± its U, E_n. Empty without an uncertainty."""
    from crane_stiffness.full6.reference import entry_name
    u = a.uncertainty
    if not u:
        return []
    k, pred, en = u['stiffness'], u.get('prediction'), u.get('En')
    rows = []
    for i in range(6):
        model = '–' if pred is None else (f'{_num(pred["stiffness"]["value"][i][i])} ± '
                                          f'{_num(pred["stiffness"]["U"][i][i], 4)}')
        rows.append([entry_name(i, i), _num(k['value'][i][i]), f'{_num(k["U"][i][i], 4)} ({_num(k["k"][i][i], 3)})',
                     f'{_num(k["statistical_interval"][0][i][i])} … {_num(k["statistical_interval"][1][i][i])}',
                     model, '–' if en is None else _num(en['stiffness'][i][i], 3)])
    k2 = u['k2']
    model = '–' if pred is None else f'{_num(pred["k2"]["value"])} ± {_num(pred["k2"]["U"], 4)}'
    rows.append(['K2', _num(k2['value']), f'{_num(k2["U"], 4)} ({_num(k2["k"], 3)})',
                 f'{_num(k2["statistical_interval"][0])} … {_num(k2["statistical_interval"][1])}', model,
                 '–' if en is None else _num(en['k2'], 3)])
    return rows


def gum_line(a: Full6Analysis) -> str:
    """What the uncertainty counts, and how many entries agree with the model."""
    u = a.uncertainty
    if not u:
        return 'measurement uncertainty: – (the step means cannot give it; see the problems)'
    line = (f'GUM: Type A from {u["type_a"]["steps"]} step means (ν = {u["type_a"]["dof"]}); {u["calibration"]}; '
            f'{u["trials"]} Monte Carlo trials (JCGM 102)')
    if u.get('En'):
        line += f'; E_n: {u["En"]["agree"]} of {u["En"]["of"]} entries of K agree with the model (|E_n| <= 1)'
    return line


def _matrix_rows(value: list[list[float]], low: list[list[float]], high: list[list[float]]) -> list[list[str]]:
    return [[AXES[i]] + [f'{fmt(value[i][j], 5)} [{fmt(low[i][j], 4)} … {fmt(high[i][j], 4)}]' for j in range(6)]
            for i in range(6)]


def full6_blocks(a: Full6Analysis, images: Sequence[str] = ()) -> list[Block]:
    """The report of a six-axis session as blocks (crane_stiffness.analysis.report)."""
    g = a.geometry
    rows = [['bag', a.bag], ['duration', f'{fmt(a.duration_s, 5)} s'],
            ['software', f'recorded with {a.recorded_with or "?"}, analysed with {a.analysed_with}'],
            ['pairs', f'{a.pairs["n"]} in {a.pairs["steps"]} steps ({a.pairs["poses"]} poses, '
                      f'{a.pairs["wrench_samples"]} load-cell samples, {a.pairs["commands"]} commands)'],
            ['settings', settings_line(a)],
            ['geometry', '–' if g is None else (f'a = {fmt(g["a"])} m, b = {fmt(g["b"])} m, h = {fmt(g["height"])} '
                                                f'm, W = {fmt(g["weight"])} N, l0 = {fmt(g["l0"])} m, '
                                                f'k = {fmt(g["k"])} N/m')]]
    if a.notes:
        rows.append(['notes', a.notes])
    blocks: list[Block] = [('h1', f'Six-axis session {a.session}: the 6×6 stiffness'), ('table', ['', ''], rows),
                           ('p', f'Status {status_text(a)}'),
                           ('h2', 'K diagonal'), ('table', _HEADERS, diagonal_rows(a)), ('p', k2_line(a)),
                           ('p', fit_line(a)), ('h2', 'K with 95 % intervals (rows loads, columns displacements)')]
    columns = ['load', *DISPLACEMENTS]
    s = a.stiffness
    blocks.append(('table', columns, _matrix_rows(s['value'], s['low'], s['high'])))
    u = a.uncertainty
    if u:
        blocks += [('h2', 'Measurement uncertainty (GUM, 95 %): K\'s diagonal and K2'), ('p', gum_line(a)),
                   ('table', _GUM_HEADERS, gum_rows(a)),
                   ('h2', 'K ± U (expanded uncertainty, 95 %; rows loads, columns displacements)'),
                   ('table', columns, [[AXES[i]] + [f'{_num(u["stiffness"]["value"][i][j], 5)} ± '
                                                    f'{_num(u["stiffness"]["U"][i][j], 3)}' for j in range(6)]
                                       for i in range(6)]),
                   ('h2', 'C ± U (rows displacements, columns loads)'),
                   ('table', ['displacement', *AXES], [[DISPLACEMENTS[i]] + [
                       f'{_num(u["compliance"]["value"][i][j], 5)} ± {_num(u["compliance"]["U"][i][j], 3)}'
                       for j in range(6)] for i in range(6)])]
        if u.get('En'):
            blocks += [('h2', 'E_n per entry of K against the model (|E_n| <= 1 agrees)'),
                       ('table', columns, [[AXES[i]] + [_num(v, 3) for v in row]
                                           for i, row in enumerate(u['En']['stiffness'])])]
    if a.reference is not None:
        t = a.reference['tangent']
        blocks += [('h2', 'Exact tangent at the rest pose'),
                   ('table', columns, [[r] + [fmt(v, 6) for v in row] for r, row in zip(AXES, t)])]
    for image in images:
        blocks.append(('img', image, Path(image).stem.replace('_', ' ')))
    if a.problems:
        blocks += [('h2', 'Problems'), ('ul', a.problems)]
    return blocks


def write_full6_report(a: Full6Analysis, out: Path, reports: Sequence[str]) -> list[str]:
    """full6_report.md / .html (``reports``) in ``out``, linking the figures already written there."""
    images = [Path(f).name for f in a.files if Path(f).suffix in ('.png', '.svg')]
    return write_blocks(full6_blocks(a, images), Path(out), 'full6_report', reports, f'six-axis session {a.session}')


__all__ = ['diagonal_rows', 'fit_line', 'full6_blocks', 'gum_line', 'gum_rows', 'headline', 'k2_line',
           'settings_line', 'status_text', 'summary_lines', 'write_full6_report']
