"""A short six-axis session as the live 6×6 estimator receives it, and feeding it over DDS in-process: commands,
load cell and pose streams of a D-optimal program on the lab model (the model's deflection at the step in force),
each message accounted by the node before more are sent. Imports rclpy's messages only inside :func:`feed`."""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from crane_stiffness.full6.design import d_optimal_design
from crane_stiffness.full6.pairs import LabelledPairs, full6_pairs
from crane_stiffness.full6.program import design_program
from crane_stiffness.model.geometry import lab_model
from crane_stiffness.model.rotation import matrix_to_quaternion, rotvec_to_matrix
from crane_stiffness.serde.stamps import stamp_seconds
from crane_stiffness.testing.synthetic_full6 import model_responses
from helpers import PATIENCE_S

LAB = lab_model(0.5, 50.0)
PEAKS = [2.8, 3.3, 24.0, 1.6, 1.4, 0.75]


def as_stamped(t: np.ndarray) -> np.ndarray:
    """Times [s] as a header stamp carries them (whole ns) and the node reads them back."""
    ns = np.round(t * 1e9).astype(np.int64)
    return stamp_seconds(ns // 1_000_000_000, ns % 1_000_000_000)


@dataclass(frozen=True)
class Streams:
    """Stamps [s] and values: commands ``tc``, ``wc`` (n, 6); load cell ``tw``, ``w`` (n, 6) [N, N·m]; pose ``tp``,
    ``position`` (n, 3) [m], ``quaternion`` (n, 4) [x y z w]."""

    tc: np.ndarray
    wc: np.ndarray
    tw: np.ndarray
    w: np.ndarray
    tp: np.ndarray
    position: np.ndarray
    quaternion: np.ndarray

    def pairs(self, settle_s: float) -> LabelledPairs:
        """The pairs the node forms of them (arrival order = stamp order here)."""
        return full6_pairs(self.tc, self.wc, self.tw, self.tw, self.w, self.tp, self.tp, self.position,
                           self.quaternion, settle_s=settle_s)


def streams(t0: float, seed: int = 2, wrench_rate_hz: float = 1000.0) -> Streams:
    """A D-optimal program of 12 steps held 1 s played from ``t0`` [s]: commands at 100 Hz, the load cell at
    ``wrench_rate_hz`` (0.02 N, 0.002 N·m noise), the pose at 250 Hz (2 um, 20 urad noise)."""
    design = d_optimal_design(LAB, PEAKS, n_steps=12, hold_s=1.0, settle_s=0.3, baseline_s=0.5)
    program = design_program(design)
    truth = model_responses(LAB, program, 0.0)
    rng = np.random.default_rng(seed)
    starts = [s.start_s for s in truth.steps]
    tc = np.arange(0.0, program.duration_s, 0.01)
    wc = np.array([program.wrench_at(t).wrench for t in tc])
    tw = np.arange(0.0, program.duration_s, 1.0 / wrench_rate_hz)
    step_of = np.clip(np.searchsorted(starts, tw, side='right') - 1, 0, None)
    w = truth.wrenches[step_of] + rng.normal(0, [0.02] * 3 + [0.002] * 3, (tw.size, 6))
    tp = np.arange(0.0, program.duration_s, 0.004) + 0.0002
    k = np.clip(np.searchsorted(starts, tp, side='right') - 1, 0, None)
    d = truth.deflection[k] + rng.normal(0, [2e-6] * 3 + [2e-5] * 3, (tp.size, 6))
    quaternion = np.array([matrix_to_quaternion(rotvec_to_matrix(r)) for r in d[:, 3:]])
    return Streams(as_stamped(t0 + tc), wc, as_stamped(t0 + tw), w, as_stamped(t0 + tp), d[:, :3], quaternion)


def feed(executor: Any, node: Any, publishers: tuple[Any, Any, Any], s: Streams) -> None:
    """Publish ``s`` in stamp order on (command, load cell, pose) ``publishers``, spinning ``executor`` until
    ``node`` (a stiffness6_estimator) has taken every message sent (its counters) before more are sent."""
    from geometry_msgs.msg import PoseStamped, WrenchStamped

    from crane_stiffness.serde.stamps import split_ns
    pub_c, pub_w, pub_p = publishers
    events = sorted([(t, 0, i) for i, t in enumerate(s.tc)] + [(t, 1, i) for i, t in enumerate(s.tw)]
                    + [(t, 2, i) for i, t in enumerate(s.tp)])
    sent = {'commands': node.counters['commands'], 'wrenches': node.counters['wrenches'],
            'poses': node.counters['poses']}
    for n, (t, kind, i) in enumerate(events):
        stamp = split_ns(round(t * 1e9))
        if kind == 2:
            pose = PoseStamped()
            pose.header.stamp.sec, pose.header.stamp.nanosec = stamp
            p, q = pose.pose.position, pose.pose.orientation
            p.x, p.y, p.z = s.position[i]
            q.x, q.y, q.z, q.w = s.quaternion[i]
            pub_p.publish(pose)
            sent['poses'] += 1
        else:
            msg = WrenchStamped()
            msg.header.stamp.sec, msg.header.stamp.nanosec = stamp
            f, m = msg.wrench.force, msg.wrench.torque
            f.x, f.y, f.z, m.x, m.y, m.z = s.wc[i] if kind == 0 else s.w[i]
            (pub_c if kind == 0 else pub_w).publish(msg)
            sent['commands' if kind == 0 else 'wrenches'] += 1
        if n % 200 == 199 or n == len(events) - 1:  # taken before more is sent (the queues hold 1000)
            deadline = time.monotonic() + PATIENCE_S
            while any(node.counters[key] < sent[key] for key in sent):
                assert time.monotonic() < deadline, ('the node did not take what was sent', sent, node.counters)
                executor.spin_once(timeout_sec=0.01)


__all__ = ['LAB', 'PEAKS', 'Streams', 'as_stamped', 'feed', 'streams']
