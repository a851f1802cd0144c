"""stiffness_estimator in-process: synthetic sensor data of known stiffness from test nodes (helpers.estimator), real
rclpy and DDS.

Every estimator under test gets its own node name and topic names (remapped), so tests cannot hear each other.
"""
from __future__ import annotations

import itertools
import math
import os
from pathlib import Path

os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')  # normally set by conftest.py already
os.environ.setdefault('ROS_DOMAIN_ID', str(os.getpid() % 100 + 1))

import numpy as np  # noqa: E402
import pytest  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from std_msgs.msg import Float64, Float64MultiArray  # noqa: E402

from helpers import PATIENCE_S, call_trigger as call  # noqa: E402
from helpers import spin_until  # noqa: E402
from helpers.estimator import (C, K, EstimatorProbe, SyntheticRig, assert_refused, executor_with,  # noqa: E402
                               isolated_estimator, row, run_in_own_process, run_program)
from crane_stiffness.contract import topics  # noqa: E402
from crane_stiffness.model.stiffness import axis_stiffness  # noqa: E402
from crane_stiffness.params.files import load_params  # noqa: E402
from crane_stiffness.nodes import stiffness_estimator  # noqa: E402
from crane_stiffness.nodes.stiffness_estimator import StiffnessEstimatorNode  # noqa: E402
from crane_stiffness.launcher.rig import ros_args  # noqa: E402
from crane_stiffness.launcher.rig_description import NODES as RIG_NODES, rig_nodes  # noqa: E402

pytestmark = pytest.mark.ros  # every test here starts ROS (conftest)

_ids = itertools.count()


def latencies_ms(probe: EstimatorProbe, rig: SyntheticRig) -> np.ndarray:
    """Per burst: when the estimator published the first estimate including the burst's newest sample (the DDS
    source timestamp, system clock) minus that sample's stamp, ms."""
    first_seen: dict[int, int] = {}
    for t_published, data in probe.values:
        stamp = round(row(data, 0)['sample_stamp'] * 1e6)  # µs, exact enough for a grid of whole ms
        first_seen.setdefault(stamp, t_published)
    out = [first_seen[round(t * 1e-3)] - t for t in rig.burst_newest if round(t * 1e-3) in first_seen]
    return np.array(out) * 1e-6


def test_known_stiffness_interval_prediction_outputs_and_reset(rclpy_context):
    name, prefix, args = isolated_estimator()
    probe = EstimatorProbe(rclpy_context, prefix)
    # The model's tangent, latched before the estimator exists: the prediction is its stiffness along the fitted
    # axis (fy), whatever axis the model's single-axis prediction follows (here another one's, ignored).
    tangent = np.diag([1500.0, 1800.0, 9.9e5, 40.0, 40.0, 5.0])
    tangent[1, 3] = tangent[3, 1] = 10.0
    prediction = axis_stiffness(tangent, 'fy')
    probe.pub_tangent.publish(Float64MultiArray(data=[float(v) for v in tangent.ravel()]))
    probe.pub_prediction.publish(Float64(data=9.9e5))
    estimator = StiffnessEstimatorNode(context=rclpy_context, cli_args=args, parameter_overrides=[
        Parameter('window', value=600), Parameter('diagnostics_rate_hz', value=5.0)])
    rig = SyntheticRig(rclpy_context, prefix, rate_hz=500.0, seed=7)
    ex = executor_with(rclpy_context, estimator, probe.node, rig.node)
    run_program(ex, rig, estimator, probe=probe)
    # The numbers below are those of every sample: the estimate whose newest pair is the rig's last sample (a
    # loaded machine delivers the last bursts late; an estimate read before them counted 444 pairs of ~500).
    assert spin_until(ex, lambda: probe.has_estimate_of(rig.burst_newest[-1]), PATIENCE_S), \
        (rig.sent, estimator.core.counters.pairs_fitted)
    assert spin_until(ex, lambda: len(probe.estimates) >= 2, PATIENCE_S)
    loading, unloading = probe.last(0), probe.last(1)
    for r in (loading, unloading):
        print(f'k = {r["stiffness"]:.2f} N/m (95 %: {r["ci95_low"]:.2f} .. {r["ci95_high"]:.2f}), '
              f'rls {r["rls_stiffness"]:.2f}, n = {r["n"]:.0f}, true {K}')
        assert r['stiffness'] == pytest.approx(K, rel=0.01)
        assert r['ci95_low'] < K < r['ci95_high']
        assert r['ci95_high'] - r['ci95_low'] < 0.01 * K
        assert r['rls_stiffness'] == pytest.approx(K, rel=0.02)
        assert r['intercept'] == pytest.approx(C, abs=0.01)
        assert r['r2'] > 0.999
        assert r['n'] > 450
        assert r['prediction'] == prediction and prediction < 1800.0  # (the coupling to mx softens fy)
        assert r['relative_error'] == pytest.approx((r['stiffness'] - prediction) / prediction, rel=1e-12)
    assert unloading['current'] == 1.0 and loading['current'] == 0.0
    assert probe.stiffness[-1] == loading['stiffness']
    counters = estimator.core.counters
    assert counters.dropped == 0 and estimator.core.sync_counters.total('out_of_order') == 0
    assert counters.pairs_fitted >= rig.sent - 2
    # The DiagnosticArray for people: one status per branch plus the input status. The rig has stopped: its
    # newest report is the one after the estimator noticed the silence (min_silence_s after the last sample; on a
    # loaded machine that report comes late, so wait for it, up to 5 s).
    spin_until(ex, lambda: probe.estimates[-1].status[0].level == b'\x03', PATIENCE_S)
    last = probe.estimates[-1]
    assert [s.name for s in last.status] == [f'/{name}: loading', f'/{name}: unloading', f'/{name}: input']
    kv = {k.key: k.value for k in last.status[0].values}
    for key in ('stiffness', 'intercept', 'stderr', 'ci95_low', 'ci95_high', 'r2', 'n', 'nonlinearity',
                'rls_stiffness', 'prediction', 'relative_error'):
        assert key in kv
    assert float(kv['stiffness']) == pytest.approx(loading['stiffness'], rel=1e-5)
    assert abs(float(kv['nonlinearity'])) < 0.05 and 'N/m' in last.status[0].message
    # The rig stopped at the program's end: its streams are silent, the estimate is frozen, STALE (never OK), the
    # input status ERROR; while the rig ran, the estimate was OK.
    assert last.status[0].level == last.status[1].level == b'\x03', last.status[0].message
    assert 'silent' in last.status[0].message and last.status[2].level == b'\x02'
    assert any(a.status[0].level == b'\x00' for a in probe.estimates)
    inputs = {k.key: k.value for k in last.status[2].values}
    assert int(inputs['pairs_fitted']) == counters.pairs_fitted
    # The estimator's own lag (publication − newest pair stamp) over every estimate it published: the rig's
    # bursts are 10 ms apart, so the lag is positive and its percentiles ordered; no bound (machine load).
    lag = {k: float(inputs[f'lag_{k}_ms']) for k in ('p50', 'p99', 'max')}
    assert int(inputs['lag_n']) > 0 and estimator.core.lag.n >= len(probe.values) > 0
    assert 0.0 < lag['p50'] <= lag['p99'] <= lag['max'] + 0.1
    print(f'estimator lag in-process: {lag} ms over {inputs["lag_n"]} estimates')
    # ~/reset clears the fits.
    reply = call(ex, probe.node, f'/{name}/reset')
    assert reply.success and 'cleared' in reply.message
    assert spin_until(ex, lambda: math.isnan(probe.last(0)['stiffness']), PATIENCE_S)
    assert math.isnan(probe.last(1)['stiffness'])
    ex.shutdown()


def test_estimator_in_its_own_process_keeps_up_with_1khz(rclpy_context):
    """As deployed: the node runs in its own process (``python -m``), sensors at 1 kHz in 200 Hz bursts; every burst
    gets an estimate that includes its newest sample, and the estimates are right.

    The latency figures (stamp of the newest sample to the estimate) are printed here and measured properly, against
    a same-run baseline, by benchmarks/bench_rig.py: a timing bound would make this test depend on machine load.
    """
    name, prefix, args = isolated_estimator()
    probe = EstimatorProbe(rclpy_context, prefix)
    # Ready once the probe has received a periodic /stiffness/estimate from the estimator: that proves its writers
    # (created with the values writer, announced after it) matched the probe's readers, which the graph
    # (count_publishers) does not; an estimate published before that match would be lost, not late.
    rig = SyntheticRig(rclpy_context, prefix, rate_hz=1000.0, burst_hz=200.0, ramp_s=0.75, seed=3,
                       paced_by=probe.has_estimate_of)
    done = run_in_own_process(rclpy_context, rig, args, nodes=[probe.node],
                              ready=lambda: probe.node.count_publishers(prefix + topics.STIFFNESS_VALUES) >= 1
                              and len(probe.estimates) > 0)
    assert done.returncode == 0, done.stderr.decode()[-2000:]
    lat = latencies_ms(probe, rig)
    bursts = len(rig.burst_newest)
    print(f'latency at 1 kHz (200 Hz bursts, own process): median {np.median(lat):.2f} ms, '
          f'p95 {np.percentile(lat, 95):.2f} ms, max {lat.max():.2f} ms, n = {len(lat)} of {bursts} bursts; '
          f'{len(probe.values)} values messages, {len(probe.estimates)} periodic estimates; '
          f'k = {probe.last(0)["stiffness"]:.1f} N/m')
    # Every burst, held back until the one before it had its estimate, has one of its own; and they come once per
    # drained batch, not with the periodic /stiffness/estimate (diagnostics_rate_hz, 5 Hz), which would hold the rig
    # to the timer's pace: several values messages for each periodic estimate, at any speed the round trip allows.
    assert len(lat) == bursts, (len(lat), bursts)
    assert len(probe.values) > 3 * len(probe.estimates), (len(probe.values), len(probe.estimates))
    assert probe.last(0)['stiffness'] == pytest.approx(K, rel=0.01)
    assert probe.last(1)['stiffness'] == pytest.approx(K, rel=0.01)


def test_driver_like_inputs_by_remapping_reliable_wrench_and_volts_channel(rclpy_context):
    """A vendor F/T driver (own topic, RELIABLE depth 100) and a DAQ volts channel, plugged in by remapping only."""
    gain, offset = 0.002, -0.001  # m/V, m: 0 V = -1 mm, 1 V = +1 mm
    tag = f'{os.getpid()}_{next(_ids)}'
    ft_topic, daq_topic = f'/ft_sensor_{tag}/data', f'/daq_{tag}/ch0'
    name, prefix, args = isolated_estimator({topics.LOAD_CELL_WRENCH: ft_topic, topics.LVDT_DISPLACEMENT: daq_topic})
    probe = EstimatorProbe(rclpy_context, prefix)
    estimator = StiffnessEstimatorNode(context=rclpy_context, cli_args=args, parameter_overrides=[
        Parameter('displacement_type', value='float64'), Parameter('displacement_gain', value=gain),
        Parameter('displacement_offset', value=offset), Parameter('slop_s', value=0.004),
        Parameter('window', value=300), Parameter('hysteresis', value=0.15)])
    driver_qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100, reliability=ReliabilityPolicy.RELIABLE)
    # One sample per 10 ms tick: the volts channel is stamped on arrival, so it must not come in bursts.
    rig = SyntheticRig(rclpy_context, prefix, rate_hz=100.0, burst_hz=100.0, ramp_s=1.5, force_topic=ft_topic,
                       force_qos=driver_qos, volts_topic=daq_topic, volts_gain=gain, volts_offset=offset,
                       command=False, seed=5, stamp_on_publish=True)
    ex = executor_with(rclpy_context, estimator, probe.node, rig.node)
    run_program(ex, rig, estimator, probe=probe)
    loading, unloading = probe.last(0), probe.last(1)
    sc = estimator.core.sync_counters
    print(f'driver-like: loading {loading["stiffness"]:.1f} N/m, unloading {unloading["stiffness"]:.1f} N/m, '
          f'{sc.pairs} pairs of {rig.sent} samples, unmatched {sc.total("unmatched")}')
    assert sc.pairs >= 0.9 * rig.sent
    for r in (loading, unloading):
        assert r['stiffness'] == pytest.approx(K, rel=0.02)
        assert r['intercept'] == pytest.approx(C, abs=0.02)
    ex.shutdown()


def test_nan_inf_absurd_zero_stamp_and_malformed_messages_dropped_counted_estimates_go_on(rclpy_context):
    injected = {'non_finite': 0, 'absurd': 0, 'zero_stamp': 0, 'malformed': 0}

    def inject(rig: SyntheticRig, i: int, t_ns: int) -> None:
        if i % 40 != 20:
            return
        rig.pub_force.publish(rig.wrench_msg(t_ns - 300_000, math.nan))
        rig.pub_point.publish(rig.point_msg(t_ns - 300_000, math.inf))
        rig.pub_force.publish(rig.wrench_msg(t_ns - 200_000, -math.inf))
        injected['non_finite'] += 3
        rig.pub_force.publish(rig.wrench_msg(t_ns - 100_000, 5e4))       # above max_abs_force
        rig.pub_point.publish(rig.point_msg(t_ns - 100_000, 0.5))        # above max_abs_displacement
        injected['absurd'] += 2
        rig.pub_force.publish(rig.wrench_msg(0, 1.0))                    # zero stamp
        rig.pub_point.publish(rig.point_msg(0, 1e-4))
        injected['zero_stamp'] += 2
        rig.pub_force.publish(b'\x00\x01\x00\x00\x05\x00')             # serialized, cut short
        rig.pub_point.publish(b'\x00\x01\x00\x00' + bytes(12))       # a header without its point
        injected['malformed'] += 2

    name, prefix, args = isolated_estimator()
    probe = EstimatorProbe(rclpy_context, prefix)
    estimator = StiffnessEstimatorNode(context=rclpy_context, cli_args=args, parameter_overrides=[
        Parameter('window', value=600)])
    rig = SyntheticRig(rclpy_context, prefix, rate_hz=500.0, inject=inject, seed=9, paced_by=probe.has_estimate_of)
    ex = executor_with(rclpy_context, estimator, probe.node, rig.node)
    run_program(ex, rig, estimator, probe=probe)
    spin_until(ex, lambda: probe.has_estimate_of(rig.burst_newest[-1]), PATIENCE_S)
    c = estimator.core.counters
    print(f'injected {injected}; counted non_finite {c.dropped_non_finite}, absurd {c.dropped_absurd}, '
          f'zero_stamp {c.dropped_zero_stamp}, malformed {c.dropped_malformed}; fitted {c.pairs_fitted} of '
          f'{rig.sent}')
    assert injected['non_finite'] >= 60
    assert (c.dropped_non_finite, c.dropped_absurd, c.dropped_zero_stamp, c.dropped_malformed) == (
        injected['non_finite'], injected['absurd'], injected['zero_stamp'], injected['malformed'])
    assert c.pairs_fitted >= rig.sent - 2
    # Estimates kept coming all along: every burst of samples (each held back until the one before it had its
    # estimate), the last one included, got an estimate whose newest sample is the burst's newest.
    missing = [t for t in rig.burst_newest if not probe.has_estimate_of(t)]
    assert rig.burst_newest and not missing, (len(missing), len(rig.burst_newest))
    assert probe.last(0)['stiffness'] == pytest.approx(K, rel=0.01)
    assert probe.last(1)['stiffness'] == pytest.approx(K, rel=0.01)
    assert spin_until(ex, lambda: any(s.name.endswith('input') and s.level == b'\x01' and 'dropped' in s.message
                                      for a in probe.estimates for s in a.status), PATIENCE_S)
    ex.shutdown()


def test_out_of_order_and_dropout_flagged_never_fitted(rclpy_context):
    late = {'n': 0}

    def inject(rig: SyntheticRig, i: int, t_ns: int) -> None:
        if i % 50 == 25:  # a late pair, 30 ms old, with values that would wreck the fit
            rig.pub_force.publish(rig.wrench_msg(t_ns - 30_000_000, 30.0))
            rig.pub_point.publish(rig.point_msg(t_ns - 30_000_000, -0.004))
            late['n'] += 1

    name, prefix, args = isolated_estimator()
    probe = EstimatorProbe(rclpy_context, prefix)
    estimator = StiffnessEstimatorNode(context=rclpy_context, cli_args=args, parameter_overrides=[
        Parameter('window', value=600), Parameter('expected_period_s', value=0.002)])
    rig = SyntheticRig(rclpy_context, prefix, rate_hz=500.0, inject=inject, seed=13)
    ex = executor_with(rclpy_context, estimator, probe.node, rig.node)
    run_program(ex, rig, estimator, probe=probe)
    sc = estimator.core.sync_counters
    print(f'late pairs sent {late["n"]}: out_of_order force {sc.force.out_of_order}, '
          f'displacement {sc.displacement.out_of_order}; fitted {estimator.core.counters.pairs_fitted} of {rig.sent}')
    assert late['n'] >= 15
    assert sc.force.out_of_order == late['n'] and sc.displacement.out_of_order == late['n']
    assert estimator.core.counters.pairs_fitted <= rig.sent
    for branch in (0, 1):
        r = probe.last(branch)
        assert r['stiffness'] == pytest.approx(K, rel=0.01) and r['r2'] > 0.999
    # Dropouts: the streams stopped when the program ended (0.3 s ago at least) and stop again for 50 ms (25
    # periods).
    assert sc.total('dropouts') == 0
    fitted = estimator.core.counters.pairs_fitted
    now = rig.node.get_clock().now
    assert spin_until(ex, lambda: now().nanoseconds >= rig.burst_newest[-1] + 300_000_000, PATIENCE_S)
    t0 = now().nanoseconds // 2_000_000 * 2_000_000
    for t_ns in (t0, t0 + 50_000_000):
        rig.pub_force.publish(rig.wrench_msg(t_ns, 1.0))
        rig.pub_point.publish(rig.point_msg(t_ns, (1.0 - C) / K))
    assert spin_until(ex, lambda: estimator.core.sync_counters.force.dropouts == 2
                      and estimator.core.sync_counters.displacement.dropouts == 2, PATIENCE_S)
    assert spin_until(ex, lambda: estimator.core.counters.pairs_fitted >= fitted + 2, PATIENCE_S)
    assert estimator.core.sync_counters.total('dropouts') == 4
    assert estimator.core.counters.pairs_fitted == fitted + 2  # flagged, and still paired
    ex.shutdown()


def test_parameters_validated_on_start_and_on_change(rclpy_context, capsys):
    name, prefix, args = isolated_estimator()
    estimator = StiffnessEstimatorNode(context=rclpy_context, cli_args=args)
    for param, value, words in [('force_axis', 'fq', "force_axis = 'fq'"), ('window', 2, 'window = 2'),
                                ('slop_s', -0.001, 'slop_s = -0.001'), ('max_age_s', 0.0001, 'max_age_s'),
                                ('displacement_type', 'analog', "displacement_type = 'analog'"),
                                ('forgetting', 1.5, 'forgetting = 1.5'),
                                ('diagnostics_rate_hz', 0.0, 'diagnostics_rate_hz = 0.0'),
                                ('displacement_gain', 0.0, 'displacement_gain = 0.0')]:
        assert_refused(estimator, param, value, words)
    assert estimator.core.settings.window == 500 and estimator.core.settings.force_axis == 'fy'
    # Accepted changes take effect (a threshold keeps the fit, a fit setting restarts it).
    assert estimator.set_parameters([Parameter('nonlinearity_warn', value=0.3)])[0].successful
    assert estimator.core.settings.nonlinearity_warn == 0.3 and estimator.core.counters.fit_restarts == 0
    assert estimator.set_parameters_atomically([Parameter('force_axis', value='mz'),
                                                Parameter('window', value=200)]).successful
    assert estimator.core.settings.force_axis == 'mz' and estimator.core.counters.fit_restarts == 1
    assert estimator.set_parameters([Parameter('displacement_type', value='float64')])[0].successful
    assert estimator.count_subscribers(prefix + topics.LVDT_DISPLACEMENT) == 1
    # Bad start-up values stop the node with the reason.
    with pytest.raises(ValueError, match='window = 1'):
        StiffnessEstimatorNode(context=rclpy_context, cli_args=isolated_estimator()[2],
                               parameter_overrides=[Parameter('window', value=1)])
    assert stiffness_estimator.main(['--ros-args', '-p', 'slop_s:=-1.0']) == 2
    assert 'slop_s = -1.0' in capsys.readouterr().err
    estimator.destroy_node()


def test_sensors_yaml_sets_every_estimator_parameter_with_its_declared_type(rclpy_context):
    """Every parameter but those the rig sets per run: a value in the node's own section of a parameter file beats
    the rig's ``-p`` (seen with rclpy 7.1.6), so a file must not set them (test below)."""
    path = Path(__file__).resolve().parents[2] / 'config' / 'sensors.yaml'
    values = load_params(path, 'stiffness_estimator')
    set_by_the_rig = {node.six_axis_parameter for node in RIG_NODES if node.six_axis_parameter}
    assert set_by_the_rig == {'six_axis_program'}
    assert set(values) == {spec.name for spec in stiffness_estimator.PARAMS} - set_by_the_rig
    node = StiffnessEstimatorNode(context=rclpy_context, cli_args=['--ros-args', '--params-file', str(path)])
    for name, value in values.items():
        assert node.get_parameter(name).value == value, name
    node.destroy_node()


@pytest.mark.parametrize('program,six', [('full6', True), ('side_force', False)])
def test_the_rig_tells_the_estimator_whether_its_program_is_six_axis(rclpy_context, program, six):
    """With exactly the arguments the rig starts it with (its parameter files, then the rig's own values)."""
    config = Path(__file__).resolve().parents[2] / 'config'
    start = {n.name: n for n in rig_nodes(config, {'program': program})}['stiffness_estimator']
    node = StiffnessEstimatorNode(context=rclpy_context, cli_args=ros_args(start))
    assert node.get_parameter('six_axis_program').value is six
    node.destroy_node()
