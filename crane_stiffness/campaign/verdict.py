"""A campaign session's verdict, shown before the next set-up: the session analysed at once by the analysis
``campaign analyze`` runs (:func:`crane_stiffness.campaign.analyze.analyze_one` into ``DIR/analysis/<session>/``, so
``campaign analyze`` later finds it current), its row (:func:`~crane_stiffness.campaign.analyze.session_row` or
:func:`~crane_stiffness.campaign.analyze.full_row`: the status and its reasons as the campaign's table has them), the
loading k with its GUM U and E_n against the model, and whether the bag holds the whole run (the result's
``recording.problem``, crane_stiffness.bag.session_metadata.cut_short).

A session is NOT OK when its row is NOT OK, its bag was cut short, it could not be analysed, or a branch is far from
the model (|E_n| > 1) while the crane on the rig is meant to be the modelled one (hardware, or a simulated nominal
crane; a campaign that simulates another crane on purpose finds the disagreement in its tables instead). The
verdict, with what the operator decided after it, is kept in ``DIR/sessions/<session>/verdict.json`` (written after
result.json: a session resumed later keeps its verdict, and the run's exit code counts it). No ROS.
"""
from __future__ import annotations

import json
import math
import os
import sys
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping, TextIO

from crane_stiffness.campaign.analyze import (ANALYSIS_FILES, analysis_current, analyze_one, full_row,
                                              session_row)
from crane_stiffness.campaign.full_series import FULL

VERDICT_FILE = 'verdict.json'
#: What the operator can do after a NOT OK session (``ask``: a prompt at the terminal).
NOT_OK_ACTIONS = ('ask', 'continue', 'stop')


@dataclass
class SessionVerdict:
    """One session's verdict. Stiffness in the analysis' unit along the series' axis (N/m, N·m/rad); for the series
    full ``k`` is K2 (the lateral stiffness) and U/E_n are not given."""

    session: str
    status: str
    """'OK' or 'NOT OK'."""
    reasons: list[str] = field(default_factory=list)
    """Why NOT OK: the analysis' problems, the estimator's last status, a bag cut short, an analysis that failed."""
    unit: str = ''
    k: float = math.nan
    """The measured loading stiffness (its fit over all pairs, as campaign analyze's table)."""
    U: float = math.nan
    """Its expanded uncertainty (GUM, 95 %), from the analysis' hold-means budget."""
    model: float = math.nan
    """The nominal model's exact tangent at rest, in the same unit."""
    relative_error: float = math.nan
    en: float = math.nan
    """E_n of the GUM estimate against the model's prediction with its uncertainty (|E_n| <= 1 agrees)."""
    cut_short: str = ''
    """'' when the bag holds the whole run, else why not."""
    decision: str = ''
    """What was done after it: continued, continued (not asked), repeated, stopped."""

    @property
    def ok(self) -> bool:
        return self.status == 'OK'

    def to_dict(self) -> dict[str, Any]:
        return {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in asdict(self).items()}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> SessionVerdict:
        fields = cls.__dataclass_fields__
        values: dict[str, Any] = {k: (math.nan if v is None and isinstance(fields[k].default, float) else v)
                                  for k, v in data.items() if k in fields}
        return cls(**values)

    def lines(self) -> list[str]:
        """The verdict for the operator: a headline, the numbers, each reason."""
        def num(v: float, fmt: str) -> str:
            return format(v, fmt) if math.isfinite(v) else '-'
        head = f'session {self.session}: {self.status}'
        numbers = (f'  k = {num(self.k, ".6g")} {self.unit}, U = {num(self.U, ".4g")} {self.unit} (95 %), model '
                   f'{num(self.model, ".6g")} {self.unit} ({num(100 * self.relative_error, "+.2f")} %), '
                   f'E_n = {num(self.en, "+.2f")}')
        return [head, numbers] + [f'  problem: {r}' for r in self.reasons]


def session_verdict(out: str | os.PathLike, plan: Mapping[str, Any], result: Mapping[str, Any]) -> SessionVerdict:
    """Analyse the session ``plan`` of the campaign directory ``out`` (unless its analysis is current) and give its
    verdict; ``result`` is its result.json."""
    out = Path(out)
    session = str(plan['id'])
    kind = 'full' if plan['series'] == FULL else 'one_axis'
    bag = out / 'bags' / session
    target = out / 'analysis' / session
    cut = str(((result.get('recording') or {}).get('problem')) or '')
    if not bag.exists():
        cut = cut or 'no bag was recorded'
    why = ''
    if bag.exists() and not analysis_current(bag, target, kind):
        why = analyze_one(str(bag), str(target), kind)
    file = target / ANALYSIS_FILES[kind]
    if why or not file.is_file():
        reasons = [f'the analysis failed: {why or "no analysis written"}'] + ([f'the bag is cut short: {cut}']
                                                                              if cut else [])
        return SessionVerdict(session=session, status='NOT OK', reasons=reasons, cut_short=cut)
    analysis = json.loads(file.read_text())
    if kind == 'full':
        row6 = full_row(dict(plan), analysis, dict(result), target)
        verdict = SessionVerdict(session=session, status=row6.status, reasons=list(row6.reasons), unit='N/m (K2)',
                                 k=row6.k2, model=row6.k2_tangent,
                                 relative_error=(row6.k2 / row6.k2_tangent - 1.0) if row6.k2_tangent else math.nan)
    else:
        row = session_row(dict(plan), analysis, dict(result), target)
        loading = (analysis.get('uncertainty') or {}).get('loading') or {}
        verdict = SessionVerdict(session=session, status=row.status, reasons=list(row.reasons), unit=row.unit, k=row.k,
                                 U=_number((loading.get('uncertainty') or {}).get('U')), model=row.model_tangent,
                                 relative_error=row.relative_error, en=_number((loading.get('En') or {}).get('en')))
        disagreements = list(analysis.get('model_disagreements') or [])
        if disagreements and plan.get('true') == plan.get('nominal'):
            # The rig is meant to be the modelled crane (hardware, or a simulated nominal one): a number far from the
            # model beyond any plausible uncertainty is a gain, sign, unit or set-up to check before the next set-up.
            # Where the campaign simulates another crane on purpose, the disagreement is its finding (its tables).
            verdict.status = 'NOT OK'
            verdict.reasons.extend(r for r in disagreements if r not in verdict.reasons)
    if cut:
        verdict.cut_short = cut
        verdict.status = 'NOT OK'
        verdict.reasons.append(f'the bag is cut short: {cut}')
    return verdict


def _number(value: Any) -> float:
    return math.nan if value is None else float(value)


def write_verdict(out: str | os.PathLike, verdict: SessionVerdict) -> Path:
    """Keep ``verdict`` in DIR/sessions/<session>/verdict.json."""
    path = Path(out) / 'sessions' / verdict.session / VERDICT_FILE
    tmp = path.with_suffix('.tmp')
    tmp.write_text(json.dumps(verdict.to_dict(), indent=1, allow_nan=False))
    os.replace(tmp, path)
    return path


def read_verdict(out: str | os.PathLike, session: str) -> SessionVerdict | None:
    """The verdict kept for ``session`` (None: none kept, e.g. a session run before verdicts were kept)."""
    try:
        return SessionVerdict.from_dict(json.loads((Path(out) / 'sessions' / session / VERDICT_FILE).read_text()))
    except (OSError, ValueError, TypeError):
        return None


def not_ok_summary(verdicts: Mapping[str, SessionVerdict]) -> list[str]:
    """One line per NOT OK session: its name and the causes (empty when every session is OK)."""
    return [f'{name}: ' + '; '.join(v.reasons or ['NOT OK']) for name, v in verdicts.items() if not v.ok]


class Review:
    """After each session of ``campaign run``: its verdict shown (on ``stream``) before the next set-up, kept in
    verdict.json, and for a NOT OK session what to do: ``on_not_ok`` 'continue' (go on, the session marked), 'stop'
    (stop the campaign), or 'ask' the operator (``ask``: repeat / continue / stop) when the run is interactive,
    else continue and mark. ``__call__`` is the runner's review (crane_stiffness.campaign.runner.Review)."""

    def __init__(self, out: str | os.PathLike, on_not_ok: str = 'ask', interactive: bool = False,
                 ask: Callable[[str], str] | None = None, stream: TextIO | None = None) -> None:
        if on_not_ok not in NOT_OK_ACTIONS:
            raise ValueError(f'on_not_ok {on_not_ok!r}: expected one of {", ".join(NOT_OK_ACTIONS)}')
        self.out, self.on_not_ok, self.interactive = Path(out), on_not_ok, interactive
        self.ask = ask or input
        self.stream = stream
        #: Every session's verdict of this run, by session (the last one of a repeated session).
        self.verdicts: dict[str, SessionVerdict] = {}

    def _say(self, text: str) -> None:
        print(text, file=self.stream or sys.stderr, flush=True)

    def __call__(self, plan: Any, result: Mapping[str, Any], repeatable: bool) -> str:
        """'continue', 'repeat' or 'stop' after session ``plan`` (a SessionPlan) with its ``result``."""
        verdict = session_verdict(self.out, plan.to_dict(), result)
        self._say('\n' + '\n'.join(verdict.lines()))
        decision = 'continue'
        if not verdict.ok:
            decision = self.on_not_ok
            if decision == 'ask':
                decision = self._ask(plan.id, repeatable) if self.interactive else 'continue'
        verdict.decision = {'continue': 'continued' if self.on_not_ok != 'ask' or self.interactive or verdict.ok
                            else 'continued (not asked: non-interactive run), marked NOT OK',
                            'repeat': 'repeated', 'stop': 'stopped'}[decision]
        write_verdict(self.out, verdict)
        self.verdicts[verdict.session] = verdict
        return decision

    def _ask(self, session: str, repeatable: bool) -> str:
        choices = ('r = repeat it (set it up again), ' if repeatable else '') + 'c = continue, s = stop the campaign'
        while True:
            try:
                answer = self.ask(f'session {session} is NOT OK: [{choices}] ').strip().lower()
            except EOFError:
                return 'continue'
            if answer in ('c', 'continue'):
                return 'continue'
            if answer in ('s', 'stop', 'q'):
                return 'stop'
            if repeatable and answer in ('r', 'repeat'):
                return 'repeat'


__all__ = ['NOT_OK_ACTIONS', 'Review', 'SessionVerdict', 'VERDICT_FILE', 'not_ok_summary', 'read_verdict',
           'session_verdict', 'write_verdict']
