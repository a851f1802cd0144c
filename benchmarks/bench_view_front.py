"""The WebSocket front's cost: a live view's servers in this process (the SDK's server behind the front, no ROS) send
``--rate`` messages a second of ``--size`` bytes on one channel (as a raw 1 kHz sensor topic a Foxglove client
watches) to one client, which reads them either from the front (the public port, every frame passing through it)
or straight from the SDK's private port (no front), alternating ``--pairs`` times in one run.

Reports per case the process's CPU (user + system, this process: the servers and the client) as a fraction of one
core, the messages received and their delivery latency (log time to receipt, p50 and p99). Target: the front adds
at most 10 % of one core per 1,000 messages a second, and at most 10 ms to the p99 latency (medians over the
pairs).
Exits 1 when a target is missed.

Run: .venv/bin/python benchmarks/bench_view_front.py [--seconds 20] [--rate 1000] [--size 200] [--pairs 2]
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import struct
import sys
import threading
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))

from websockets.sync.client import connect  # noqa: E402

from crane_stiffness.view.server import FoxgloveServer  # noqa: E402

TOPIC = '/load_cell/wrench'
ADDED_CPU_PER_KHZ = 0.10
ADDED_P99_LIMIT_S = 0.010


def _cpu() -> float:
    t = os.times()
    return t.user + t.system


def run_case(port: int, server: FoxgloveServer, seconds: float, rate: float, size: int) -> dict:
    """One client on ``port`` subscribed to the channel while the server sends for ``seconds``."""
    latencies: list[float] = []
    ws = connect(f'ws://127.0.0.1:{port}', subprotocols=['foxglove.sdk.v1'], max_size=None, open_timeout=60,
                 legacy=True)
    stop = threading.Event()

    def read() -> None:
        sub_id = 1
        while not stop.is_set():
            try:
                frame = ws.recv(timeout=0.2)
            except TimeoutError:
                continue
            except Exception:  # noqa: BLE001 (closed at the end)
                return
            if isinstance(frame, str):
                msg = json.loads(frame)
                if msg.get('op') == 'advertise':
                    channel = next(c for c in msg['channels'] if c['topic'] == TOPIC)
                    ws.send(json.dumps({'op': 'subscribe', 'subscriptions': [{'id': sub_id,
                                                                              'channelId': channel['id']}]}))
            elif frame[0] == 1:
                log_time = struct.unpack_from('<Q', frame, 5)[0]
                latencies.append(time.time() - log_time / 1e9)

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    channel = server.ros[TOPIC]
    while not channel.has_sinks():  # until the client subscribed
        time.sleep(0.01)
    payload = bytes(size)
    period = 1.0 / rate
    cpu0, start = _cpu(), time.monotonic()
    sent = 0
    while (now := time.monotonic()) - start < seconds:
        due = int((now - start) / period) + 1
        while sent < due:
            channel.log(payload, log_time=time.time_ns())
            sent += 1
        time.sleep(period / 2)
    elapsed = time.monotonic() - start
    cpu = (_cpu() - cpu0) / elapsed
    time.sleep(0.5)
    stop.set()
    reader.join(5)
    ws.close()
    lat = sorted(latencies)
    return {'cpu': cpu, 'sent': sent, 'received': len(lat),
            'p50_ms': 1e3 * lat[len(lat) // 2] if lat else None,
            'p99_ms': 1e3 * lat[int(0.99 * (len(lat) - 1))] if lat else None}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--seconds', type=float, default=20.0)
    ap.add_argument('--rate', type=float, default=1000.0)
    ap.add_argument('--size', type=int, default=200)
    ap.add_argument('--pairs', type=int, default=2)
    ap.add_argument('--json', help='write the figures here')
    args = ap.parse_args(argv)
    definition = 'std_msgs/Header header\nbyte[] data\n'
    server = FoxgloveServer('127.0.0.1', 0, {TOPIC: ('geometry_msgs/msg/WrenchStamped', definition)}, {}, {},
                            lambda *_: None, lambda *_: None, lambda *_: None)
    runs: dict[str, list[dict]] = {'direct': [], 'front': []}
    try:
        for i in range(args.pairs):
            for case, port in (('direct', server.server.port), ('front', server.port)):
                res = run_case(port, server, args.seconds, args.rate, args.size)
                runs[case].append(res)
                print(f'pair {i + 1} {case:6s}: CPU {100 * res["cpu"]:.1f} % of a core, {res["received"]} of '
                      f'{res["sent"]} received, latency p50 {res["p50_ms"]:.2f} ms p99 {res["p99_ms"]:.2f} ms',
                      flush=True)
    finally:
        server.stop()
    added = statistics.median(f['cpu'] - d['cpu'] for d, f in zip(runs['direct'], runs['front']))
    p99 = statistics.median(f['p99_ms'] - d['p99_ms'] for d, f in zip(runs['direct'], runs['front'])) / 1e3
    per_khz = added / (args.rate / 1000.0)
    ok = per_khz <= ADDED_CPU_PER_KHZ and p99 <= ADDED_P99_LIMIT_S
    print(f'the front adds {100 * added:.1f} % of a core at {args.rate:g} messages/s ({100 * per_khz:.1f} % per '
          f'1,000/s; target <= {100 * ADDED_CPU_PER_KHZ:.0f} %) and {1e3 * p99:.2f} ms to the p99 latency (target <= '
          f'{1e3 * ADDED_P99_LIMIT_S:.0f} ms): {"met" if ok else "MISSED"}; load average {os.getloadavg()[0]:.1f}')
    if args.json:
        Path(args.json).write_text(json.dumps({'runs': runs, 'added_cpu': added, 'added_p99_s': p99, 'met': ok},
                                              indent=1))
    return 0 if ok else 1


if __name__ == '__main__':
    raise SystemExit(main())
