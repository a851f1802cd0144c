"""Statuses that mean one thing each (crane_stiffness.contract.status): a part that has not begun is WAITING (published
as OK
with a message starting 'waiting: '), never STALE, and never makes the overall status worse than the parts that
are running; STALE only when data that was flowing stopped. The estimator's statuses, their form on
/stiffness/estimate, the live view's status channel (the page's badge, the layout's indicator) and the demo's
verdict agree. Pure: no ROS, simulated clocks (nothing here depends on the machine's speed)."""
from __future__ import annotations

import importlib.util
import json
import re
from pathlib import Path

import numpy as np

from crane_stiffness.estimation.live import LiveStiffness
from crane_stiffness.estimation.settings import LiveSettings
from crane_stiffness.contract.status import (ERROR, NAMES, OK, STALE, WAITING, WAITING_PREFIX, WARN, overall,
                                             read_level, wire_level)
from crane_stiffness.view import plot

REPO = Path(__file__).resolve().parents[2]
K = 2000.0      # N/m
PERIOD = 0.001  # s: 1 kHz streams
T0 = 1000.0     # s, a plausible header stamp (the node clock runs with it: arrival = stamp)


def _loading_ramp(live: LiveStiffness, n: int = 2000, peak: float = 4.0) -> float:
    """The first loading ramp of a program (command and load rising to ``peak``, no unloading yet); returns the
    arrival of the newest sample, s (node clock)."""
    rng = np.random.default_rng(7)
    command = np.linspace(0.0, peak, n)
    force = command + rng.normal(0.0, 0.01, n)
    x = command / K + rng.normal(0.0, 2e-7, n)
    t = T0
    for i in range(n):
        t = T0 + i * PERIOD
        live.add_command(t, (0.0, float(command[i]), 0.0, 0.0, 0.0, 0.0), t)
        live.add_force(t, (0.0, float(force[i]), 0.0, 0.0, 0.0, 0.0), arrival_s=t)
        live.add_displacement(t, float(x[i]), arrival_s=t)
    return t


def _statuses(live: LiveStiffness, now_s: float) -> list[tuple[str, int, str]]:
    """What the node publishes on /stiffness/estimate at ``now_s``: (name, diagnostic_msgs level, message) per
    branch, then the input status (stiffness_estimator._publish_estimate)."""
    live.values()
    live.refresh()
    out = [(str(r.branch), wire_level(r.level), r.message) for r in live.report(now_s)]
    level, message, _ = live.input_report('estimate', now_s)
    return out + [('input', wire_level(level), message)]


def _silence_limit(live: LiveStiffness) -> float:
    """The stated time: a stream silent longer than ``dropout_factor`` delivery periods and ``min_silence_s`` is
    dead (docs/faults.md)."""
    s = live._settings
    return max(max(h.silence_limit(s.dropout_factor), s.min_silence_s) for h in live.health.values())


def test_during_the_first_loading_ramp_loading_is_ok_unloading_waiting_and_the_badge_ok() -> None:
    live = LiveStiffness(LiveSettings(window=1000))
    # Before the first sample nothing has begun: every part waits, the badge says so (neither OK nor STALE).
    before = _statuses(live, T0)
    assert [read_level(lvl, msg) for _, lvl, msg in before] == [WAITING] * 3, before
    assert all(lvl == OK and msg.startswith(WAITING_PREFIX) for _, lvl, msg in before)  # diagnostic_msgs: 0..3
    assert 'no usable force or displacement sample yet' in before[2][2]
    assert plot.status_message(before)['level_name'] == 'WAITING'

    newest = _loading_ramp(live)
    statuses = _statuses(live, newest + 0.01)
    (_, loading, loading_msg), (_, unloading, unloading_msg), (_, inputs, input_msg) = statuses
    assert (loading, inputs) == (OK, OK) and 'N/m' in loading_msg, statuses
    assert not input_msg.startswith(WAITING_PREFIX), input_msg
    # the unloading branch has not begun: published as OK with a message that says it waits, read back as WAITING
    assert unloading == OK and unloading_msg.startswith(WAITING_PREFIX + 'no estimate yet'), unloading_msg
    assert read_level(unloading, unloading_msg) == WAITING
    # the page's badge and the layout's indicator (/live_view/status): OK, the branch's line WAITING
    channel = plot.status_message(statuses)
    assert (channel['level'], channel['level_name']) == (OK, 'OK'), channel
    assert [(s['name'], s['level_name']) for s in channel['statuses']] == [
        ('loading', 'OK'), ('unloading', 'WAITING'), ('input', 'OK')]
    assert 'unloading: WAITING waiting: no estimate yet' in channel['text']
    # the demo signs it (its summary's statuses are the observer's read_level names)
    summary = {'status': {name: {'level': NAMES[read_level(lvl, msg)], 'message': msg} for name, lvl, msg in statuses},
               'relative_error': 0.001}
    assert _demo().verdict(summary, 0.02) == '', summary


def test_a_stopped_sensor_turns_every_branch_stale_within_the_stated_time() -> None:
    live = LiveStiffness(LiveSettings(window=1000))
    newest = _loading_ramp(live)
    limit = _silence_limit(live)
    assert 0.25 <= limit < 1.0, limit  # min_silence_s: 1 kHz streams, 3 periods are 3 ms
    # A pause shorter than the stated time is not a dead sensor.
    assert all(lvl != STALE for _, lvl, _ in _statuses(live, newest + 0.5 * limit))
    # Both sensors stopped (the rig's streams end together); past the stated time: every branch STALE, input ERROR.
    statuses = _statuses(live, newest + limit + 0.01)
    assert [lvl for _, lvl, _ in statuses] == [STALE, STALE, ERROR], statuses
    assert 'estimate frozen' in statuses[0][2] and 'silent' in statuses[0][2]
    # the branch that had not begun is STALE too (its inputs are dead: nothing to wait for), saying it had nothing
    assert 'nothing to estimate from' in statuses[1][2] and not statuses[1][2].startswith(WAITING_PREFIX)
    channel = plot.status_message(statuses)
    assert (channel['level'], channel['level_name']) == (STALE, 'STALE'), channel
    assert _demo().verdict({'status': {n: {'level': NAMES[lvl], 'message': m} for n, lvl, m in statuses},
                            'relative_error': 0.001}, 0.02) != ''


def test_one_sensor_stopping_is_stale_and_one_never_started_waits() -> None:
    """The displacement sensor stops while the load cell goes on: STALE after the stated time. A sensor that never
    delivered is not stale (nothing stopped): the inputs wait for it, never OK."""
    live = LiveStiffness(LiveSettings(window=1000))
    newest = _loading_ramp(live)
    limit = _silence_limit(live)
    t = newest
    while t < newest + limit + 0.01:
        t += PERIOD
        live.add_force(t, (0.0, 4.0, 0.0, 0.0, 0.0, 0.0), arrival_s=t)
    statuses = _statuses(live, t)
    assert [lvl for _, lvl, _ in statuses] == [STALE, STALE, ERROR], statuses
    assert 'displacement silent' in statuses[2][2]
    assert plot.status_message(statuses)['level_name'] == 'STALE'

    only_force = LiveStiffness(LiveSettings(window=1000))
    for i in range(1000):
        only_force.add_force(T0 + i * PERIOD, (0.0, 1e-3 * i, 0.0, 0.0, 0.0, 0.0), arrival_s=T0 + i * PERIOD)
    statuses = _statuses(only_force, T0 + 1.0)
    assert [read_level(lvl, msg) for _, lvl, msg in statuses] == [WAITING] * 3, statuses
    assert 'no usable displacement sample yet' in statuses[2][2]
    assert plot.status_message(statuses)['level_name'] == 'WAITING'


def test_the_overall_level_is_the_worst_of_the_parts_a_waiting_one_never_worse() -> None:
    assert overall([]) == WAITING and overall([WAITING, WAITING]) == WAITING
    assert overall([OK, WAITING, OK]) == OK and overall([WARN, WAITING, OK]) == WARN
    assert overall([STALE, WAITING, ERROR]) == STALE and overall([OK, STALE, OK]) == STALE
    assert [wire_level(lvl) for lvl in NAMES] == [OK, OK, WARN, ERROR, STALE]
    assert read_level(OK, 'waiting: x') == WAITING and read_level(WARN, 'waiting: x') == WARN
    assert read_level(OK, 'k = 5 N/m; waiting: x') == OK


def test_the_page_and_the_layout_show_every_level_by_its_name() -> None:
    """The page's badge takes its class (level-<n>, a colour each) and its text (level_name) from the status channel;
    the layout's indicator has a rule per level, labelled with its name."""
    css = (REPO / 'crane_stiffness' / 'view' / 'web' / 'style.css').read_text()
    assert {int(n) for n in re.findall(r'\.level-(-?\d+) \{', css)} == set(NAMES)
    app = (REPO / 'crane_stiffness' / 'view' / 'web' / 'app.js').read_text()
    assert 'el.className = `level-${st.level}`' in app and 'el.textContent = st.level_name' in app
    layout = json.loads((REPO / 'foxglove' / 'stiffness_test.json').read_text())
    indicator = layout['configById']['Indicator!level']
    assert indicator['path'] == '/live_view/status.level'
    assert {int(r['rawValue']): r['label'] for r in indicator['rules']} == NAMES


def _demo():
    """scripts/demo.py as a module (its verdict on the summary)."""
    spec = importlib.util.spec_from_file_location('crane_stiffness_demo', REPO / 'scripts' / 'demo.py')
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module

