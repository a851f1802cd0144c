"""The live view over the Foxglove WebSocket protocol, on the running simulated rig: the channels and schemas it
advertises, subscribing, decoding, and the values checked against what the rig published (the plot's points are
the estimator's fitted pairs, the scene's wire tensions are /crane/wire_states), and a service call through the
bridge that tares the load cell: refused to a client without the token (the rig untouched), done for one with it."""
from __future__ import annotations

import json
import math
import re
import time
from typing import Any, Callable

import pytest
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger

from crane_stiffness.contract import topics
from crane_stiffness.nodes.live_view import DEFAULT_SERVICES, DEFAULT_TOPICS, _TYPES
from crane_stiffness.launcher.rosrun import installed_config
from crane_stiffness.contract.status import ERROR, NAMES, STALE, WAITING_PREFIX, overall, read_level
from helpers.foxglove_client import PATIENCE_S, FoxgloveClient
from helpers.live_rig import live_rig, wait_for_pairs, watched
from helpers.processes import UNCLEAN, final_counters

DERIVED = ('xy', 'fit_lines', 'prediction', 'estimate', 'status', 'wires', 'scene')


def test_protocol_channels_values_and_tare(install_tree, rclpy_context, tmp_path):
    install, env = install_tree
    with live_rig(env, installed_config(install), tmp_path, rclpy_context) as (procs, watcher, ports):
        client = FoxgloveClient(ports['port'], token=ports['token'])
        try:
            # The rig's topics as foxglove_bridge offers them: ROS 2 schemas, CDR messages.
            for topic in DEFAULT_TOPICS:
                ch = client.channels[topic]
                assert (ch['encoding'], ch['schemaEncoding'], ch['schemaName']) == ('cdr', 'ros2msg', _TYPES[topic])
            wrench = client.channels[topics.LOAD_CELL_WRENCH]['schema']
            assert '\nstd_msgs/Header header\nWrench wrench\n' in wrench  # the .msg text, then what it uses
            assert 'MSG: geometry_msgs/Wrench\n' in wrench and 'MSG: builtin_interfaces/Time\n' in wrench
            for name in DERIVED:
                assert client.channels[f'/live_view/{name}']['encoding'] == 'json'
            assert client.channels['/live_view/scene']['schemaName'] == 'foxglove.SceneUpdate'
            assert set(DEFAULT_SERVICES) <= set(client.services)
            assert client.services['/load_cell/tare']['type'] == 'std_srvs/srv/Trigger'

            client.subscribe(*(f'/live_view/{name}' for name in DERIVED), topics.WIRE_STATES)
            wait_for_pairs(procs, watcher, 3000)
            # the program runs: loading, points growing, until the client has what the checks look at
            assert client.poll_until(_Enough(client, watcher)), {t: len(m) for t, m in client.messages.items()}
            procs.check_alive(allow_exit=('load_program',))
            _check_plot(client, watcher)
            _check_crane(client, watcher)
            _check_estimate(client, watcher)

            # without the token (a page of the page's own origin, opened without ?token=): it may watch, not tare
            epochs_before = list(watcher.tare_epochs)
            page_origin = f'http://127.0.0.1:{ports["http_port"]}'
            watcher_only = FoxgloveClient(ports['port'], origin=page_origin)
            try:
                assert '/load_cell/tare' in watcher_only.services
                watcher_only.call_raw(watcher_only.services['/load_cell/tare']['id'], 'cdr',
                                      serialize_message(Trigger.Request()), 5)
                assert watcher_only.poll_until(lambda: 5 in watcher_only.failures and watcher_only.statuses)
            finally:
                watcher_only.close()
            assert 'no token' in watcher_only.failures[5], watcher_only.failures
            assert 'no token' in watcher_only.statuses[-1]['message'] and watcher_only.statuses[-1]['level'] == 2
            _wait_for(lambda: 'service call /load_cell/tare from 127.0.0.1:' in procs.log('live_view'))
            refusal = [line for line in procs.log('live_view').splitlines()
                       if 'service call /load_cell/tare from 127.0.0.1:' in line]
            assert refusal and f'(Origin {page_origin}) refused: no token' in refusal[0], refusal

            # tare through the bridge with the token (CDR, as Foxglove's service call panel sends for ros2msg
            # services): the first tare of the run, the refused call did none
            encoding, payload = client.call('/load_cell/tare', 'cdr', serialize_message(Trigger.Request()), 1)
            response = deserialize_message(payload, Trigger.Response)
            assert encoding == 'cdr' and response.success, response.message
            expected = (epochs_before or [0.0])[-1] + 1
            _wait_for(lambda: watcher.tare_epochs and watcher.tare_epochs[-1] == expected and
                      'service /load_cell/tare called through the WebSocket' in procs.log('live_view'))
            assert watcher.tare_epochs and watcher.tare_epochs[-1] == (epochs_before or [0.0])[-1] + 1, \
                (epochs_before, watcher.tare_epochs)
            # the view names the client it called for, and so does the load cell (the view's control event)
            assert re.search(r'service /load_cell/tare called through the WebSocket by 127\.0\.0\.1:\d+ '
                             r'\(Origin none\): success=True', procs.log('live_view'))
            _wait_for(lambda: re.search(r"~/tare by the live view's WebSocket client 127\.0\.0\.1:\d+ \(Origin "
                                        r'none\) \(through /live_view\): tared on', procs.log('load_cell')))
        finally:
            client.close()
        codes = procs.stop()
    assert codes['live_view'] == 0
    log = procs.log('live_view')
    assert not any(sign in log for sign in UNCLEAN), log[-3000:]
    counters = final_counters(log, 'live_view')
    assert counters['derived_sent'] > 0 and counters['forwarded'] > 0 and counters['service_calls'] == 1
    assert counters['service_calls_refused'] == 1 and counters['connections_refused'] == 0


class _Enough:
    """Whether the client holds what the checks below look at: 10 plots, the newest with more than 120 points stamped
    after the watcher's first pair (so more than 100 it can check), a message of every derived channel, a scene with
    the applied force drawn, and the raw wire states (each scene read once: they pile up while the test waits)."""

    def __init__(self, client: FoxgloveClient, watcher) -> None:
        self.client, self.watcher, self.scenes_read, self.force_drawn = client, watcher, 0, False

    def __call__(self) -> bool:
        messages = self.client.messages
        scenes = messages.get('/live_view/scene', [])
        while not self.force_drawn and self.scenes_read < len(scenes):
            self.force_drawn = bool(json.loads(scenes[self.scenes_read])['entities'][0]['arrows'])
            self.scenes_read += 1
        xy = messages.get('/live_view/xy', [])
        if not self.force_drawn or len(xy) < 10:
            return False
        last = json.loads(xy[-1])
        shown = watched(self.watcher, (p['t'] for branch in ('loading', 'unloading') for p in last[branch]))
        return (len(shown) > 120 and bool(messages.get(topics.WIRE_STATES))
                and all(messages.get(f'/live_view/{name}') for name in DERIVED))


def _wait_for(condition: Callable[[], Any], timeout_s: float = PATIENCE_S) -> None:
    """Until ``condition()`` holds or ``timeout_s`` passed (the caller then asserts what it needs): the watcher's
    subscriptions fill its records on another thread, and may be a moment behind the view."""
    deadline = time.monotonic() + timeout_s
    while not condition() and time.monotonic() < deadline:
        time.sleep(0.05)


def _check_plot(client: FoxgloveClient, watcher) -> None:
    xy = client.json_messages('/live_view/xy')
    assert len(xy) >= 10, len(xy)
    last = xy[-1]
    points = [(b, p) for b, branch in enumerate(('loading', 'unloading')) for p in last[branch]]
    assert len(points) <= 500  # max_points: decimated for display
    assert last['stride'] >= 1 and last['pairs'] >= len(points)
    # The pairs shown that the watcher was matched for (it may have matched the estimator after the segment began):
    # its subscription fills its dict from another thread, and may be a moment behind the view, so wait until it
    # holds every one of them, then read one copy (atomic under the GIL).
    shown_stamps = watched(watcher, (p['t'] for _, p in points))
    _wait_for(lambda: shown_stamps <= watcher.pairs.keys())
    fitted_pairs = dict(watcher.pairs)
    missing = shown_stamps - fitted_pairs.keys()
    assert len(missing) <= 0.02 * len(shown_stamps), f'{len(missing)} of {len(shown_stamps)} shown pairs never seen'
    points = [(b, p) for b, p in points if p['t'] in shown_stamps and p['t'] in fitted_pairs]
    assert len(points) > 100, (last['pairs'], len(shown_stamps))
    for branch, p in points:  # every point shown is a pair the estimator fitted, exactly
        x, force, fitted_branch, segment = fitted_pairs[p['t']]
        assert (p['x'], p['y'], branch, segment) == (x, force, fitted_branch, last['segment'])
    # the points of one segment decimated by one stride: one pair in every `stride` of those fitted, so consecutive
    # points shown lie `stride` pairs apart (counted from wherever view and watcher began: the same offset for all)
    fitted = sorted(t for t, v in fitted_pairs.items() if v[3] == last['segment'])
    shown = {p['t'] for _, p in points}
    index = [i for i, t in enumerate(fitted) if t in shown]
    if not missing:  # (a pair the watcher lost would shift the count)
        assert all(b - a == last['stride'] for a, b in zip(index, index[1:])), last['stride']
    # the fit line and its band per branch, the prediction line, and each point carries them at its x
    # (the newest message with a loading fit: one published as a new fit segment began has none yet)
    with_fit = [m for m in client.json_messages('/live_view/fit_lines') if m['loading']['line']]
    assert with_fit, 'no fit_lines message with a loading fit'
    load = with_fit[-1]['loading']
    assert len(load['line']) == 21 and all(lo['y'] < mid['y'] < hi['y'] for lo, mid, hi in
                                            zip(load['lower'], load['line'], load['upper']))
    k = load['stiffness']
    assert load['line'][-1]['y'] - load['line'][0]['y'] == pytest.approx(
        k * (load['line'][-1]['x'] - load['line'][0]['x']), rel=1e-9)
    pred = client.json_messages('/live_view/prediction')[-1]
    assert pred['stiffness'] > 0 and len(pred['line']) == 2
    assert math.isfinite(last['loading'][-1]['fit']) and math.isfinite(last['loading'][-1]['prediction'])


def _check_crane(client: FoxgloveClient, watcher) -> None:
    # the scenes of wire states stamped from the watcher's first on (it may have matched the model after the view
    # did); a scene's stamp is the wire states' (to within the float's rounding, far below their period)
    first = watcher.first_wires_ns
    assert first is not None
    scenes = [s for s in client.json_messages('/live_view/scene')
              if s['entities'][0]['timestamp']['sec'] * 1_000_000_000 + s['entities'][0]['timestamp']['nsec']
              >= first - 1000]
    assert scenes
    metas = [{kv['key']: kv['value'] for kv in s['entities'][0]['metadata']} for s in scenes]
    shown = {tuple(float(meta[f'tension.wire_{i}']) for i in range(1, 7)) for meta in metas}
    raw = client.messages[topics.WIRE_STATES]  # the ROS channel: CDR as published
    published = {tuple(deserialize_message(payload, JointState).effort) for payload in raw[-20:]}
    _wait_for(lambda: (shown | published) <= watcher.tensions)
    for scene in scenes:  # each scene's tensions are one /crane/wire_states message's, exactly
        entity = scene['entities'][0]
        meta = {kv['key']: kv['value'] for kv in entity['metadata']}
        tensions = tuple(float(meta[f'tension.wire_{i}']) for i in range(1, 7))
        assert tensions in watcher.tensions, tensions
        assert entity['frame_id'] == 'crane_view' and float(meta['deflection_scale']) == 200.0
        assert len(entity['lines']) == 7 and len(entity['triangles']) == 1  # overhead triangle + 6 wires
    assert any(s['entities'][0]['arrows'] for s in scenes)  # a force applied during the program
    wires = client.json_messages('/live_view/wires')[-1]['wires']
    assert [w['name'] for w in wires] == [f'wire_{i}' for i in range(1, 7)]
    assert raw
    for payload in raw[-20:]:
        assert tuple(deserialize_message(payload, JointState).effort) in watcher.tensions


def _check_estimate(client: FoxgloveClient, watcher) -> None:
    estimates = client.json_messages('/live_view/estimate')
    assert estimates
    stamps = {e['loading']['sample_stamp'] for e in estimates[-20:] if e['loading']['stiffness'] is not None}
    _wait_for(lambda: stamps <= watcher.values.keys())
    for est in estimates[-20:]:
        loading = est['loading']
        if loading['stiffness'] is not None:
            assert watcher.values[loading['sample_stamp']] == loading['stiffness']
    # The page's badge and the layout's indicator: the estimator's statuses as published, a part that has not begun
    # read back as WAITING (published OK, 'waiting: ...'), the overall the worst of them; STALE only for a branch
    # whose inputs stopped (input ERROR), never for one that waits (the unloading branch during the loading ramp).
    channel = client.json_messages('/live_view/status')
    shown = {(s['level'], s['message']) for s in channel[-1]['statuses']}
    _wait_for(lambda: any({(read_level(lvl, msg), msg) for lvl, msg in s.values()} == shown
                          for s in list(watcher.status_history)))
    history = [{(read_level(lvl, msg), msg) for lvl, msg in s.values()} for s in watcher.status_history]
    assert shown in history
    for status in channel:
        parts = {s['name'].rpartition(': ')[2]: s for s in status['statuses']}
        assert status['level'] == overall(s['level'] for s in status['statuses'])
        assert status['level_name'] == NAMES[status['level']]
        if parts['input']['level'] != ERROR:
            assert all(s['level'] != STALE for s in status['statuses']), status['text']
        if parts['unloading']['message'].startswith(WAITING_PREFIX):
            assert parts['unloading']['level_name'] == 'WAITING' and status['level'] != STALE, status['text']
