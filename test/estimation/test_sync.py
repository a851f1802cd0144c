"""Tests of crane_stiffness.estimation.sync: approximate stamp pairing and its counters, live and vectorized."""
from __future__ import annotations

import math

import numpy as np
import pytest

from crane_stiffness.estimation import ApproximateTimeSync, ParameterError, SyncError
from crane_stiffness.estimation.sync import InterpolatingSync, pair_by_interpolation, pair_by_stamp

RATE_HZ = 5000.0
PERIOD = 1.0 / RATE_HZ


def _interleaved(n: int, jitter: float, offset: float, rng: np.random.Generator) -> list[tuple[str, float, float]]:
    """Two 5 kHz streams with stamp jitter; the displacement stamps lag by ``offset``. Sorted by arrival."""
    base = np.arange(n) * PERIOD
    tf = base + rng.uniform(-jitter, jitter, n)
    td = base + offset + rng.uniform(-jitter, jitter, n)
    events = [('force', t, float(i)) for i, t in enumerate(tf)] + [('displacement', t, float(i)) for i, t in
                                                                    enumerate(td)]
    return sorted(events, key=lambda e: e[1])


def _run(sync: ApproximateTimeSync, events: list[tuple[str, float, object]]) -> list:
    pairs = []
    for stream, stamp, value in events:
        pairs.extend(sync.push(stream, stamp, value))
    pairs.extend(sync.flush())
    return pairs


def test_pairs_jittered_streams() -> None:
    rng = np.random.default_rng(1)
    n = 2000
    sync = ApproximateTimeSync(slop=0.4 * PERIOD, expected_period=PERIOD)
    pairs = _run(sync, _interleaved(n, jitter=0.05 * PERIOD, offset=0.1 * PERIOD, rng=rng))
    assert len(pairs) == n
    assert all(p.force == p.displacement for p in pairs)  # each sample with its true partner
    assert all(abs(p.force_stamp_s - p.displacement_stamp_s) <= 0.4 * PERIOD for p in pairs)
    stamps = [p.stamp_s for p in pairs]
    assert stamps == sorted(stamps)
    assert pairs[0].stamp_s == pytest.approx(0.5 * (pairs[0].force_stamp_s + pairs[0].displacement_stamp_s))
    counters = sync.counters
    assert counters.pairs == n
    assert counters.force.received == counters.displacement.received == n
    assert counters.force.paired == n
    assert counters.total('unmatched') == counters.total('dropouts') == counters.total('stale') == 0


def test_pairs_emitted_with_one_sample_latency() -> None:
    sync = ApproximateTimeSync(slop=1e-4)
    assert sync.push('force', 0.0, 1.0) == []
    assert sync.push('displacement', 0.00005, 2.0) == []  # a later force sample could still be nearer
    pairs = sync.push('force', 0.0002, 3.0)
    assert [(p.force, p.displacement) for p in pairs] == [(1.0, 2.0)]
    assert sync.pending('force') == 1


def test_each_sample_used_once_and_nearest_wins() -> None:
    sync = ApproximateTimeSync(slop=0.005)
    out = []
    for stream, stamp, value in [('force', 0.0, 'a0'), ('displacement', 0.004, 'b0'), ('force', 0.0041, 'a1'),
                                 ('displacement', 0.0046, 'b1'), ('force', 0.02, 'a2')]:
        out.extend(sync.push(stream, stamp, value))
    # a1 is nearer to b0 than a0 is: a0 is dropped, not paired; b1 finds no partner left within slop.
    assert [(p.force, p.displacement) for p in out] == [('a1', 'b0')]
    counters = sync.counters
    assert counters.force.unmatched == 1
    assert counters.displacement.unmatched == 1


def test_slop_rejects_distant_stamps() -> None:
    rng = np.random.default_rng(2)
    sync = ApproximateTimeSync(slop=0.1 * PERIOD, expected_period=PERIOD)
    pairs = _run(sync, _interleaved(500, jitter=0.0, offset=0.3 * PERIOD, rng=rng))
    assert pairs == []
    assert sync.counters.total('unmatched') == 1000


def test_out_of_order_never_paired() -> None:
    sync = ApproximateTimeSync(slop=1e-4)
    sync.push('force', 1.0, 'f1')
    assert sync.push('force', 0.5, 'old') == []
    pairs = sync.push('displacement', 0.5, 'd-old') + sync.push('displacement', 1.0, 'd1') + sync.flush()
    assert [(p.force, p.displacement) for p in pairs] == [('f1', 'd1')]
    assert sync.counters.force.out_of_order == 1
    assert sync.counters.displacement.out_of_order == 0


def test_stale_samples_dropped() -> None:
    sync = ApproximateTimeSync(slop=1e-3, max_age=0.05)
    sync.push('displacement', 1.0, 0.0)
    assert sync.push('force', 0.9, 1.0) == []  # 100 ms behind the displacement stream
    assert sync.counters.force.stale == 1
    sync.push('force', 0.96, 1.0)  # 40 ms behind: not stale, but too far to pair
    assert sync.counters.force.stale == 1
    pairs = sync.push('force', 1.0002, 2.0) + sync.flush()
    assert [(p.force, p.displacement) for p in pairs] == [(2.0, 0.0)]


def test_non_finite_dropped_and_counted() -> None:
    sync = ApproximateTimeSync(slop=1e-4)
    out = []
    out += sync.push('force', 0.0, np.array([0.0, math.nan, 0.0, 0.0, 0.0, 0.0]))
    out += sync.push('force', math.inf, 1.0)
    out += sync.push('displacement', 0.0, 5e-3)
    out += sync.push('displacement', 0.001, math.inf)
    out += sync.push('force', 0.001, np.zeros(6))
    out += sync.push('displacement', 0.0011, 6e-3)
    out += sync.flush()
    assert len(out) == 1
    assert out[0].displacement == 6e-3
    assert sync.counters.force.non_finite == 2
    assert sync.counters.displacement.non_finite == 1


def test_dropouts_counted_with_given_and_estimated_period() -> None:
    for period in (PERIOD, None):
        sync = ApproximateTimeSync(slop=0.3 * PERIOD, expected_period=period, dropout_factor=3.0)
        stamps = [i * PERIOD for i in range(100)] + [(100 + 10 + i) * PERIOD for i in range(100)] \
            + [(220 + i) * PERIOD for i in range(50)]  # gaps of 11 and 10 periods
        for i, t in enumerate(stamps):
            sync.push('force', t, 1.0)
            if i != 150:  # one displacement sample missing: a 2-period gap, below the 3-period limit
                sync.push('displacement', t, 1.0)
        sync.flush()
        assert sync.counters.force.dropouts == 2
        assert sync.counters.displacement.dropouts == 2
        assert sync.period('force') == pytest.approx(PERIOD, rel=1e-6)
        assert sync.counters.pairs == len(stamps) - 1


def test_latency_bounded_when_one_stream_stops() -> None:
    sync = ApproximateTimeSync(slop=1e-3, max_age=0.01)
    sync.push('force', 0.0, 'f0')
    sync.push('displacement', 0.0005, 'd0')
    pairs = []
    for i in range(1, 30):  # force stream silent; displacement runs on
        pairs += sync.push('displacement', 0.0005 + i * 1e-3, f'd{i}')
    assert [(p.force, p.displacement) for p in pairs] == [('f0', 'd0')]
    assert sync.pending('displacement') <= 12  # older ones can never pair: discarded


def test_parameter_and_stream_errors() -> None:
    with pytest.raises(ParameterError, match='slop'):
        ApproximateTimeSync(slop=-1.0)
    with pytest.raises(ParameterError, match='max_age'):
        ApproximateTimeSync(slop=0.1, max_age=0.01)
    with pytest.raises(ParameterError, match='dropout_factor'):
        ApproximateTimeSync(slop=0.1, dropout_factor=0.5)
    with pytest.raises(ParameterError, match=r'expected_period\[force\]'):
        ApproximateTimeSync(slop=0.1, expected_period={'force': 0.0})
    with pytest.raises(SyncError, match='torque'):
        ApproximateTimeSync(slop=0.1).push('torque', 0.0, 1.0)


def test_two_5khz_streams_every_sample_with_its_partner() -> None:
    """2 s of two 5 kHz streams (its speed: benchmarks/bench_sync.py)."""
    rng = np.random.default_rng(3)
    events = _interleaved(10_000, jitter=0.05 * PERIOD, offset=0.0, rng=rng)
    sync = ApproximateTimeSync(slop=0.4 * PERIOD, expected_period=PERIOD)
    pairs = _run(sync, events)
    assert len(pairs) == 10_000
    assert all(p.force == p.displacement for p in pairs)


# ------------------------------------------------------------------------------------------- vectorized --
def _streaming_pairs(fs, fl, ds, dl, slop, max_age):
    sync = ApproximateTimeSync(slop, max_age=max_age)
    events = sorted([(t, 0, i) for i, t in enumerate(fl)] + [(t, 1, i) for i, t in enumerate(dl)])
    out = []
    for _, kind, i in events:
        out += sync.push('force', fs[i], i) if kind == 0 else sync.push('displacement', ds[i], i)
    out += sync.flush()
    return [(p.force, p.displacement) for p in out]


@pytest.mark.parametrize('case', ['one_clock', 'jitter', 'large_jitter', 'rates_1000_700', 'dropouts',
                                  'out_of_order', 'stale'])
def test_vectorized_pairing_equals_the_live_synchroniser(case):
    rng = np.random.default_rng(7)
    n, slop = 4000, 6e-4
    f_period, d_period, jitter, d_offset = 1e-3, 1e-3, 0.0, 0.0
    if case == 'jitter':
        jitter, d_offset = 5e-5, 2e-4
    elif case == 'large_jitter':
        jitter = 4e-4
    elif case == 'rates_1000_700':
        d_period, jitter = 1 / 700, 1e-4
    fs = np.sort(100 + np.arange(n) * f_period + rng.normal(0, jitter, n))
    ds = np.sort(100 + d_offset + np.arange(int(n * f_period / d_period)) * d_period
                 + rng.normal(0, jitter, int(n * f_period / d_period)))
    if case == 'dropouts':
        fs = fs[rng.random(fs.size) > 0.05]
        ds = ds[rng.random(ds.size) > 0.05]
    fl = np.sort((np.floor(fs * 100) + 1) / 100 + 1e-4) + np.arange(fs.size) * 1e-7
    dl = np.sort((np.floor(ds * 100) + 1) / 100 + 2e-4) + np.arange(ds.size) * 1e-7
    if case == 'out_of_order':
        fs[rng.choice(fs.size, 40, replace=False)] -= 3e-3
    if case == 'stale':
        dl[1000:1300] += 0.3  # a burst of LVDT samples arrives late: the older ones are stale
        dl = np.maximum.accumulate(dl)
    expected = _streaming_pairs(fs, fl, ds, dl, slop, 0.1)
    got = pair_by_stamp(fs, fl, ds, dl, slop, 0.1)
    assert list(zip(got.force_index.tolist(), got.displacement_index.tolist())) == expected
    assert got.counters['pairs'] == len(expected)
    if case == 'one_clock':
        assert got.counters['replayed_stretches'] == 0 and len(expected) == n
    if case == 'stale':
        assert got.counters['displacement_stale'] > 0


# ----------------------------------------------------------------------------------------------- interpolated --
def test_interpolation_is_linear_and_leaves_out_what_it_cannot_bracket():
    """Fast samples at 0, 1, 2, 5 s (force 0, 1, 3, 6 N); slow samples around them."""
    sync = InterpolatingSync('force', max_gap=2.0, max_age=100.0)
    out = []
    for t, f in [(0.0, 0.0), (1.0, 1.0), (2.0, 3.0)]:
        out += sync.push('force', t, f)
    assert out == []
    out += sync.push('displacement', -0.1, 10.0)   # before the first force sample: nothing to interpolate from
    out += sync.push('displacement', 0.5, 20.0)
    out += sync.push('displacement', 2.0, 30.0)    # on a sample: its value (the bracket is 1 < t <= 2)
    out += sync.push('displacement', 3.5, 40.0)    # waits for a force sample at or after 3.5 s
    assert sync.pending('displacement') == 1
    out += sync.push('force', 5.0, 6.0)            # brackets 3.5 s across a 3 s gap > max_gap: not paired
    out += sync.push('displacement', 6.0, 50.0)    # after the last force sample: waits
    assert [(p.stamp_s, p.force, p.displacement) for p in out] == [(0.5, 0.5, 20.0), (2.0, 3.0, 30.0)]
    assert all(p.force_stamp_s == p.displacement_stamp_s for p in out)
    c = sync.counters
    assert (c.pairs, c.displacement.paired, c.displacement.unmatched, sync.pending('displacement')) == (2, 2, 2, 1)
    assert c.force.received == 4 and sync.pending('force') == 4  # all kept: 100 s of history
    sync.restart()  # a new segment: the waiting sample and the fast history are counted, the counters go on
    c = sync.counters
    assert (c.displacement.discarded, c.force.paired, c.force.discarded) == (1, 3, 1)  # 0, 1, 2 s served a pair
    # The other way round: the displacement interpolated at each force stamp.
    sync = InterpolatingSync('displacement', max_gap=0.01)
    out = sync.push('displacement', 0.0, 0.0) + sync.push('displacement', 0.01, 1e-5) + sync.push('force', 0.0025, 4.0)
    assert [(p.stamp_s, p.force, p.displacement) for p in out] == [(0.0025, 4.0, 0.25e-5)]
    with pytest.raises(ParameterError, match='max_gap'):
        InterpolatingSync('force', max_gap=0.0)
    with pytest.raises(ParameterError, match='fast'):
        InterpolatingSync('lvdt', max_gap=0.01)


def _accounted(sync, stream: str) -> bool:
    c = getattr(sync.counters, stream)
    return c.received == (c.paired + c.out_of_order + c.non_finite + c.stale + c.unmatched + c.discarded
                          + sync.pending(stream))


def _mixed_rate_streams(case: str, fast: str, rng: np.random.Generator):
    """A 1 kHz fast and a 100 Hz slow stream, off each other's grid, with jitter; stamps, values, arrival times."""
    n_fast, n_slow = 6000, 600
    tf = 100 + np.arange(n_fast) * 1e-3 + rng.normal(0, 2e-5, n_fast)
    ts = 100 + 3.3e-3 + np.arange(n_slow) * 1e-2 + rng.normal(0, 5e-5, n_slow)
    if case == 'dropout':
        keep = (tf < 102.0) | (tf > 102.05)  # a 50 ms dropout of the fast stream
        tf = tf[keep]
    if case == 'duplicates':
        tf[1000:1010] = tf[1000]   # a driver repeating a stamp: equal stamps are in order
    yf = rng.normal(0, 1, (tf.size, 2)) if case == 'vector' else np.cumsum(rng.normal(0, 1, tf.size))
    ys = rng.normal(0, 1, ts.size)
    lf = tf + 1e-4 + rng.uniform(0, 2e-3, tf.size)     # the fast driver delivers in small batches
    ls = ts + rng.uniform(-5e-3, 3e-2, ts.size)        # the slow one: sometimes before the fast samples it needs
    if case == 'out_of_order':
        tf[rng.choice(tf.size, 30, replace=False)] -= 4e-3
        ts[rng.choice(ts.size, 10, replace=False)] -= 25e-3
    lf, ls = np.maximum.accumulate(lf), np.maximum.accumulate(ls)  # each stream arrives in its own order
    if case == 'stale':
        ls[200:260] += 0.3  # a burst of slow samples arrives late: the older ones are stale
        ls = np.maximum.accumulate(ls)
    if case == 'slow_first':
        tf, yf, lf = tf[500:], yf[500:], lf[500:]  # the slow stream starts half a second before the fast one
    force, disp = ((tf, yf, lf), (ts, ys, ls)) if fast == 'force' else ((ts, ys, ls), (tf, yf, lf))
    return force, disp


@pytest.mark.parametrize('fast', ['force', 'displacement'])
@pytest.mark.parametrize('case', ['plain', 'dropout', 'duplicates', 'vector', 'out_of_order', 'stale', 'slow_first'])
def test_vectorized_interpolation_equals_the_live_synchroniser(case, fast):
    """The two forms of interpolated pairing pinned together: the same pairs (stamps and values to the bit), the
    same drops, every sample accounted for."""
    rng = np.random.default_rng(11)
    (fs, fv, fl), (ds, dv, dl) = _mixed_rate_streams(case, fast, rng)
    slow = 'displacement' if fast == 'force' else 'force'
    sync = InterpolatingSync(fast, max_gap=1.05e-3, max_age=0.1)  # 1 ms period: jitter crosses it
    events = sorted([(t, 0, i) for i, t in enumerate(fl)] + [(t, 1, i) for i, t in enumerate(dl)])
    live = []
    for _, kind, i in events:
        live += sync.push('force', fs[i], fv[i]) if kind == 0 else sync.push('displacement', ds[i], dv[i])
    got = pair_by_interpolation(fs, (fl * 1e9).astype(np.int64), ds, (dl * 1e9).astype(np.int64), fast,
                                fv if fast == "force" else dv, 1.05e-3, 0.1)
    assert len(live) == got.counters['pairs'] > 0.8 * min(fs.size, ds.size) * (0.5 if case == 'stale' else 1)
    np.testing.assert_array_equal([p.stamp_s for p in live], got.stamp)
    fast_live = np.array([p.force if fast == 'force' else p.displacement for p in live])
    slow_live = np.array([p.displacement if fast == 'force' else p.force for p in live])
    np.testing.assert_array_equal(fast_live, got.fast_value)
    np.testing.assert_array_equal(slow_live, (dv if fast == 'force' else fv)[got.slow_index])
    c = sync.counters
    for stream in ('force', 'displacement'):
        assert getattr(c, stream).out_of_order == got.counters[f'{stream}_out_of_order']
        assert getattr(c, stream).stale == got.counters[f'{stream}_stale']
        assert _accounted(sync, stream), getattr(c, stream)
    assert getattr(c, slow).unmatched == got.counters[f'{slow}_unmatched']
    assert sync.pending(slow) == got.counters[f'{slow}_waiting']
    if case == 'dropout':
        assert got.counters[f'{slow}_unmatched'] >= 4  # the slow samples in the 50 ms gap: left out, counted
    if case in ('out_of_order', 'stale'):
        assert got.counters[f'{slow}_{case}'] > 0
    if case == 'slow_first':
        assert got.counters[f'{slow}_unmatched'] >= 45


def test_interpolated_pairs_are_truer_than_the_nearest_on_a_ramp():
    """A 1 kHz force and a 100 Hz LVDT 0.4 ms off the force grid, a 4 N/s ramp: interpolated, the force of a pair
    is the force at the LVDT's instant; nearest, it is the force 0.4 ms away (1.6 mN: 8 % of the 20 mN per 10 ms
    poll)."""
    rate = 4.0  # N/s
    tf = np.arange(0.0, 1.0, 1e-3)
    ts = np.arange(0.0104, 0.99, 1e-2)
    interp = InterpolatingSync('force', max_gap=2e-3, max_age=0.1)
    near = ApproximateTimeSync(6e-4, max_age=0.1)
    pairs_i, pairs_n = [], []
    for sync, out in ((interp, pairs_i), (near, pairs_n)):
        for t, stream in sorted([(t, 'force') for t in tf] + [(t, 'displacement') for t in ts]):
            out += sync.push(stream, t, rate * t if stream == 'force' else t)  # the LVDT: the instant it was taken
        out += sync.flush()
    err_i = np.array([p.force - rate * p.displacement for p in pairs_i])
    err_n = np.array([p.force - rate * p.displacement for p in pairs_n])
    assert len(pairs_i) == len(pairs_n) == ts.size
    assert np.abs(err_i).max() < 1e-12
    np.testing.assert_allclose(err_n, -rate * 0.4e-3, rtol=1e-6)
