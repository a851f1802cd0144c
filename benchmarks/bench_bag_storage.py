"""Benchmark: bulk-decoding the same streams from each rosbag2 storage and compression, per message, against MCAP.

Generates the synthetic rig bag of bench_bag_decode (``--seconds`` at ``--rate``: /load_cell/wrench WrenchStamped and
/lvdt/displacement PointStamped) with this package's writer (MCAP, zstd chunks), copies it with the independent
``rosbags`` writer into sqlite3 (.db3), zstd-compressed files (.mcap.zstd, .db3.zstd) and zstd-compressed messages
(sqlite3 and MCAP), then times ``BagReader(bag).decode_topics`` of both topics (open + decode, numpy arrays; for a
file-compressed bag including decompressing the file) on each, ``--repeats`` times in turn, best time of each.

Target: every storage at most ``TARGET_RATIO`` (2) times the time per message of the original MCAP bag, measured in
the same run. Exits 1 when missed. Usage::

    python benchmarks/bench_bag_storage.py [--seconds 300] [--rate 1000] [--repeats 3] [--keep]
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / 'test'))  # helpers.rosbag2_copy: the rosbags copy the tests use
from crane_stiffness.testing.scratch import keep_or_remove  # noqa: E402

from bench_bag_decode import LVDT_TOPIC, WRENCH_TOPIC, generate  # noqa: E402
from crane_stiffness.bag import BagReader  # noqa: E402

TARGET_RATIO = 2.0  # time per message of any storage vs the original MCAP bag, same run

STORAGES = {'MCAP (rosbags, uncompressed)': ('mcap', ''), 'sqlite3 (.db3)': ('sqlite3', ''),
            'MCAP, file zstd (.mcap.zstd)': ('mcap', 'file'),
            'sqlite3, file zstd (.db3.zstd)': ('sqlite3', 'file'), 'sqlite3, message zstd': ('sqlite3', 'message'),
            'MCAP, message zstd': ('mcap', 'message')}


def decode(path: Path) -> tuple[float, int]:
    start = time.perf_counter()
    with BagReader(path) as reader:
        arrays = reader.decode_topics([WRENCH_TOPIC, LVDT_TOPIC])
    return time.perf_counter() - start, sum(len(a) for a in arrays.values())


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--seconds', type=float, default=300.0, help='bag length in s (default 300)')
    parser.add_argument('--rate', type=float, default=1000.0, help='sample rate in Hz (default 1000)')
    parser.add_argument('--repeats', type=int, default=3, help='timed reads of each bag (default 3)')
    parser.add_argument('--keep', action='store_true', help='keep the bags')
    args = parser.parse_args()
    from helpers.rosbag2_copy import copy_bag

    tmp = Path(tempfile.mkdtemp(prefix='bench_bag_storage_'))
    try:
        bags = {'MCAP (this package, zstd chunks)': tmp / 'original'}
        count = generate(bags['MCAP (this package, zstd chunks)'], args.seconds, args.rate)
        print(f'{count:,} messages ({args.seconds:g} s at {args.rate:g} Hz, two topics); copying with rosbags ...',
              flush=True)
        for name, (storage, compression) in STORAGES.items():
            bags[name] = copy_bag(tmp / 'original', tmp / f'{storage}_{compression or "none"}', storage=storage,
                                  compression=compression)
        best: dict[str, float] = {}
        for _ in range(args.repeats):
            for name, path in bags.items():
                seconds, decoded = decode(path)
                assert decoded == count, (name, decoded, count)
                best[name] = min(best.get(name, seconds), seconds)
        base = best['MCAP (this package, zstd chunks)'] / count
        missed = []
        for name, seconds in best.items():
            size = sum(p.stat().st_size for p in bags[name].iterdir())
            ratio = seconds / count / base
            print(f'  {name:34s} {seconds:6.2f} s = {seconds / count * 1e6:5.2f} µs/message '
                  f'({ratio:4.2f}x MCAP) {size / 1e6:7.1f} MB')
            if ratio > TARGET_RATIO:
                missed.append(f'{name} {ratio:.2f}x')
        print(f'TARGET MISSED (> {TARGET_RATIO:g}x): ' + ', '.join(missed) if missed else
              f'targets met (every storage <= {TARGET_RATIO:g}x the MCAP time per message)')
        return 1 if missed else 0
    finally:
        keep_or_remove(tmp, args.keep)


if __name__ == '__main__':
    sys.exit(main())
