"""Benchmark: bulk-decoding a rig bag with crane_stiffness.bag versus mcap-ros2-support's per-message decoder.

Generates a synthetic rig bag (default one hour at 1 kHz: /load_cell/wrench WrenchStamped and /lvdt/displacement
PointStamped, 2 × 3600 × 1000 = 7.2 million messages) in a temporary directory with :class:`BagWriter`, then times

- ``BagReader.decode_topics`` on both topics (open + decode, numpy structured arrays), and
- mcap_ros2's ``DecoderFactory`` through ``mcap.reader.make_reader(...).iter_decoded_messages()`` on the first
  ``--baseline-messages`` messages (default 200,000), extrapolated linearly to the whole file.

The target is ≤ 20 s for the hour. Usage::

    python benchmarks/bench_bag_decode.py [--seconds 3600] [--rate 1000] [--baseline-messages 200000] [--keep]
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from crane_stiffness.serde import encode_stamped  # noqa: E402
from crane_stiffness.bag import BagReader, BagWriter  # noqa: E402

WRENCH_TOPIC = '/load_cell/wrench'
LVDT_TOPIC = '/lvdt/displacement'
T0_NS = 1_700_000_000_000_000_000


def generate(path: Path, seconds: float, rate_hz: float) -> int:
    """Write the synthetic bag; return its message count."""
    count = int(round(seconds * rate_hz))
    t = T0_NS + (np.arange(count, dtype=np.int64) * int(round(1e9 / rate_hz)))
    phase = np.arange(count) / rate_hz
    force = np.column_stack([10 * np.sin(phase), np.cos(phase), 500 + 200 * np.sin(0.1 * phase),
                             0.1 * phase % 3, -0.2 * np.sin(phase), np.full(count, 0.05)])
    disp = np.column_stack([1e-5 * np.sin(phase), 2e-5 * np.cos(phase), 1e-3 * np.sin(0.1 * phase)])
    wrench, wsize = encode_stamped(t, 'load_cell', force)
    lvdt, lsize = encode_stamped(t + 250_000, 'lvdt', disp)
    with BagWriter(path, compression='zstd') as writer:
        writer.add_topic(WRENCH_TOPIC, 'geometry_msgs/msg/WrenchStamped')
        writer.add_topic(LVDT_TOPIC, 'geometry_msgs/msg/PointStamped')
        write = writer.write
        times = t.tolist()
        for i, log in enumerate(times):
            write(WRENCH_TOPIC, wrench[i * wsize:(i + 1) * wsize], log + 100_000)
            write(LVDT_TOPIC, lvdt[i * lsize:(i + 1) * lsize], log + 350_000)
    return 2 * count


def bench_bulk(path: Path) -> tuple[float, dict[str, np.ndarray]]:
    start = time.perf_counter()
    with BagReader(path) as reader:
        arrays = reader.decode_topics([WRENCH_TOPIC, LVDT_TOPIC])
    return time.perf_counter() - start, arrays


def bench_baseline(mcap_path: Path, limit: int) -> tuple[float, int, list]:
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    start = time.perf_counter()
    sample = []
    done = 0
    with open(mcap_path, 'rb') as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        for _, channel, message, ros_msg in reader.iter_decoded_messages():
            if channel.topic == WRENCH_TOPIC and len(sample) < 1000:
                sample.append((message.log_time, ros_msg.wrench.force.z))
            done += 1
            if done >= limit:
                break
    return time.perf_counter() - start, done, sample


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--seconds', type=float, default=3600.0, help='recording length in s (default 3600)')
    parser.add_argument('--rate', type=float, default=1000.0, help='rate of each topic in Hz (default 1000)')
    parser.add_argument('--baseline-messages', type=int, default=200_000,
                        help='messages decoded by the baseline before extrapolating (default 200000)')
    parser.add_argument('--keep', action='store_true', help='keep the generated bag and print where it is')
    args = parser.parse_args()

    tmp = Path(tempfile.mkdtemp(prefix='bench_bag_decode_'))
    bag = tmp / 'rig_session'
    try:
        print(f'generating {args.seconds:g} s at {args.rate:g} Hz on 2 topics ...', flush=True)
        start = time.perf_counter()
        total = generate(bag, args.seconds, args.rate)
        gen_s = time.perf_counter() - start
        size = sum(f.stat().st_size for f in bag.glob('*.mcap'))
        print(f'  wrote {total:,} messages, {size / 1e6:.1f} MB (zstd chunks) in {gen_s:.1f} s '
              f'({gen_s / total * 1e6:.2f} µs/message)')

        bulk_s, arrays = bench_bulk(bag)
        decoded = sum(len(a) for a in arrays.values())
        assert decoded == total, (decoded, total)
        print(f'bulk decode (crane_stiffness.bag, open + both topics): {bulk_s:.2f} s for {decoded:,} messages '
              f'= {decoded / bulk_s / 1e6:.2f} M msg/s  [target ≤ 20 s for one hour]')

        limit = min(args.baseline_messages, total)
        base_s, done, sample = bench_baseline(next(bag.glob('*.mcap')), limit)
        per_msg = base_s / done
        extrapolated = per_msg * total
        wrench = arrays[WRENCH_TOPIC]
        lookup = dict(zip(wrench['log_time_ns'][:2000].tolist(), wrench['fz'][:2000].tolist()))
        assert all(lookup[t] == fz for t, fz in sample), 'bulk and baseline values differ'
        print(f'baseline (mcap_ros2 DecoderFactory, per message): {base_s:.2f} s for the first {done:,} messages '
              f'= {per_msg * 1e6:.2f} µs/message; EXTRAPOLATED to {total:,} messages: {extrapolated:.1f} s')
        print(f'speed-up of the bulk decoder: {extrapolated / bulk_s:.0f}x '
              f'(baseline measured on {done:,} messages and extrapolated linearly)')
    finally:
        if args.keep:
            print(f'bag kept at {bag}')
        else:
            shutil.rmtree(tmp, ignore_errors=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
