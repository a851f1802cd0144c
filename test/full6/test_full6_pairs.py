"""The 6x6 pairs live and offline: Full6Pairing, fed sample by sample in arrival order, gives the pairs of
full6_pairs over the whole streams, pair by pair, and they carry the deflection the platform had."""
from __future__ import annotations

import numpy as np

from crane_stiffness.full6.pairs import Full6Pairing, Rest, full6_pairs
from crane_stiffness.full6.steps import label_steps


def _rotvec_to_quaternion(r: np.ndarray) -> np.ndarray:
    angle = np.linalg.norm(r, axis=-1, keepdims=True)
    axis = np.where(angle > 0, r / np.where(angle > 0, angle, 1.0), 0.0)
    return np.concatenate([axis * np.sin(angle / 2), np.cos(angle / 2)], axis=-1)


def _session(seed: int = 5):
    """Commands at 100 Hz (zero, then 6 held steps of 1 s, 0.2 s ramps between), wrench at 1 kHz, pose at 250 Hz
    with a known compliance, noise, and deliveries out of step (a pose arrives 0-3 ms after its stamp)."""
    rng = np.random.default_rng(seed)
    steps = np.vstack([np.zeros(6), rng.uniform(-1, 1, (6, 6)) * [2, 3, 20, 1.5, 1.4, 0.7]])
    tc = np.arange(0.0, 9.0, 0.01)
    wc = np.zeros((tc.size, 6))
    for k in range(1, steps.size // 6):
        start = 1.2 * k
        ramp = (tc >= start - 0.2) & (tc < start)
        wc[ramp] = steps[k - 1] + np.outer((tc[ramp] - start + 0.2) / 0.2, steps[k] - steps[k - 1])
        wc[(tc >= start) & (tc < start + 1.0)] = steps[k]
    tw = np.arange(0.0, 9.0, 0.001)
    true_w = wc[np.clip(np.searchsorted(tc, tw, side='right') - 1, 0, None)]
    w = true_w + rng.normal(0, 0.01, true_w.shape)
    compliance = np.diag([2e-5, 2e-5, 5e-7, 2e-4, 2e-4, 1e-3]) + 1e-6
    tp = np.arange(0.0, 9.0, 0.004) + 0.0005
    true_p = wc[np.clip(np.searchsorted(tc, tp, side='right') - 1, 0, None)]
    d = true_p @ compliance.T + rng.normal(0, [2e-6] * 3 + [2e-5] * 3, (tp.size, 6))
    rest = np.array([0.0, 0.0, 0.48])
    position = rest + d[:, :3]
    quaternion = _rotvec_to_quaternion(d[:, 3:])
    pose_log = tp + rng.uniform(0, 0.003, tp.size)
    return tc, wc, tw, w, tp, pose_log, position, quaternion, rest


def test_streaming_pairs_equal_the_vectorised_ones_pair_by_pair():
    tc, wc, tw, w, tp, pose_log, position, quaternion, rest = _session()
    pose_log = np.maximum.accumulate(pose_log)  # arrival order of the pose stream itself
    expected = full6_pairs(tc, wc, tw, tw, w, tp, pose_log, position, quaternion, settle_s=0.25)
    live = Full6Pairing(settle_s=0.25)
    events = ([(t, 0, i) for i, t in enumerate(tc)] + [(t, 1, i) for i, t in enumerate(tw)]
              + [(t, 2, i) for i, t in enumerate(pose_log)])
    got = []
    for _, kind, i in sorted(events):  # everything in order of arrival
        if kind == 0:
            got += live.command(tc[i], wc[i])
        elif kind == 1:
            got += live.wrench(tw[i], w[i])
        else:
            got += live.pose(tp[i], position[i], quaternion[i])
    assert len(got) == len(expected) > 1000
    assert np.array_equal([g[0] for g in got], expected.stamp)
    assert np.array_equal([g[3] for g in got], expected.step)
    assert np.allclose([g[1] for g in got], expected.wrench, rtol=0, atol=1e-12)
    assert np.allclose([g[2] for g in got], expected.deflection, rtol=0, atol=1e-15)
    # the deflections are those of the platform, from the first pose; the labels those of the held steps
    assert np.allclose(expected.deflection[:, :3], position[np.searchsorted(tp, expected.stamp)] - position[0])
    assert set(expected.step) == set(label_steps(tc, wc, tp, 0.25)) - {-1}
    assert live.unlabelled > 0  # settling and ramps
    # still waiting: only pairs no later command will ever label (after the last command), as offline
    assert live.waiting >= 1 and all(stamp >= tc[-1] for stamp, _, _ in live._waiting)


def test_a_given_rest_pose_is_where_deflections_start():
    tc, wc, tw, w, tp, _, position, quaternion, rest = _session(6)
    pairs = full6_pairs(tc, wc, tw, tw, w, tp, tp, position, quaternion, settle_s=0.25,
                        rest=Rest.of(rest, [0.0, 0.0, 0.0, 1.0]))
    i = np.searchsorted(tp, pairs.stamp)
    assert np.allclose(pairs.deflection[:, :3], position[i] - rest, rtol=0, atol=1e-15)
    assert len(pairs) > 1000
