"""The estimator tests' rig and probe: a test node playing load cell, LVDT and load program for a spring of known
stiffness (:class:`SyntheticRig`), a probe recording what stiffness_estimator publishes (:class:`EstimatorProbe`), and
running the two against an estimator in-process or in its own process. Used by test_estimator_node,
test_estimator_faults, test_estimator_wiring and test_rezero.
"""
from __future__ import annotations

import itertools
import os
import signal
import subprocess
import sys
import time

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PointStamped, WrenchStamped
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from std_msgs.msg import Float64, Float64MultiArray

from crane_stiffness.contract import topics
from crane_stiffness.estimation.sync import DISPLACEMENT, FORCE
from crane_stiffness.rosnode.qos import LATCHED_QOS, RELIABLE_QOS, SENSOR_QOS
from crane_stiffness.nodes.stiffness_estimator import VALUE_FIELDS, StiffnessEstimatorNode
from crane_stiffness.sim.sampling import SampleClock
from helpers import NS, PATIENCE_S, spin_until
from helpers.probe import ProbeNode

K = 1875.0   # N/m, true stiffness of the synthetic spring
C = 0.15     # N, load at zero displacement (an untared load cell)
NF = len(VALUE_FIELDS)
_ids = itertools.count()


def isolated_estimator(extra_remaps: dict[str, str] | None = None) -> tuple[str, str, list[str]]:
    """A unique node name, a topic prefix and cli_args remapping the estimator's topics under that prefix."""
    name = f'estimator_{os.getpid()}_{next(_ids)}'
    prefix = f'/{name}_t'
    args = ['--ros-args', '-r', f'__node:={name}']
    for topic in (topics.WRENCH_COMMAND, topics.REJECTED_COMMAND, topics.LOAD_CELL_WRENCH, topics.LVDT_DISPLACEMENT,
                  topics.LVDT_ZERO, topics.LOAD_CELL_TARE, topics.PREDICTED_AXIS_STIFFNESS, topics.STIFFNESS_ESTIMATE,
                  topics.STIFFNESS_VALUES, topics.PREDICTED_STIFFNESS,
                  topics.STIFFNESS, topics.DIAGNOSTICS):
        target = (extra_remaps or {}).get(topic, prefix + topic)
        args += ['-r', f'{topic}:={target}']
    return name, prefix, args


def row(data, branch: int) -> dict[str, float]:
    """One branch's fields (0 loading, 1 unloading) of a /stiffness/estimate_values message's data."""
    return dict(zip(VALUE_FIELDS, list(data)[branch * NF:(branch + 1) * NF]))


class SyntheticRig:
    """A test node playing load cell, LVDT and load program for a linear spring ``F = K·x + C``.

    The load is a triangle 0 → ``peak`` → 0 (``ramp_s`` each way) after ``lead_s`` at zero. Samples are taken on
    the grid 1/rate of the clock and published in bursts by a 100 Hz timer, like the simulated sensors; the
    command (optional) is published once per burst with the burst's first stamp. ``inject(i, t_ns)`` is called
    before sample i and may publish extra messages.

    ``paced_by(t_ns)``, if given, holds each burst back until it says the previous burst's newest sample (stamp
    ``t_ns``) got its estimate (at most ``pace_timeout_s`` of wall time; then the burst goes out, and the test's check
    of that estimate fails). A loaded machine then delays bursts instead of merging several into one estimate, so
    "every burst gets its estimate" holds at any speed.
    """

    def __init__(self, ctx, prefix: str, *, rate_hz: float = 500.0, peak: float = 4.0, ramp_s: float = 1.0,
                 lead_s: float = 0.1, force_noise: float = 0.02, x_noise: float = 2e-7, seed: int = 1,
                 force_topic: str | None = None, force_qos=SENSOR_QOS, volts_topic: str | None = None,
                 volts_gain: float = 1.0, volts_offset: float = 0.0, command: bool = True, inject=None,
                 burst_hz: float = 100.0, stamp_on_publish: bool = False, paced_by=None,
                 pace_timeout_s: float = PATIENCE_S):
        self.node = Node(f'rig{prefix.replace("/", "_")}', context=ctx)
        self.rng = np.random.default_rng(seed)
        self.peak, self.ramp_s, self.lead_s = peak, ramp_s, lead_s
        self.force_noise, self.x_noise = force_noise, x_noise
        self.gain, self.offset = volts_gain, volts_offset
        self.inject = inject
        self.paced_by, self.pace_timeout_s = paced_by, pace_timeout_s
        self.last_burst_wall = 0.0  # time.monotonic() of the last burst, s
        self.stamp_on_publish = stamp_on_publish
        self.pub_force = self.node.create_publisher(WrenchStamped, force_topic or prefix + topics.LOAD_CELL_WRENCH,
                                                    force_qos)
        if volts_topic:
            self.pub_volts = self.node.create_publisher(Float64, volts_topic, RELIABLE_QOS)
            self.pub_point = None
        else:
            self.pub_point = self.node.create_publisher(PointStamped, prefix + topics.LVDT_DISPLACEMENT,
                                                        SENSOR_QOS)
        self.pub_cmd = self.node.create_publisher(WrenchStamped, prefix + topics.WRENCH_COMMAND, RELIABLE_QOS) \
            if command else None
        # Every sample goes out, however long a loaded machine stalls this process (a SampleClock skips what is older
        # than its backlog, 0.5 s by default: two runs compared sample for sample would then differ); after a stall
        # the samples due go out at most MAX_BURST per tick, as a DAQ's buffer drains, so a burst never outruns the
        # estimator's queue in the same executor (best effort: what overflows it is lost).
        self.clock = SampleClock(rate_hz, max_backlog_s=3600.0)
        self.backlog: list[int] = []
        # Fault hooks (test_estimator_faults): which samples are published, the LVDT's zero, commands on or off.
        self.force_ok = lambda i: True
        self.force_map = lambda i, f: f
        # Sensor hooks (test_estimator_wiring): the platform wrench at the centre (crane_base) for a load F, what the
        # F/T sensor reports of it in its own frame, and how late the LVDT's stamps are [ns].
        self.platform = lambda f: (0.0, f, 0.0, 0.0, 0.0, 0.0)
        self.sensor = None
        self.disp_late_ns = 0
        self.disp_ok = lambda i: True
        self.x_offset = 0.0
        self.command_on = True
        self.start_ns: int | None = None
        self.sent = 0
        self.force_published = 0  # the rig's own samples published on each stream (not what ``inject`` adds)
        self.displacement_published = 0
        # Every message published on each stream (what ``inject`` adds too), counted by the publishers made here.
        self.force_sent = 0
        self.displacement_sent = 0
        self._count_publishes(self.pub_force, 'force_sent')
        self._count_publishes(self.pub_point or self.pub_volts, 'displacement_sent')
        self.burst_newest: list[int] = []  # stamp of the newest sample of every burst, ns
        self.done = False
        self.running = False
        self.node.create_timer(1.0 / burst_hz, self._tick)

    def start(self) -> None:
        self.running = True

    def _count_publishes(self, publisher, counter: str) -> None:
        publish = publisher.publish

        def counted(msg) -> None:
            setattr(self, counter, getattr(self, counter) + 1)
            publish(msg)
        publisher.publish = counted

    def load(self, t_s: float) -> float | None:
        t = t_s - self.lead_s
        if t < 0.0:
            return 0.0
        if t <= self.ramp_s:
            return self.peak * t / self.ramp_s
        if t <= 2 * self.ramp_s:
            return self.peak * (2 * self.ramp_s - t) / self.ramp_s
        return None

    def wrench_msg(self, t_ns: int, fy: float, wrench=None) -> WrenchStamped:
        """A WrenchStamped with force.y = fy, or with all six components of ``wrench``."""
        msg = WrenchStamped()
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(int(t_ns), NS)
        msg.header.frame_id = 'load_cell'
        if wrench is None:
            msg.wrench.force.y = float(fy)
        else:
            w = [float(v) for v in wrench]
            f, m = msg.wrench.force, msg.wrench.torque
            f.x, f.y, f.z, m.x, m.y, m.z = w
        return msg

    def point_msg(self, t_ns: int, x: float) -> PointStamped:
        msg = PointStamped()
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(int(t_ns), NS)
        msg.header.frame_id = 'lvdt'
        msg.point.x = float(x)
        return msg

    #: The most samples one tick sends (normally rate_hz / burst_hz: 5).
    MAX_BURST = 25

    def _tick(self) -> None:
        now_ns = self.node.get_clock().now().nanoseconds
        self.backlog += self.clock.due(now_ns).tolist()
        if (self.paced_by is not None and self.burst_newest and not self.paced_by(self.burst_newest[-1])
                and time.monotonic() - self.last_burst_wall < self.pace_timeout_s):
            return
        times = np.array(self.backlog[:self.MAX_BURST], dtype=np.int64)
        del self.backlog[:self.MAX_BURST]
        if not self.running or self.done or times.size == 0:
            return
        if self.stamp_on_publish:  # one sample per tick, stamped now (a driver stamping on receipt)
            times = np.array([now_ns])
        if self.start_ns is None:
            self.start_ns = int(times[0])
        if self.pub_cmd is not None and self.command_on:
            first = self.load((int(times[0]) - self.start_ns) / NS)
            if first is not None:
                self.pub_cmd.publish(self.wrench_msg(int(times[0]), first, self.platform(first)))
        newest: int | None = None
        for t_ns in times.tolist():
            f = self.load((t_ns - self.start_ns) / NS)
            if f is None:
                # The program ended inside this burst: its newest sample is the last one sent, not times[-1].
                self.done = True
                break
            if self.inject is not None:
                self.inject(self, self.sent, t_ns)
            x = (f - C) / K + self.rng.normal(0.0, self.x_noise) - self.x_offset
            measured = self.force_map(self.sent, f + self.rng.normal(0.0, self.force_noise))
            wrench = self.platform(measured)
            force_msg = self.wrench_msg(t_ns, measured, wrench if self.sensor is None else self.sensor(wrench))
            if self.force_ok(self.sent):
                self.pub_force.publish(force_msg)
                self.force_published += 1
            if self.pub_point is not None:
                if self.disp_ok(self.sent):
                    self.pub_point.publish(self.point_msg(t_ns + self.disp_late_ns, x))
                    self.displacement_published += 1
            else:
                self.pub_volts.publish(Float64(data=(x - self.offset) / self.gain))
                self.displacement_published += 1
            self.sent += 1
            newest = int(t_ns)
        if newest is not None:
            self.burst_newest.append(newest)
            self.last_burst_wall = time.monotonic()


class EstimatorProbe(ProbeNode):
    """Records the estimator's outputs; publishes the latched model prediction."""

    def __init__(self, ctx, prefix: str):
        super().__init__(ctx, prefix)
        self.values: list[tuple[int, list[float]]] = []  # (publication time at the estimator ns, data)
        self.sample_stamps_us: set[int] = set()  # the sample_stamp of every estimate received, µs
        self.node.create_subscription(Float64MultiArray, prefix + topics.STIFFNESS_VALUES, self._on_values, SENSOR_QOS)
        self.stiffness: list[float] = self.record(topics.STIFFNESS, Float64, RELIABLE_QOS, lambda m: m.data)
        self.estimates: list[DiagnosticArray] = self.record(topics.STIFFNESS_ESTIMATE, DiagnosticArray, RELIABLE_QOS)
        self.pub_prediction = self.publisher(topics.PREDICTED_AXIS_STIFFNESS, Float64, LATCHED_QOS)
        self.pub_tangent = self.publisher(topics.PREDICTED_STIFFNESS, Float64MultiArray, LATCHED_QOS)

    def _on_values(self, msg: Float64MultiArray, info: dict) -> None:
        self.values.append((info['source_timestamp'], list(msg.data)))
        stamp = row(msg.data, 0)['sample_stamp']
        if np.isfinite(stamp):  # NaN before the first pair
            self.sample_stamps_us.add(round(stamp * 1e6))

    def has_estimate_of(self, t_ns: int) -> bool:
        """Whether an estimate received has the sample of stamp ``t_ns`` as its newest (µs: exact enough for a grid
        of whole ms; the stamp travels as float64 seconds)."""
        return round(t_ns * 1e-3) in self.sample_stamps_us

    def has_newest_values_of(self, estimator: StiffnessEstimatorNode) -> bool:
        """Whether the newest /stiffness/estimate_values received is the newest ``estimator`` published (NaN fields
        equal)."""
        return bool(self.values) and np.array_equal(np.asarray(self.values[-1][1]),
                                                     np.asarray(estimator.values_msg.data), equal_nan=True)

    def last(self, branch: int) -> dict[str, float]:
        return row(self.values[-1][1], branch)


def executor_with(ctx, *nodes) -> SingleThreadedExecutor:
    """A single-threaded executor in ``ctx`` spinning ``nodes``."""
    ex = SingleThreadedExecutor(context=ctx)
    for n in nodes:
        ex.add_node(n)
    return ex


def run_program(ex, rig: SyntheticRig, estimator: StiffnessEstimatorNode, timeout_s: float = PATIENCE_S,
                probe: EstimatorProbe | None = None) -> None:
    """Wait for the connections, play the program, then let the estimator drain its queue; with ``probe``, until the
    probe has received the newest estimate the estimator published (``timeout_s``: the wait for the program) [s]."""
    assert spin_until(ex, lambda: rig.pub_force.get_subscription_count() >= 1
                      and (rig.pub_point or rig.pub_volts).get_subscription_count() >= 1
                      and (rig.pub_cmd is None or rig.pub_cmd.get_subscription_count() >= 1), PATIENCE_S)
    rig.start()
    assert spin_until(ex, lambda: rig.done, timeout_s)
    wait_drained(ex, rig, estimator, probe)


def wait_drained(ex, rig: SyntheticRig, estimator: StiffnessEstimatorNode, probe: EstimatorProbe | None = None) -> None:
    """After the rig's program: until every message the rig published (its samples and what ``inject`` added) has
    reached the in-process estimator and, with ``probe``, the probe has the newest estimate the estimator published.

    A loaded machine delivers the last bursts late (a 2 s wait once read an estimate 56 pairs short). Not asserted:
    best-effort DDS may lose one, and the test's own checks then say what is missing. The estimator fits each sample
    as it arrives and publishes its values as it fits."""
    c = estimator.core.counters
    spin_until(ex, lambda: c.force_received >= max(rig.force_published, rig.force_sent)
               and c.displacement_received >= max(rig.displacement_published, rig.displacement_sent), PATIENCE_S)
    if probe is not None:
        spin_until(ex, lambda: probe.has_newest_values_of(estimator), PATIENCE_S)


def assert_refused(node, param: str, value, words: str) -> None:
    """Setting ``param`` to ``value`` is refused with a reason containing ``words``; the old value stays."""
    old = node.get_parameter(param).value
    result = node.set_parameters([Parameter(param, value=value)])[0]
    assert not result.successful, param
    assert words in result.reason, result.reason
    now = node.get_parameter(param).value
    if isinstance(old, (list, tuple)) or hasattr(old, 'tolist'):
        assert list(now) == list(old)
    else:
        assert now == old


def run_in_own_process(ctx, rig: SyntheticRig, args: list[str], nodes=(), ready=lambda: True,
                       settled=lambda: True) -> subprocess.CompletedProcess:
    """The estimator as deployed, in its own process (``python -m``), fed by ``rig`` (and watched by ``nodes``):
    wait for the rig's connections and ``ready``, play the program, wait for ``settled`` (what the estimator must
    have done before it is stopped, seen by ``nodes``), then SIGINT. Every wait has the suite's patience. Returns the
    process's exit status, stdout and stderr (bytes)."""
    proc = subprocess.Popen([sys.executable, '-m', 'crane_stiffness.nodes.stiffness_estimator'] + args,
                            env=dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path)),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    ex = executor_with(ctx, *nodes, rig.node)
    try:
        assert spin_until(ex, lambda: rig.pub_force.get_subscription_count() >= 1
                          and rig.pub_point.get_subscription_count() >= 1 and rig.pub_cmd.get_subscription_count() >= 1
                          and ready(), PATIENCE_S)
        rig.start()
        assert spin_until(ex, lambda: rig.done, PATIENCE_S)
        if rig.paced_by is not None:  # the last burst's estimate, before the estimator is stopped
            spin_until(ex, lambda: rig.paced_by(rig.burst_newest[-1]), rig.pace_timeout_s)
        spin_until(ex, settled, PATIENCE_S)  # not asserted: the test's own checks say what is missing
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            out, err = proc.communicate(timeout=PATIENCE_S)
        except subprocess.TimeoutExpired:
            proc.kill()
            out, err = proc.communicate()
        ex.shutdown()
    return subprocess.CompletedProcess(proc.args, proc.returncode, out, err)


def statuses(array) -> tuple[list, object]:
    """(the branch statuses, the input status) of one /stiffness/estimate DiagnosticArray."""
    return list(array.status[:2]), array.status[2]


def identity(c: dict[str, int]) -> None:
    """Every message the estimator received is accounted for in its final counters."""
    for s in (FORCE, DISPLACEMENT):
        used_or_dropped = (c[f'{s}_dropped'] + c[f'{s}_paired'] + c[f'{s}_out_of_order'] + c[f'{s}_non_finite']
                           + c[f'{s}_stale'] + c[f'{s}_unmatched'] + c[f'{s}_discarded'] + c[f'{s}_pending'])
        assert c[f'{s}_received'] == used_or_dropped, (s, c)
        assert c[f'{s}_received'] == c[f'{s}_dropped'] + c[f'{s}_passed_checks'], (s, c)
    assert c['pairs'] == c['pairs_fitted'] + c['pairs_rejected_command'] + c['pairs_non_finite'], c
    assert c['command_received'] == c['command_used'] + c['command_rejected'] + c['command_dropped'], c

