"""Bad input to the live view on the running rig: a client with the token sending garbage (not JSON, unknown
operations, unknown binary opcodes, a truncated service call, unknown channels), a call of an unknown service, 20
clients connecting and leaving (some without closing): the node keeps running and says so in its log, and the rig's
numbers are unchanged (the estimator fits
every pair it pairs, its statuses are OK, the estimate is within 2 % of the prediction, and the plot's points are
still the fitted pairs)."""
from __future__ import annotations

import json
import time

from crane_stiffness.launcher.rosrun import installed_config
from helpers.foxglove_client import PATIENCE_S, FoxgloveClient
from helpers.live_rig import live_rig, wait_for_pairs, watched
from helpers.processes import UNCLEAN, final_counters
from crane_stiffness.contract.status import OK


def test_garbage_unknown_service_and_many_clients(install_tree, rclpy_context, tmp_path):
    install, env = install_tree
    # On simulated time (at the wall clock's pace): a busy machine slows the rig instead of losing samples, so the
    # estimator's statuses below are OK at any load, and anything else would be the bad input's doing.
    with live_rig(env, installed_config(install), tmp_path, rclpy_context,
                  arguments={'use_sim_time': 'true', 'real_time_factor': '1.0'}) as (procs, watcher, ports):
        wait_for_pairs(procs, watcher, 1000)
        client = FoxgloveClient(ports['port'], token=ports['token'])
        try:
            client.subscribe('/live_view/xy', '/live_view/estimate')
            for text in ('not json at all', '{"op": "bogus"}', json.dumps({'op': 'subscribe', 'subscriptions': [
                    {'id': 99, 'channelId': 999999}]}), '{"op": "unsubscribe", "subscriptionIds": "x"}'):
                client.ws.send(text)
            for frame in (b'\x07garbage', b'\x02\x01', b''):
                client.ws.send(frame)
            client.call_raw(4242, 'cdr', b'\x00\x01\x00\x00\x00', 7)  # no such service
            # the server tells the client what was wrong: the failed call and statuses for the garbage
            client.poll_until(lambda: 7 in client.failures and len(client.statuses) >= 3)
            assert 7 in client.failures, client.statuses
            assert len(client.statuses) >= 3, client.statuses
            for i in range(20):
                other = FoxgloveClient(ports['port'])
                other.subscribe('/live_view/scene', '/load_cell/wrench')
                other.poll(0.1)
                if i % 2:
                    other.close()
                else:
                    other.ws.socket.close()  # gone without a closing handshake
            # the view still serves this client: new plots arrive after the others came and went
            seen = len(client.messages.get('/live_view/xy', []))
            assert client.poll_until(lambda: len(client.messages.get('/live_view/xy', [])) > seen), \
                'no plot for the first client after 20 others came and went'
            procs.check_alive(allow_exit=('load_program',))
            # and its points are still the fitted pairs: those stamped after the watcher's first (it may have matched
            # the estimator after the program began), and its thread may be a moment behind the view
            last = client.json_messages('/live_view/xy')[-1]
            points = {p['t']: (p['x'], p['y']) for branch in ('loading', 'unloading') for p in last[branch]}
            shown = watched(watcher, points)
            assert shown, (watcher.first_stamp, sorted(points)[-1])
            deadline = time.monotonic() + PATIENCE_S
            while not shown <= watcher.pairs.keys() and time.monotonic() < deadline:
                time.sleep(0.05)
            for t in shown:
                assert watcher.pairs[t][:2] == points[t]
        finally:
            client.close()
        # the program to its end, then the estimator's own numbers
        assert procs.procs['load_program'].wait(120) == 0
        # the estimator's newest statuses while the rig still runs: the nodes stop together, and an estimator that
        # outlives its sensors by a few periods (a loaded machine) rightly reports them silent
        statuses = dict(watcher.statuses)
        client_log = procs.log('live_view')
        codes = procs.stop()
    assert codes['live_view'] == 0 and codes['stiffness_estimator'] == 0
    assert client_log.count('Invalid message from') >= 3, client_log[-3000:]
    assert client_log.count('foxglove: Registered client') >= 21
    log = procs.log('live_view')
    assert not any(sign in log for sign in UNCLEAN), log[-3000:]
    assert final_counters(log, 'live_view')['derived_sent'] > 0
    assert statuses['input'][0] == OK, statuses['input']
    assert statuses['loading'][0] == OK, statuses['loading']
    estimator = final_counters(procs.log('stiffness_estimator'), 'stiffness_estimator')
    assert estimator['pairs_fitted'] == estimator['pairs'] > 10000, estimator
    assert estimator['force_dropped'] == estimator['displacement_dropped'] == 0, estimator
    assert abs(watcher.loading['relative_error']) < 0.02, watcher.loading
