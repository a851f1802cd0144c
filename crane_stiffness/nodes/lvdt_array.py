"""lvdt_array: the platform pose from an array of n >= 6 LVDTs, for a lab with displacement sensors only (a thin
adapter around crane_stiffness.full6.lvdt_array.LvdtArray).

Subscribes one reading topic per LVDT (``topics``; geometry_msgs/PointStamped, point.x = the reading [m], as the lvdt
and modbus_lvdt nodes publish on /lvdt/displacement; six lvdt nodes remapped to /lvdt_1/displacement ... in the lab
config, config/lvdt_array_lab.yaml). LVDT i touches the platform at ``contact_points`` row i (body frame [m]) and
measures along ``directions`` row i (crane_base, normalised), zeroed at the rest pose (``rest_position``,
``rest_orientation``), with white noise ``noise_std`` [m].

**Grouping rule.** The readings of one sample instant carry the same header stamp (LVDTs sampled on one clock grid, as
the simulated ones are; ``stamp_tolerance_s`` > 0 lets stamps of one instant differ by up to that from the group's
first reading, for DAQs stamping each channel itself: keep it below half the sample period). A group is solved once
it holds one reading of every LVDT, and only then: its pose is stamped with the mean of its readings' stamps. A group
still missing a reading is dropped (counted ``groups_incomplete``, never published) when a later group completes
(each LVDT's stream arrives in stamp order, so the missing reading was lost) or when a reading stamped more than
``max_wait_s`` after it arrives (an LVDT that went silent). A reading stamped at or before the last completed
instant (+ tolerance) is late and dropped (``late_readings``), a second reading of one LVDT for one instant too
(``duplicate_readings``), and a non-finite one (``dropped_non_finite``): each leaves its group incomplete. No pose
is ever made of readings of different instants or of fewer than every LVDT. At start, until every LVDT delivers
(each starts sampling at its first pose, and DDS matches each stream in its own time), the instants only some have
read are dropped so: a WARN on /diagnostics for a report or two.

The complete groups are solved together at ``publish_rate_hz`` (LvdtArray.solve of a batch: exact rigid motion by
Gauss-Newton, ~25 times cheaper per group than one at a time) and published as

- /pose_sensor/pose (PoseStamped, sensor QoS, frame ``frame_id``): as the pose_sensor node and a motion-capture
  tracker publish it, so stiffness6_estimator takes it unchanged: the centre at ``rest_position`` + δu [m] and the
  orientation exp([δθ]×)·R0 (quaternion [x, y, z, w], body -> crane_base), d = [δu, δθ] the solved deflection
  (crane_stiffness.full6.deflection: δθ in the fixed frame, applied on the left of the rest orientation R0);
- /lvdt_array/pose (PoseWithCovarianceStamped, sensor QoS, the same pose and stamp) with the covariance of d: the
  LVDTs' noise propagated to first order at the solution, 6×6 row-major in the order x y z, rotation about the fixed
  x y z [m², m·rad, rad²].

The arrangement is checked at start and on every change (LvdtArray): fewer than six LVDTs, a motion no LVDT sees or a
condition number above ``max_condition`` is refused with the error naming the arrangement (``arrangement``) and the
motion. ``topics`` is read at start only. The node runs on the node clock's timers only to batch the solving: its
output depends on the stamps alone. It is no participant of the simulated-time lockstep
(crane_stiffness.sim.lockstep): on simulated time use the pose_sensor node.

/diagnostics: the counters, ``residual_rms_m`` (of the last batch's readings against the solved pose: several times
the noise means an LVDT off its line, a wrong arrangement or a bad zero), ``condition_number``, ``open_groups``.
Counters (and FINAL_COUNTERS): received = used + dropped_non_finite + late_readings + duplicate_readings (readings);
groups_complete = published (poses) + groups still waiting to be solved.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from geometry_msgs.msg import PointStamped, PoseStamped, PoseWithCovarianceStamped
from rclpy.node import Node

from crane_stiffness.contract import topics
from crane_stiffness.full6.errors import ArrangementError
from crane_stiffness.full6.lvdt_array import LAB_LVDT_NOISE, MAX_CONDITION, LvdtArray, lab_arrangement
from crane_stiffness.model.rotation import quaternion_multiply, quaternion_to_matrix, rotvec_to_quaternion
from crane_stiffness.params.spec import ParamSpec
from crane_stiffness.rosnode.device_params import check_start_only
from crane_stiffness.rosnode.diagnostics import Counters, Diagnostics
from crane_stiffness.rosnode.messages import pose_stamped
from crane_stiffness.rosnode.parameters import Params, check, valid_topic_name
from crane_stiffness.rosnode.qos import sensor_qos
from crane_stiffness.rosnode.run import run
from crane_stiffness.rosnode.sim_time import uses_sim_time
from crane_stiffness.serde.cdr import CdrError, decode_stamped
from crane_stiffness.sim.pose_sensor import normalised
from crane_stiffness.contract.status import OK, WARN
from crane_stiffness.sim.calibration import LVDT_CALIBRATION_PARAMS, LVDT_COMPONENTS, calibration_of

_LAB = lab_arrangement()
PARAMS = (
    ParamSpec('topics', [f'/lvdt_{i}/displacement' for i in range(1, 7)], "the LVDTs' reading topics "
              '(geometry_msgs/PointStamped, point.x = reading [m]), one per LVDT in the order of contact_points and '
              'directions; read at start only [-]'),
    ParamSpec('contact_points', _LAB.contact_points.ravel().tolist(), "each LVDT's contact point on the platform, "
              'body frame from its centre, x y z per LVDT (3 numbers each) [m]'),
    ParamSpec('directions', _LAB.directions.ravel().tolist(), "each LVDT's measuring direction (its reading grows "
              'along it), crane_base, x y z per LVDT (3 numbers each, normalised) [-]'),
    ParamSpec('noise_std', [LAB_LVDT_NOISE], "the LVDTs' white-noise standard deviation: one number for all, or one "
              'per LVDT; > 0 [m]'),
    ParamSpec('arrangement', _LAB.name, "the arrangement's name, in its errors and on /diagnostics [-]"),
    ParamSpec('max_condition', MAX_CONDITION, 'largest condition number of an accepted arrangement (the noise-weighted '
              'Jacobian, rotations at the RMS lever arm; crane_stiffness.full6.lvdt_array) [-]', low=1.0, high=1e6),
    ParamSpec('rest_position', [0.0, 0.0, 0.0], 'the platform centre at the rest pose the LVDTs were zeroed at, '
              'crane_base; the published position is this plus the solved translation [m]'),
    ParamSpec('rest_orientation', [0.0, 0.0, 0.0, 1.0], "the platform's orientation at that rest pose, quaternion "
              '[x, y, z, w] body -> crane_base (normalised); the solved rotation is applied to it, and it turns the '
              'contact points into lever arms [-]'),
    ParamSpec('stamp_tolerance_s', 0.0, "readings stamped within this of a group's first reading are of one sample "
              'instant (0: identical stamps, as LVDTs sampled on one clock grid give); below half the sample '
              'period [s]', low=0.0, high=1.0),
    ParamSpec('max_wait_s', 0.5, 'an incomplete group is dropped once a reading stamped this much later arrives [s]',
              low=1e-6, high=60.0),
    ParamSpec('publish_rate_hz', 100.0, 'rate at which the complete groups are solved (one batch) and published '
              '[Hz]', low=1.0, high=1000.0),
    ParamSpec('frame_id', topics.FRAME_BASE, 'header.frame_id of the published poses; the pose is in crane_base '
              'whatever it says (a label) [-]'),
    *LVDT_CALIBRATION_PARAMS,  # one declaration for every LVDT channel of the array
)
#: Read at start only: the subscriptions are made once.
START_ONLY = ('topics',)
#: Open groups kept at most (whatever max_wait_s): an LVDT silent for good leaves no more behind than this.
MAX_OPEN_GROUPS = 10_000


@dataclass
class LvdtArrayCounters(Counters):
    """Readings: ``received`` = ``used`` + ``dropped_non_finite`` + ``late_readings`` + ``duplicate_readings``.
    Groups (sample instants): ``groups_complete`` (solved and ``published``, or about to be), ``groups_incomplete``
    (dropped, never published)."""

    used: int = 0
    late_readings: int = 0
    duplicate_readings: int = 0
    groups_complete: int = 0
    groups_incomplete: int = 0


class StampGroups:
    """Readings of ``n`` sensors grouped by sample instant (the rule in the module docstring). Stamps in ns."""

    def __init__(self, n: int, tolerance_ns: int, max_wait_ns: int, counters: LvdtArrayCounters) -> None:
        self.n = n
        self.tolerance_ns = tolerance_ns
        self.max_wait_ns = max_wait_ns
        self.counters = counters
        self.open: dict[int, tuple[list[int | None], list[float]]] = {}  # first stamp -> (stamps, readings)
        self.last_done_ns: int | None = None  # first stamp of the newest completed group

    def add(self, index: int, stamp_ns: int, reading: float) -> tuple[int, list[float]] | None:
        """Reading of sensor ``index`` [m] stamped ``stamp_ns``; returns (stamp [ns], n readings [m]) of the group it
        completed, or None."""
        c = self.counters
        if self.last_done_ns is not None and stamp_ns <= self.last_done_ns + self.tolerance_ns:
            c.late_readings += 1
            return None
        key = next((k for k in self.open if abs(stamp_ns - k) <= self.tolerance_ns), None)
        if key is None:
            key = stamp_ns
            self.open[key] = ([None] * self.n, [math.nan] * self.n)
        stamps, readings = self.open[key]
        if stamps[index] is not None:
            c.duplicate_readings += 1
            return None
        stamps[index], readings[index] = stamp_ns, reading
        c.used += 1
        self._drop(lambda k: k < stamp_ns - self.max_wait_ns)  # an LVDT that went silent
        if len(self.open) > MAX_OPEN_GROUPS:
            self._drop(lambda k: k < min(self.open) + 1)
        if key not in self.open or any(s is None for s in stamps):
            return None
        del self.open[key]
        self._drop(lambda k: k < key)  # a later instant is complete: the earlier ones lost a reading for good
        self.last_done_ns = key
        c.groups_complete += 1
        return round(sum(s for s in stamps if s is not None) / self.n), readings

    def _drop(self, older) -> None:
        for k in [k for k in self.open if older(k)]:
            del self.open[k]
            self.counters.groups_incomplete += 1

    def clear(self) -> None:
        """Forget the open groups (counted incomplete)."""
        self._drop(lambda k: True)


def pose_arrays(deflection: np.ndarray, rest_position: np.ndarray, rest_quaternion: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """Positions (m, 3) [m] and quaternions (m, 4) [x, y, z, w] (body -> crane_base) of deflections (m, 6) [m, rad]
    from the rest pose: rest_position + δu and exp([δθ]×)·R0 (crane_stiffness.full6.deflection inverted)."""
    turn = rotvec_to_quaternion(deflection[:, 3:])
    return rest_position + deflection[:, :3], normalised(quaternion_multiply(turn, rest_quaternion))


class LvdtArrayNode(Node):
    """Groups the LVDT readings by instant; each tick solves the complete groups and publishes their poses."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('lvdt_array', **kwargs)
        self.counters = LvdtArrayCounters()
        self.array: LvdtArray | None = None  # set by _apply (Params, below)
        self.rest_position = np.zeros(3)
        self.rest_quaternion = np.array([0.0, 0.0, 0.0, 1.0])
        self.groups: StampGroups | None = None
        self.done: list[tuple[int, list[float]]] = []  # complete groups not solved yet: (stamp [ns], readings [m])
        self.settings: dict[str, Any] = {}
        self.timer: Any = None
        self.residual_rms = math.nan
        self.not_converged = 0
        self._incomplete_reported = 0
        sim_time = uses_sim_time(self)
        self.pub = self.create_publisher(PoseStamped, topics.POSE_SENSOR_POSE, sensor_qos(sim_time))
        self.pub_cov = self.create_publisher(PoseWithCovarianceStamped, topics.LVDT_ARRAY_POSE, sensor_qos(sim_time))
        self.params = Params(self, PARAMS, self._validate, self._apply)
        for i, topic in enumerate(self.settings['topics']):
            self.create_subscription(PointStamped, topic, functools.partial(self._on_reading, i),
                                     sensor_qos(sim_time), raw=True)
        self.diagnostics = Diagnostics(self, self._report)

    def _validate(self, values: dict[str, Any]) -> tuple[LvdtArray, np.ndarray, np.ndarray]:
        check_start_only(values, self.settings, START_ONLY)
        calibration_of(values, LVDT_COMPONENTS)  # the declared calibration of its channels: refused when malformed
        names = values['topics']
        check(len(names) > 0 and all(valid_topic_name(t) for t in names), 'topics', names,
              'must be valid topic names, one per LVDT')
        check(len(set(names)) == len(names), 'topics', names, 'must name each topic once')
        n = len(names)
        for name in ('contact_points', 'directions'):
            check(len(values[name]) == 3 * n, name, values[name], f'must be 3 numbers per LVDT: {3 * n} for the {n} '
                  'topics')
        check(len(values['noise_std']) in (1, n), 'noise_std', values['noise_std'], f'must be one number or {n}')
        check(all(math.isfinite(v) for v in values['rest_position']) and len(values['rest_position']) == 3,
              'rest_position', values['rest_position'], 'must be 3 finite numbers')
        q = np.array(values['rest_orientation'], dtype=float)
        check(q.shape == (4,) and bool(np.isfinite(q).all()) and float(np.linalg.norm(q)) > 0.0,
              'rest_orientation', values['rest_orientation'], 'must be a quaternion [x, y, z, w], 4 finite numbers, '
              'not all zero')
        check(values['frame_id'] != '', 'frame_id', values['frame_id'], 'must be non-empty')
        noise = values['noise_std'][0] if len(values['noise_std']) == 1 else values['noise_std']
        try:
            array = LvdtArray(np.reshape(values['contact_points'], (n, 3)), np.reshape(values['directions'], (n, 3)),
                              noise, name=values['arrangement'], rest_rotation=quaternion_to_matrix(q),
                              max_condition=values['max_condition'])
        except ArrangementError as exc:  # not a ValueError: Params reports ValueErrors
            raise ValueError(f'contact_points, directions, noise_std: {exc}') from exc
        return array, np.array(values['rest_position'], dtype=float), q / np.linalg.norm(q)

    def _apply(self, built: tuple[LvdtArray, np.ndarray, np.ndarray], values: dict[str, Any]) -> None:
        array, rest_position, rest_quaternion = built
        if self.array is not None:
            self._solve_and_publish()  # the groups completed so far, with the set-up they were read under
        self.array, self.rest_position, self.rest_quaternion = array, rest_position, rest_quaternion
        tolerance_ns, wait_ns = round(values['stamp_tolerance_s'] * 1e9), round(values['max_wait_s'] * 1e9)
        if self.groups is None:
            self.groups = StampGroups(array.n, tolerance_ns, wait_ns, self.counters)
        self.groups.tolerance_ns, self.groups.max_wait_ns = tolerance_ns, wait_ns
        if self.timer is not None:
            self.destroy_timer(self.timer)
        self.timer = self.create_timer(1.0 / values['publish_rate_hz'], self._solve_and_publish)
        self.settings = values
        self.get_logger().info(f"arrangement '{array.name}': {array.n} LVDTs, condition number "
                               f'{array.condition_number:.4g}, RMS lever arm {array.radius:.4g} m')

    def _on_reading(self, index: int, data: bytes) -> None:
        self.counters.received += 1
        try:
            sec, nanosec, (x, _, _) = decode_stamped(data, 3)
        except CdrError:
            self.counters.dropped_absurd += 1
            return
        if not math.isfinite(x):
            self.counters.dropped_non_finite += 1
            return
        assert self.groups is not None
        complete = self.groups.add(index, sec * 1_000_000_000 + nanosec, x)
        if complete is not None:
            self.done.append(complete)

    def _solve_and_publish(self) -> None:
        """Solve the complete groups in one batch and publish a pose and a pose with covariance for each."""
        if not self.done:
            return
        assert self.array is not None
        done, self.done = self.done, []
        solution = self.array.solve(np.array([r for _, r in done]))
        self.not_converged += 0 if solution.converged else len(done)
        self.residual_rms = float(np.sqrt(np.mean(solution.residuals ** 2)))
        positions, quaternions = pose_arrays(solution.deflection, self.rest_position, self.rest_quaternion)
        frame = self.settings['frame_id']
        for (t_ns, _), u, q, cov in zip(done, positions.tolist(), quaternions.tolist(), solution.covariance):
            msg = pose_stamped(t_ns, frame, u, q)
            self.pub.publish(msg)
            out = PoseWithCovarianceStamped(header=msg.header)
            out.pose.pose = msg.pose
            out.pose.covariance = cov.ravel().tolist()
            self.pub_cov.publish(out)
        self.counters.published += len(done)

    def _report(self) -> tuple[int, str, list[tuple[str, str]]]:
        assert self.array is not None and self.groups is not None
        new = self.counters.groups_incomplete - self._incomplete_reported
        self._incomplete_reported = self.counters.groups_incomplete
        pairs = self.counters.as_pairs() + [('open_groups', str(len(self.groups.open))),
                                            ('not_converged', str(self.not_converged)),
                                            ('residual_rms_m', repr(self.residual_rms)),
                                            ('condition_number', f'{self.array.condition_number:.6g}'),
                                            ('arrangement', self.array.name)]
        if new:
            return WARN, f'{new} sample instant(s) dropped without a reading of every LVDT', pairs
        if not self.counters.published:
            return OK, f'waiting for a reading of each of the {self.array.n} LVDTs at one instant', pairs
        return OK, f'{self.counters.published} poses published', pairs


def main(args=None) -> int:
    return run(LvdtArrayNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
