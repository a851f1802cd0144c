"""Live pairing benchmark: the estimator's ApproximateTimeSync on two 5 kHz streams, against real time and against a
bare Python loop over the same messages, measured in one run.

The live estimator pairs every sample as it arrives; it must keep far ahead of the sensors. 10 s of two 5 kHz streams
with stamp jitter (100,000 messages) go through ``ApproximateTimeSync.push`` one by one, as the node feeds it; the
baseline is the same loop doing nothing but appending each message (the floor of handling a message in Python).
Target: the pairing runs ≥ 10× faster than real time. The ratio to the baseline is the figure to read across
machines.

Run: .venv/bin/python benchmarks/bench_sync.py [--seconds 10] [--json out.json]
"""
from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np

from crane_stiffness.estimation.sync import ApproximateTimeSync

RATE_HZ = 5000.0
TARGET_REAL_TIME = 10.0


def events(seconds: float, seed: int = 3) -> list[tuple[str, float, float]]:
    """Both streams' (stream, stamp, value), sorted by stamp (arrival), jitter ±5 % of the period."""
    n = int(seconds * RATE_HZ)
    period = 1.0 / RATE_HZ
    rng = np.random.default_rng(seed)
    base = np.arange(n) * period
    out = [('force', float(t), float(i)) for i, t in enumerate(base + rng.uniform(-0.05, 0.05, n) * period)]
    out += [('displacement', float(t), float(i)) for i, t in enumerate(base + rng.uniform(-0.05, 0.05, n) * period)]
    return sorted(out, key=lambda e: e[1])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--seconds', type=float, default=10.0, help='seconds of data per stream [s]')
    ap.add_argument('--json', help='write the figures to this file')
    args = ap.parse_args(argv)
    data = events(args.seconds)

    start = time.perf_counter()
    seen: list = []
    for stream, stamp, value in data:
        seen.append((stream, stamp, value))
    baseline_s = time.perf_counter() - start

    sync = ApproximateTimeSync(slop=0.4 / RATE_HZ, expected_period=1.0 / RATE_HZ)
    start = time.perf_counter()
    pairs = []
    for stream, stamp, value in data:
        pairs.extend(sync.push(stream, stamp, value))
    pairs.extend(sync.flush())
    pairing_s = time.perf_counter() - start

    n = len(data) // 2
    if len(pairs) != n or any(p.force != p.displacement for p in pairs):
        print(f'FAIL: {len(pairs)} pairs of {n} samples, or a sample paired with another than its partner')
        return 1
    real_time = args.seconds / pairing_s
    figures = {'messages': len(data), 'pairing_s': pairing_s, 'baseline_loop_s': baseline_s,
               'per_message_us': pairing_s / len(data) * 1e6, 'times_real_time': real_time,
               'ratio_to_bare_loop': pairing_s / baseline_s, 'target_times_real_time': TARGET_REAL_TIME}
    print(f'pairing {len(data):,} messages ({args.seconds:g} s of two {RATE_HZ:g} Hz streams): {pairing_s:.3f} s, '
          f'{figures["per_message_us"]:.2f} µs/message, {real_time:.1f}x real time (target >= '
          f'{TARGET_REAL_TIME:g}x); the bare loop over the same messages {baseline_s:.3f} s '
          f'(pairing = {figures["ratio_to_bare_loop"]:.1f}x the bare loop)')
    if args.json:
        with open(args.json, 'w') as fh:
            json.dump(figures, fh, indent=2)
    if real_time < TARGET_REAL_TIME:
        print(f'target missed: {real_time:.1f}x real time < {TARGET_REAL_TIME:g}x')
        return 1
    return 0


if __name__ == '__main__':
    sys.exit(main())
