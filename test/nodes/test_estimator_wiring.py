"""Sensor frames and stream delay wired into the live estimator (real rclpy + DDS) and its offline counterpart
(analyze):

* sensor frames: an F/T sensor rotated 90° about z, mounted 50 mm off the platform centre and measuring the reaction
  gives the same estimate as one at the centre, aligned (sensor_rotation, sensor_position, sensor_reaction);
* clocks: a displacement stream stamped 3 ms late is found 3 ms late (within 0.5 ms) by the estimator, WARNed, and
  with ``displacement_delay_s = 0.003`` the loading/unloading difference the delay causes disappears.

The rig (helpers.estimator.SyntheticRig) publishes the wrench as the mounted sensor would measure it; the sensor's
reading is modelled here independently of crane_stiffness.estimation.frames (explicit rotation matrix).
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from rclpy.parameter import Parameter

from helpers import PATIENCE_S, spin_until
from crane_stiffness.analysis.analyze import analyze_session
from crane_stiffness.estimation.settings import LiveSettings
from crane_stiffness.nodes.stiffness_estimator import StiffnessEstimatorNode
from crane_stiffness.sim.program import LoadProgram, Segment
from crane_stiffness.testing.synthetic import write_synthetic_session
from helpers.estimator import (K, EstimatorProbe, SyntheticRig, assert_refused, executor_with, isolated_estimator,
                               run_program)

ANGLE = math.pi / 2                                # sensor rotated 90° about z
R = np.array([[math.cos(ANGLE), -math.sin(ANGLE), 0.0], [math.sin(ANGLE), math.cos(ANGLE), 0.0], [0.0, 0.0, 1.0]])
QUAT = [0.0, 0.0, math.sin(ANGLE / 2), math.cos(ANGLE / 2)]
POSITION = np.array([0.03, 0.04, 0.0])             # 50 mm from the platform centre [m]
MOUNT_PARAMS = {'sensor_rotation': QUAT, 'sensor_position': POSITION.tolist(), 'sensor_reaction': True}
DELAY = 0.003                                      # the displacement stamps are this late [s]


def sensor_reading(w_c) -> np.ndarray:
    """What the mounted sensor reports of the platform wrench ``w_c`` (at the centre, crane_base), rows (n, 6) or
    (6,): its own frame (R^T), about its own origin (m − r × f), the reaction (negated)."""
    w = np.atleast_2d(np.asarray(w_c, dtype=float))
    f, m = w[:, :3], w[:, 3:]
    out = -np.hstack([f @ R, (m - np.cross(POSITION, f)) @ R])
    return out[0] if np.ndim(w_c) == 1 else out


def run_rig(ctx, params: dict, *, platform=None, sensor=None, rate_hz=500.0, late_ns=0, load=None,
            force_noise=0.02, seed=11):
    """One estimator and rig over DDS; returns (loading row, unloading row, estimator, probe, rig)."""
    name, prefix, args = isolated_estimator()
    probe = EstimatorProbe(ctx, prefix)
    estimator = StiffnessEstimatorNode(context=ctx, cli_args=args, parameter_overrides=[
        Parameter(k, value=v) for k, v in params.items()])
    rig = SyntheticRig(ctx, prefix, rate_hz=rate_hz, seed=seed, force_noise=force_noise)
    if platform is not None:
        rig.platform = platform
    rig.sensor = sensor
    rig.disp_late_ns = late_ns
    if load is not None:
        rig.load = load
    ex = executor_with(ctx, estimator, probe.node, rig.node)
    # Matched both ways before the rig starts: runs compared with each other must not lose their first (best
    # effort) samples to discovery, one more than the other.
    assert spin_until(ex, lambda: estimator.sub_force.get_publisher_count() >= 1
                      and estimator.sub_displacement.get_publisher_count() >= 1
                      and estimator.sub_command.get_publisher_count() >= 1, PATIENCE_S)
    run_program(ex, rig, estimator, probe=probe)
    assert spin_until(ex, lambda: len(probe.estimates) >= 2, PATIENCE_S)
    # The estimate after the streams paused: its input status says they are silent (not asserted: the tests' checks
    # say what is missing).
    spin_until(ex, lambda: 'silent' in probe.estimates[-1].status[2].message, PATIENCE_S)
    out = probe.last(0), probe.last(1), estimator, probe, rig
    ex.shutdown()
    for node in (estimator, probe.node, rig.node):
        node.destroy_node()
    return out


@pytest.mark.parametrize('axis', ['fy', 'mz'])
def test_rotated_off_centre_reaction_sensor_gives_the_aligned_estimate(rclpy_context, axis):
    if axis == 'fy':   # the load F on fy, with a weight and constant disturbances that rotation would mix in
        platform = lambda f: (2.0, f, 50.0, 0.3, -0.2, 0.1)  # noqa: E731
    else:              # the load F on mz, with a side force 10·F: 50 mm off centre it adds 0.4·F to the sensor's mz
        platform = lambda f: (10.0 * f, 0.0, 50.0, 0.0, 0.0, f)  # noqa: E731
    # Branches from the measured force: the same in both runs (the command goes out once per burst, and bursts
    # follow the machine's load: which pairs near the peak a command covers would differ from run to run).
    base = {'window': 5000, 'force_axis': axis, 'branch_source': 'force'}
    aligned = run_rig(rclpy_context, base, platform=platform)
    mounted = run_rig(rclpy_context, {**base, **MOUNT_PARAMS}, platform=platform,
                      sensor=lambda w: sensor_reading(w))
    wrong = sensor_reading(np.array(platform(4.0)))[{'fy': 1, 'mz': 5}[axis]]
    print(f'{axis}: the sensor reads {wrong:.3f} for a load of 4; aligned k = {aligned[0]["stiffness"]:.4f}, '
          f'mounted k = {mounted[0]["stiffness"]:.4f}')
    assert abs(wrong - 4.0) > 1.0  # untransformed, the reading is far from the load: the test can fail
    for b in (0, 1):
        a, m = aligned[b], mounted[b]
        assert a['stiffness'] == pytest.approx(K, rel=0.01)
        # The same samples and noise: equal but for a pair DDS may deliver to one run and not the other (best
        # effort), worth ~2e-5 of the stiffness here; in practice equal to the last digit.
        assert a['n'] > 400 and abs(m['n'] - a['n']) <= 2
        for field in ('stiffness', 'rls_stiffness'):
            assert m[field] == pytest.approx(a[field], rel=2e-4), (b, field)
        assert m['intercept'] == pytest.approx(a['intercept'], abs=2e-3)
    assert mounted[2].core.counters.dropped == 0


def delayed_load(t_s: float) -> float | None:
    """Two ramps up to 20 N and back (40 N/s) with holds, then 1.3 s at 0 N (the streams go on: statuses while they
    run), [N]."""
    knots_t = [0.0, 0.1, 0.5, 0.6, 1.0, 1.2, 1.6, 1.7, 2.1, 3.4]
    knots_f = [0.0, 0.0, 20.0, 20.0, 0.0, 0.0, 20.0, 20.0, 0.0, 0.0]
    return None if t_s > knots_t[-1] else float(np.interp(t_s, knots_t, knots_f))


def input_statuses(probe: EstimatorProbe) -> list[tuple[int, str, dict[str, str]]]:
    out = []
    for array in probe.estimates:
        for s in array.status:
            if s.name.endswith(': input'):
                out.append((s.level[0], s.message, {k.key: k.value for k in s.values}))
    return out


def test_injected_3ms_displacement_delay_found_warned_and_corrected(rclpy_context):
    params = {'window': 5000, 'diagnostics_rate_hz': 5.0, 'branch_source': 'force'}  # (see the frames test)
    kw = dict(rate_hz=1000.0, load=delayed_load, force_noise=0.01, seed=21)
    runs = {'baseline': run_rig(rclpy_context, params, **kw),
            'delayed': run_rig(rclpy_context, params, late_ns=int(DELAY * 1e9), **kw),
            'corrected': run_rig(rclpy_context, {**params, 'displacement_delay_s': DELAY},
                                 late_ns=int(DELAY * 1e9), **kw)}
    diff, reported = {}, {}
    for key, (loading, unloading, estimator, probe, rig) in runs.items():
        diff[key] = loading['intercept'] - unloading['intercept']
        statuses = input_statuses(probe)
        trusted = [s for s in statuses if math.isfinite(float(s[2]['stream_delay_s']))]
        assert trusted, f'{key}: no stream delay reported: {statuses[-1][2].get("stream_delay_note")}'
        reported[key] = trusted
        last = trusted[-1][2]
        print(f'{key}: loading - unloading intercept {diff[key] * 1e3:+.2f} mN, k {loading["stiffness"]:.1f} / '
              f'{unloading["stiffness"]:.1f} N/m; stream_delay_s {last["stream_delay_s"]}, residual '
              f'{last["stream_delay_residual_s"]}, ok {last["stream_delay_ok"]}, peak '
              f'{last["stream_delay_peak_correlation"]}, estimates made {estimator.core.stream_delay.runs}')
        if key != 'delayed':  # the delay skews the branches (the ends of the ramps): that is what is corrected
            assert loading['stiffness'] == pytest.approx(K, rel=0.005)
            assert unloading['stiffness'] == pytest.approx(K, rel=0.005)
    base, delayed, corrected = (reported[k][-1][2] for k in ('baseline', 'delayed', 'corrected'))
    # Found: the baseline's streams agree, the delayed ones are 3 ms apart, and with the correction 3 ms were
    # applied and nothing is left.
    assert float(base['stream_delay_s']) == pytest.approx(0.0, abs=0.5e-3)
    assert float(delayed['stream_delay_s']) == pytest.approx(DELAY, abs=0.5e-3)
    assert float(corrected['stream_delay_s']) == pytest.approx(DELAY, abs=0.5e-3)
    assert float(corrected['stream_delay_residual_s']) == pytest.approx(0.0, abs=0.5e-3)
    assert float(corrected['displacement_delay_s']) == DELAY
    assert base['stream_delay_ok'] == corrected['stream_delay_ok'] == 'true' and delayed['stream_delay_ok'] == 'false'
    # Reported: while the streams ran, the uncorrected delay made the input status WARN naming it; corrected, OK.
    running = {k: [s for s in v if 'silent' not in s[1]] for k, v in reported.items()}
    assert running['delayed'] and all(level == 1 and 'max_stream_delay_s' in message
                                      for level, message, _ in running['delayed'])
    assert running['corrected'] and all(level == 0 for level, _, _ in running['corrected'])
    assert running['baseline'] and all(level == 0 for level, _, _ in running['baseline'])
    # The delay splits the branches (40 N/s × 3 ms = 0.12 N each way along the ramps, less the holds'
    # pairs in the same branches: ~0.15 N); the correction joins them again.
    assert abs(diff['delayed'] - diff['baseline']) > 0.08
    assert abs(diff['corrected'] - diff['baseline']) < 0.02


def short_program() -> LoadProgram:
    segs = [Segment('hold', 'fy', 0.0, 0.5)]
    for level in (2.0, 4.0, 2.0, 0.0):
        segs += [Segment('ramp', 'fy', level, 0.4), Segment('hold', 'fy', level, 0.4)]
    return LoadProgram(segs, repeats=1, name='wiring', rate_hz=100.0)


def test_analyze_moves_the_wrench_and_reports_the_delay_like_the_live_estimator(tmp_path):
    kw = dict(stiffness=48_000.0, live=True, seed=4, force_noise=0.005)
    aligned = write_synthetic_session(tmp_path / 'aligned', short_program(), **kw)
    mounted = write_synthetic_session(tmp_path / 'mounted', short_program(), estimator=MOUNT_PARAMS,
                                      sensor=sensor_reading, **kw)
    late = write_synthetic_session(tmp_path / 'late', short_program(), displacement_late_s=DELAY, **kw)
    fixed = write_synthetic_session(tmp_path / 'fixed', short_program(), displacement_late_s=DELAY,
                                    estimator={'displacement_delay_s': DELAY}, **kw)
    a, m, lt, fx = (analyze_session(s.path, write_files=False) for s in (aligned, mounted, late, fixed))
    assert LiveSettings.from_params(MOUNT_PARAMS).force_row() is not None
    for branch in ('loading', 'unloading'):
        assert a.branch_fits[branch].stiffness == pytest.approx(48_000.0, rel=0.01)
        assert m.branch_fits[branch].stiffness == pytest.approx(a.branch_fits[branch].stiffness, rel=1e-9)
        assert m.branch_fits[branch].intercept == pytest.approx(a.branch_fits[branch].intercept, abs=1e-9)
        # The live estimate recorded with the mounted sensor (LiveStiffness's per-sample row) is reproduced by the
        # vectorised matrix.
        assert m.live.max_rel_diff[branch] < 1e-9
        assert fx.live.max_rel_diff[branch] < 1e-9
    print(f'offline stream delay: aligned {a.stream_delay["stream_delay_s"]}, late {lt.stream_delay["stream_delay_s"]}'
          f', corrected {fx.stream_delay["stream_delay_s"]} (residual {fx.stream_delay["stream_delay_residual_s"]})')
    assert float(a.stream_delay['stream_delay_s']) == pytest.approx(0.0, abs=0.5e-3)
    assert float(lt.stream_delay['stream_delay_s']) == pytest.approx(DELAY, abs=0.5e-3)
    assert lt.stream_delay['stream_delay_ok'] == 'false'
    assert any('max_stream_delay_s' in p for p in lt.problems)
    assert float(fx.stream_delay['stream_delay_residual_s']) == pytest.approx(0.0, abs=0.5e-3)
    assert fx.stream_delay['stream_delay_ok'] == 'true' and not any('max_stream_delay_s' in p for p in fx.problems)
    assert float(fx.stream_delay['displacement_delay_s']) == DELAY


# --- the live and vectorised forms pinned together; the parameters' checks ---------------------------------------

@pytest.mark.parametrize('axis', ['fx', 'fy', 'fz', 'mx', 'my', 'mz'])
def test_the_per_sample_row_is_the_vectorised_matrix_and_the_frames_transform(axis):
    from crane_stiffness.contract.axes import AXES
    from crane_stiffness.estimation.frames import transform_wrench
    settings = LiveSettings.from_params({**MOUNT_PARAMS, 'force_axis': axis})
    w = np.random.default_rng(5).normal(0.0, 10.0, (200, 6))
    i = AXES.index(axis)
    row = settings.force_row()
    live = np.array([sum(c * v for c, v in zip(row, sample)) for sample in w.tolist()])
    np.testing.assert_allclose(live, settings.force_component(w), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(live, transform_wrench(w, QUAT, POSITION, reaction=True)[:, i], rtol=1e-12, atol=1e-12)
    # The independent sensor model inverted: the platform's wrench comes back.
    np.testing.assert_allclose(settings.force_component(sensor_reading(w)), w[:, i], rtol=1e-12, atol=1e-12)
    # At the centre, aligned: nothing to compute, the component as is.
    plain = LiveSettings.from_params({'force_axis': axis})
    assert plain.force_row() is None and np.array_equal(plain.force_component(w), w[:, i])


@pytest.mark.parametrize('correction', [0.0, 0.0025])
def test_stream_delay_live_window_matches_the_offline_estimate(correction):
    """LiveStiffness fed sample by sample (estimates at its slow refresh) and stream_delay_of over the same samples
    find the same delay, and say the same about it, when the window holds the whole recording."""
    from crane_stiffness.estimation.inputs import Samples
    from crane_stiffness.estimation.live import LiveStiffness
    from crane_stiffness.estimation.stream_delay import stream_delay_of
    from crane_stiffness.contract.status import OK, WARN
    rng = np.random.default_rng(2)
    t = np.arange(0.0, 2.1, 0.001) + 100.0
    load = np.array([delayed_load(s - 100.0) for s in t])
    f = load + rng.normal(0.0, 0.01, t.size)
    x = (load - 0.15) / K + rng.normal(0.0, 2e-7, t.size)
    settings = LiveSettings.from_params({'window': 5000, 'delay_window_s': 5.0, 'displacement_delay_s': correction})
    core = LiveStiffness(settings)
    for i in range(t.size):
        core.add_force(t[i], (0.0, f[i], 0.0, 0.0, 0.0, 0.0))
        core.add_displacement(t[i] + DELAY, x[i])
    core.refresh()   # new data, a first estimate
    core.refresh()   # nothing new: the streams paused; the estimate stays
    live = core.stream_delay.estimate
    assert live is not None and live.ok
    none = np.zeros(t.size, np.int64)
    offline, problem, values = stream_delay_of(settings, Samples(t, none, f),
                                               Samples(t + DELAY - correction, none, x))
    assert offline.delay_s == pytest.approx(live.delay_s, abs=1e-9)
    assert live.delay_s == pytest.approx(DELAY - correction, abs=0.5e-3)
    kv = dict(values)
    assert float(kv['stream_delay_s']) == pytest.approx(DELAY, abs=0.5e-3)
    level, message, pairs = core.input_report('test')
    assert dict(pairs) == {**dict(pairs), **kv}  # the same key/values live and offline
    if correction == 0.0:   # 3 ms left > max_stream_delay_s = 2 ms
        assert level == WARN and problem and problem in message and kv['stream_delay_ok'] == 'false'
    else:                   # 0.5 ms left
        assert level == OK and problem == '' and kv['stream_delay_ok'] == 'true'


def test_stream_delay_of_a_long_recording_looks_where_the_load_moves():
    """Over a recording many windows long (10 min of holds with a few load cycles, 1 kHz) the offline estimate uses
    the windows where the force moves (moving_windows) and finds the delay to the same accuracy as over one window,
    while a recording without load changes is not trusted and says why."""
    from crane_stiffness.estimation.inputs import Samples
    from crane_stiffness.estimation.stream_delay import DELAY_WINDOWS, moving_windows, stream_delay_of
    rng = np.random.default_rng(5)
    t = np.arange(0.0, 600.0, 0.001) + 50.0
    cycle_starts = [37.0, 211.0, 402.5, 555.0]        # four 2.1 s load cycles in 10 min of holds
    load = np.zeros(t.size)
    for c in cycle_starts:
        inside = (t - 50.0 >= c) & (t - 50.0 < c + 2.1)
        load[inside] = [delayed_load(s) for s in t[inside] - 50.0 - c]
    f = load + rng.normal(0.0, 0.01, t.size)
    x = load / K + rng.normal(0.0, 2e-7, t.size)
    settings = LiveSettings.from_params({'delay_window_s': 5.0})
    windows = moving_windows(t, f, 5.0, DELAY_WINDOWS)
    assert len(windows) == DELAY_WINDOWS and windows == sorted(windows)
    for c in cycle_starts:  # every cycle lies (at least partly) in a chosen window
        assert any(start <= 50.0 + c + 1.0 < end for start, end in windows), (c, windows)
    none = np.zeros(t.size, np.int64)
    estimate, problem, values = stream_delay_of(settings, Samples(t, none, f), Samples(t + DELAY, none, x))
    assert estimate is not None and estimate.ok and estimate.delay_s == pytest.approx(DELAY, abs=0.5e-3)
    assert 'ms late' in problem and dict(values)['stream_delay_ok'] == 'false'  # 3 ms > max_stream_delay_s 2 ms
    flat = rng.normal(0.0, 0.01, t.size)
    estimate, problem, values = stream_delay_of(settings, Samples(t, none, flat),
                                                Samples(t + DELAY, none, rng.normal(0.0, 2e-7, t.size)))
    assert estimate is None and problem == '' and 'too little load change' in dict(values)['stream_delay_note']


def test_mount_and_delay_parameters_validated_on_start_and_on_change(rclpy_context):
    _, _, args = isolated_estimator()
    node = StiffnessEstimatorNode(context=rclpy_context, cli_args=args)
    for param, value, words in [('sensor_rotation', [0.0, 0.0, 0.0, 0.0], 'sensor_rotation = [0.0, 0.0, 0.0, 0.0]'),
                                ('sensor_rotation', [1.0, 2.0], 'sensor_rotation'),
                                ('sensor_position', [0.0, 0.1], 'sensor_position = [0.0, 0.1]'),
                                ('displacement_delay_s', 0.5, 'displacement_delay_s = 0.5'),
                                ('max_stream_delay_s', 0.0, 'max_stream_delay_s = 0.0'),
                                ('delay_window_s', 0.1, 'delay_window_s = 0.1')]:
        assert_refused(node, param, value, words)
    restarts = node.core.counters.fit_restarts
    assert node.set_parameters([Parameter('sensor_rotation', value=QUAT)])[0].successful
    assert node.core.counters.fit_restarts == restarts + 1 and node.core.settings.force_row() is not None
    assert node.set_parameters([Parameter('displacement_delay_s', value=0.003)])[0].successful
    assert node.core.settings.displacement_delay_s == 0.003 and node.core.counters.fit_restarts == restarts + 2
    with pytest.raises(ValueError, match='sensor_position'):
        StiffnessEstimatorNode(context=rclpy_context, cli_args=isolated_estimator()[2],
                               parameter_overrides=[Parameter('sensor_position', value=[0.0, float('nan'), 0.0])])
    node.destroy_node()
