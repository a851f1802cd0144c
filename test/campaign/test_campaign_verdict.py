"""Each session's verdict at once (campaign/verdict.py): analysed by campaign analyze's own analysis, k with its U and
E_n against the model, NOT OK for the analysis' reasons, the estimator's status or a bag cut short; what happens
after a NOT OK one (repeat / continue / stop; continue and mark when nobody can be asked), kept in verdict.json; and
`campaign run` exiting 5 naming the NOT OK sessions, those done before included. A synthetic session (no ROS; its
bag has no live estimator topics, which the analysis names as problems: NOT OK as campaign analyze has it; an OK
session run on the simulated rig is test_campaign_run's)."""
from __future__ import annotations

import io
import json
import math
import subprocess
import sys
from pathlib import Path

import pytest

from crane_stiffness.campaign.analyze import analyze_campaign
from crane_stiffness.campaign.spec import load_campaign
from crane_stiffness.campaign.verdict import Review, read_verdict, session_verdict
from crane_stiffness.cli.exit_codes import EXIT_SESSION_NOT_OK
from crane_stiffness.testing.synthetic_campaign import write_synthetic_campaign

CLI = Path(sys.prefix) / 'bin' / 'crane-stiffness'
CUT = 'the recording ended before the program did (write error): the bag is not the whole run'


@pytest.fixture(scope='module')
def campaign(tmp_path_factory):
    """A campaign of one synthetic session, analysed once by its first verdict (the module's tests share it)."""
    tmp = tmp_path_factory.mktemp('verdict')
    path = tmp / 'one.yaml'
    path.write_text('campaign:\n  ros__parameters:\n    name: one\n    series: [fy]\n'
                    '    programs: [campaign_side_force]\n    weights: [40.0]\n    lengths: [0.5]\n')
    out = tmp / 'out'
    plans = write_synthetic_campaign(out, load_campaign(path), seed=5, sample_rate_hz=200)
    return path, out, Plan(plans[0].to_dict()), result_of(out, plans[0].id)


def result_of(out: Path, session: str) -> dict:
    return json.loads((out / 'sessions' / session / 'result.json').read_text())


def set_result(out: Path, result: dict) -> None:
    (out / 'sessions' / result['session'] / 'result.json').write_text(json.dumps(result))


class Plan:
    """What the review reads of a SessionPlan."""

    def __init__(self, data: dict) -> None:
        self.data, self.id = data, data['id']

    def to_dict(self) -> dict:
        return self.data


def test_the_verdict_is_campaign_analyzes_row_with_u_and_en_and_analyze_reuses_its_analysis(campaign):
    _, out, plan, result = campaign
    verdict = session_verdict(out, plan.data, result)
    assert verdict.unit == 'N/m' and abs(verdict.relative_error) < 0.01 and verdict.cut_short == ''
    assert verdict.k == pytest.approx(verdict.model, rel=0.01)
    assert 0 < verdict.U < 0.1 * verdict.k and math.isfinite(verdict.en) and abs(verdict.en) <= 1
    lines = verdict.lines()
    assert lines[0] == f'session {plan.id}: {verdict.status}' and f'E_n = {verdict.en:+.2f}' in lines[1]
    assert lines[2:] == [f'  problem: {r}' for r in verdict.reasons]
    # The same analysis as campaign analyze's, in its place: analyze finds it current and has the same row.
    assert (out / 'analysis' / plan.id / 'analysis.json').is_file()
    analysed = analyze_campaign(out, workers=1, formats=('png',), reports=('md',))
    assert analysed.analysed == []
    row = analysed.rows[0]
    assert (row.status, row.reasons, row.k) == (verdict.status, verdict.reasons, verdict.k)
    # (the synthetic bag has no live estimate: a problem the analysis names)
    assert verdict.status == 'NOT OK' and any('not in the bag' in r for r in verdict.reasons)


def test_the_estimators_status_and_a_bag_cut_short_are_named(campaign):
    _, out, plan, result = campaign
    before = session_verdict(out, plan.data, result).reasons
    warn = {**result, 'status': {'loading': {'level': 'WARN', 'message': 'fit not trusted'}}}
    assert session_verdict(out, plan.data, warn).reasons == before + [
        "the estimator's last loading status was WARN: fit not trusted"]
    cut = {**result, 'recording': {'stop_reason': 'write error', 'problem': CUT}}
    verdict = session_verdict(out, plan.data, cut)
    assert verdict.status == 'NOT OK' and verdict.cut_short == CUT
    assert verdict.reasons == before + [f'the bag is cut short: {CUT}']
    assert verdict.lines()[-1] == f'  problem: the bag is cut short: {CUT}'


def test_after_a_not_ok_session_repeat_continue_or_stop_kept_in_verdict_json(campaign):
    _, out, plan, result = campaign
    answers = iter(['maybe', 'r'])
    shown = io.StringIO()
    asked = Review(out, interactive=True, ask=lambda prompt: next(answers), stream=shown)
    assert asked(plan, result, True) == 'repeat'
    assert f'session {plan.id}: NOT OK' in shown.getvalue() and '  problem: ' in shown.getvalue()
    assert read_verdict(out, plan.id).decision == 'repeated'
    # Not repeatable now (sessions side by side): 'r' is not taken.
    prompts = []
    answers = iter(['r', 's'])

    def ask(prompt: str) -> str:
        prompts.append(prompt)
        return next(answers)
    assert Review(out, interactive=True, ask=ask, stream=shown)(plan, result, False) == 'stop'
    assert prompts[0] == f'session {plan.id} is NOT OK: [c = continue, s = stop the campaign] '
    assert read_verdict(out, plan.id).decision == 'stopped'
    # Nobody to ask: it goes on, the session marked; or the run says what to do.
    assert Review(out, interactive=False, stream=shown)(plan, result, True) == 'continue'
    kept = read_verdict(out, plan.id)
    assert kept.status == 'NOT OK' and kept.decision == 'continued (not asked: non-interactive run), marked NOT OK'
    assert Review(out, on_not_ok='stop', stream=shown)(plan, result, True) == 'stop'
    assert Review(out, on_not_ok='continue', stream=shown)(plan, result, True) == 'continue'
    assert read_verdict(out, plan.id).decision == 'continued'


def test_campaign_run_exits_5_naming_the_not_ok_sessions_done_before(campaign):
    path, out, plan, result = campaign
    run = [str(CLI), 'campaign', 'run', str(path), '--out', str(out), '--quiet']
    try:
        set_result(out, {**result, 'recording': {'problem': CUT}})
        Review(out, stream=io.StringIO())(plan, result_of(out, plan.id), True)  # its verdict as campaign run keeps it
        bad = subprocess.run(run, capture_output=True, text=True, timeout=300)
        assert bad.returncode == EXIT_SESSION_NOT_OK == 5, bad.stderr
        assert '0 session(s) run, 1 done before, 1 planned' in bad.stdout
        assert '1 of 1 session(s) NOT OK' in bad.stderr
        assert bad.stderr.rstrip().endswith(f'the bag is cut short: {CUT}')
        assert f'  {plan.id}: ' in bad.stderr
    finally:
        set_result(out, result)


def test_a_session_far_from_the_model_is_not_ok_unless_the_campaign_simulates_another_crane(tmp_path):
    """A crane half as stiff as modelled: where the campaign simulates it on purpose (true.* set) the disagreement is
    the campaign's finding, not a reason; where the rig is meant to be the modelled crane (hardware, or the nominal
    simulated one: the plan's true crane is its nominal) it makes the session NOT OK, naming the disagreement."""
    path = tmp_path / 'soft.yaml'
    path.write_text('campaign:\n  ros__parameters:\n    name: soft\n    series: [fy]\n'
                    '    programs: [campaign_side_force]\n    weights: [40.0]\n    lengths: [0.5]\n'
                    '    true.wire_stiffness_factor: 0.5\n')
    out = tmp_path / 'out'
    plan = write_synthetic_campaign(out, load_campaign(path), seed=7, sample_rate_hz=200)[0].to_dict()
    result = result_of(out, plan['id'])
    assert plan['true'] != plan['nominal']
    finding = session_verdict(out, plan, result)
    analysis = json.loads((out / 'analysis' / plan['id'] / 'analysis.json').read_text())
    far = analysis['model_disagreements']
    assert far and abs(finding.en) > 1.0, (finding.en, far)
    assert not set(far) & set(finding.reasons)
    meant = session_verdict(out, dict(plan, true=plan['nominal']), result)
    assert meant.status == 'NOT OK' and set(far) <= set(meant.reasons)
    assert meant.en == finding.en
