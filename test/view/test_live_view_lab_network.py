"""The live view open to the lab network (``host:=0.0.0.0``), reached from another machine: two Linux network
namespaces joined by a veth pair (crane_stiffness.testing.lab_network, made and removed by the test), the live_view
node (as ``ros2 run`` starts it, from the install tree) in one, a client in the other (a Python process of its own in
that namespace). Off loopback every connection needs the token: without it the WebSocket handshake is refused (401);
with it the client connects and its service call goes through to ROS (here "not available": no node offers it); a
foreign Host is refused (403); the page is served to a request naming the view's address.

Where namespaces cannot be made (not root, no iproute2), the test FAILS with the reason: it is not skipped.
"""
from __future__ import annotations

import json
import subprocess
import sys
import time

import pytest

from crane_stiffness.testing.lab_network import LabNetwork, LabNetworkError, NamespacedProcesses
from helpers.live_rig import page_address

pytestmark = pytest.mark.ros  # starts a ROS node (conftest)

#: The other machine's client: handshakes by hand, a service call with the token; prints what it met as JSON.
CLIENT = r'''
import base64, json, os, socket, struct, sys, urllib.request
address, port, http_port, token = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]

def handshake(path, host):
    lines = [f'GET {path} HTTP/1.1', f'Host: {host}', 'Upgrade: websocket', 'Connection: Upgrade',
             f'Sec-WebSocket-Key: {base64.b64encode(os.urandom(16)).decode()}', 'Sec-WebSocket-Version: 13',
             'Sec-WebSocket-Protocol: foxglove.sdk.v1']
    sock = socket.create_connection((address, port), timeout=120)
    sock.sendall(('\r\n'.join(lines) + '\r\n\r\n').encode())
    reply = b''
    while b'\r\n\r\n' not in reply:
        reply += sock.recv(4096)
    return sock, int(reply.split(b' ', 2)[1])

out = {}
sock, out['no_token'] = handshake('/', f'{address}:{port}')
sock.close()
sock, out['foreign_host'] = handshake(f'/?token={token}', f'evil.example:{port}')
sock.close()
from websockets.sync.client import connect
with connect(f'ws://{address}:{port}/?token={token}', subprotocols=['foxglove.sdk.v1'], open_timeout=120) as ws:
    out['with_token'] = 101
    services = None
    while services is None:
        msg = ws.recv(timeout=120)
        if isinstance(msg, str) and json.loads(msg)['op'] == 'advertiseServices':
            services = {s['name']: s['id'] for s in json.loads(msg)['services']}
    ws.send(struct.pack('<BIII', 2, services['/session_recorder/stop'], 1, 4) + b'json{}')
    while 'call' not in out:
        msg = ws.recv(timeout=120)
        if isinstance(msg, str) and json.loads(msg)['op'] == 'serviceCallFailure':
            out['call'] = json.loads(msg)['message']
with urllib.request.urlopen(f'http://{address}:{http_port}/config.json', timeout=120) as reply:
    out['page'] = reply.status
print(json.dumps(out))
'''


def test_off_loopback_every_connection_needs_the_token(install_tree, tmp_path):
    install, env = install_tree
    net = LabNetwork(subnet='10.213.53.0')
    try:
        net.create()
    except LabNetworkError as exc:
        net.remove()
        pytest.fail(f'the lab network cannot be made here: {exc}')
    try:
        view_ns, client_ns = net.namespaces['analysis'], net.namespaces['daq']
        address = net.analysis_address
        with NamespacedProcesses(env, tmp_path / 'logs', {'live_view': view_ns}) as procs:
            # the default ports: the namespace is a machine of its own, nothing else listens there
            procs.start('live_view', 'crane_stiffness', 'live_view',
                        ['--ros-args', '-p', 'host:=0.0.0.0', '-p', f'token_file:={tmp_path / "token"}'])
            deadline = time.monotonic() + 120
            while 'live view: page http://' not in procs.log('live_view'):
                procs.check_alive()
                assert time.monotonic() < deadline, procs.log('live_view')
                time.sleep(0.1)
            token = page_address(procs.log('live_view'))['token']
            assert (tmp_path / 'token').read_text().strip() == token
            assert 'every connection needs the token' in procs.log('live_view')
            script = tmp_path / 'client.py'
            script.write_text(CLIENT)
            client = subprocess.run(['ip', 'netns', 'exec', client_ns, sys.executable, str(script), address, '8765',
                                     '8080', token], capture_output=True, text=True, timeout=600, env=env)
            assert client.returncode == 0, client.stderr[-3000:]
            met = json.loads(client.stdout.strip().splitlines()[-1])
            log = procs.log('live_view')
            codes = procs.stop()
    finally:
        net.remove()
    assert met['no_token'] == 401 and met['foreign_host'] == 403 and met['with_token'] == 101, met
    # past the token: the call reached ROS, where no recorder offers the service
    assert 'is not available' in met['call'] and 'no token' not in met['call'], met
    assert met['page'] == 200, met
    assert f'live view: WebSocket from {net.daq_address}:' in log and 'refused: the token is needed' in log, log
    assert codes['live_view'] == 0, log[-2000:]
