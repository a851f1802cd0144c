"""`campaign run` on the simulated rig shows each session's verdict as soon as it has run (analysed by campaign
analyze's analysis, which then finds it current), keeps it in verdict.json and exits 0 when every session is OK."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.ros  # the rig's nodes

CLI = Path(sys.prefix) / 'bin' / 'crane-stiffness'


def test_each_sessions_verdict_is_shown_after_it_and_analyze_reuses_the_analysis(tmp_path):
    spec = tmp_path / 'small.yaml'
    spec.write_text('campaign:\n  ros__parameters:\n    name: small\n    series: [fy]\n'
                    '    programs: [campaign_side_force]\n    weights: [40.0, 80.0]\n    lengths: [0.5]\n')
    out = tmp_path / 'campaign'
    run = subprocess.run([str(CLI), 'campaign', 'run', str(spec), '--out', str(out), '--quiet', '--jobs', '1'],
                         capture_output=True, text=True, timeout=900)
    assert run.returncode == 0, run.stderr[-3000:]
    assert '2 session(s) run, 0 done before, 2 planned' in run.stdout
    first, second = 'fy_W40_l0.5_r1', 'fy_W80_l0.5_r1'
    # The first session's verdict is shown before the second session's rig starts (its node logs say so).
    assert f'session {first}: OK' in run.stderr and f'session {second}: OK' in run.stderr
    assert run.stderr.index(f'session {first}: OK') < run.stderr.index(f'session {second}: OK')
    verdicts = {s: json.loads((out / 'sessions' / s / 'verdict.json').read_text()) for s in (first, second)}
    first_judged = (out / 'sessions' / first / 'verdict.json').stat().st_mtime
    second_started = min(p.stat().st_mtime for p in (out / 'bags' / second).rglob('*') if p.is_file())
    assert first_judged <= second_started
    for name, v in verdicts.items():
        assert v['status'] == 'OK' and v['reasons'] == [] and v['cut_short'] == '' and v['decision'] == 'continued'
        assert abs(v['relative_error']) < 0.02 and 0 < v['U'] < 0.1 * v['k'] and abs(v['en']) <= 1, v
        line = f'  k = {v["k"]:.6g} N/m, U = {v["U"]:.4g} N/m (95 %), model {v["model"]:.6g} N/m'
        assert line in run.stderr
    analyze = subprocess.run([str(CLI), 'campaign', 'analyze', str(out), '--quiet'], capture_output=True, text=True,
                             timeout=900)
    assert analyze.returncode == 0, analyze.stderr[-3000:]
    assert '2 session(s) (0 analysed now, 2 unchanged)' in analyze.stdout
