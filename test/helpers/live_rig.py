"""The simulated rig with the live view, for the live view tests: every node started from the colcon install as
``ros2 launch crane_stiffness rig.launch.py live_view:=true`` starts them, and :class:`RigWatcher`, a test node that
records what the rig published (the estimator's fitted pairs and values, the wire states, the tare epochs) on a
thread of its own, to compare with what the view serves.
"""
from __future__ import annotations

import contextlib
import re
import threading
import time
from pathlib import Path
from typing import Any, Iterable, Iterator

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64, Float64MultiArray

from helpers import PATIENCE_S
from crane_stiffness.contract import topics
from crane_stiffness.estimation.live import PAIR_FIELDS, VALUE_FIELDS
from crane_stiffness.rosnode.qos import KEPT_QOS, LATCHED_QOS, RELIABLE_QOS
from crane_stiffness.launcher.ports import free_port
from crane_stiffness.launcher.rig import start_rig
from crane_stiffness.launcher.rosrun import Processes


class RigWatcher(Node):
    """What the rig published, as received (lists are appended on the watcher's thread)."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('live_view_test_watcher', **kwargs)
        self.pairs: dict[float, tuple[float, float, int, int]] = {}  # stamp -> (x, force, branch, segment)
        # The stamp of the first pair received. DDS discovery between two processes takes up to ~2.5 s (Fast DDS's
        # endpoint announcements), so the watcher may match the estimator after the program began; from its first
        # message on the stream is reliable and deep, so every pair stamped from then on is here.
        self.first_stamp: float | None = None
        self.tensions: set[tuple[float, ...]] = set()
        self.first_wires_ns: int | None = None  # the header stamp of the first wire states received (as first_stamp)
        self.values: dict[float, float] = {}  # sample_stamp -> loading stiffness
        self.loading: dict[str, float] = {}  # the newest loading row (VALUE_FIELDS)
        self.tare_epochs: list[float] = []
        self.statuses: dict[str, tuple[int, str]] = {}
        self.status_history: list[dict[str, tuple[int, str]]] = []
        # a deep queue: this thread may fall a few seconds behind on a loaded machine and must not drop a pair
        deep = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
        self.create_subscription(Float64MultiArray, topics.FITTED_PAIRS, self._on_pairs, deep)
        self.create_subscription(JointState, topics.WIRE_STATES, self._on_wires, RELIABLE_QOS)
        self.create_subscription(Float64MultiArray, topics.STIFFNESS_VALUES, self._on_values, KEPT_QOS)
        self.create_subscription(Float64, topics.LOAD_CELL_TARE, self._on_tare, LATCHED_QOS)
        self.create_subscription(DiagnosticArray, topics.STIFFNESS_ESTIMATE, self._on_estimate, KEPT_QOS)
        self.executor_ = SingleThreadedExecutor(context=self.context)
        self.executor_.add_node(self)
        self.stopping = False
        self.thread = threading.Thread(target=self._spin, daemon=True)
        self.thread.start()

    def _spin(self) -> None:
        while not self.stopping:
            self.executor_.spin_once(timeout_sec=0.05)

    def _on_pairs(self, msg: Float64MultiArray) -> None:
        n = len(PAIR_FIELDS)
        data = list(msg.data)
        if self.first_stamp is None and data:
            self.first_stamp = data[0]
        for i in range(0, len(data), n):
            stamp, x, f, branch, segment = data[i:i + n]
            self.pairs[stamp] = (x, f, int(branch), int(segment))

    def _on_wires(self, msg: JointState) -> None:
        if self.first_wires_ns is None:
            self.first_wires_ns = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        self.tensions.add(tuple(msg.effort))

    def _on_values(self, msg: Float64MultiArray) -> None:
        row = dict(zip(VALUE_FIELDS, msg.data[:len(VALUE_FIELDS)]))  # the loading row
        self.values[row['sample_stamp']] = row['stiffness']
        self.loading = row

    def _on_tare(self, msg: Float64) -> None:
        self.tare_epochs.append(msg.data)

    def _on_estimate(self, msg: DiagnosticArray) -> None:
        self.statuses = {s.name.rpartition(': ')[2]: (s.level[0], s.message) for s in msg.status}
        self.status_history.append(self.statuses)

    def stop(self) -> None:
        self.stopping = True
        self.thread.join(5)
        self.executor_.remove_node(self)
        self.executor_.shutdown()
        self.destroy_node()


@contextlib.contextmanager
def live_rig(env: dict[str, str], share: Path, out: Path, context: Any, overrides: dict[str, dict] | None = None,
             arguments: dict[str, str] | None = None,
             **view: Any) -> Iterator[tuple[Processes, RigWatcher, dict[str, Any]]]:
    """The side-force rig with the live view on free ports (``view``: more live_view parameters; ``overrides``:
    other nodes' parameters; ``arguments``: launch arguments, e.g. ``use_sim_time``), the watcher subscribed before
    anything starts; yields (processes, watcher, {'port', 'http_port', 'url', 'token'}) once the view serves: the
    ports, and the page's address with its token and the token as the node logged them."""
    ports: dict[str, Any] = {'port': free_port(), 'http_port': free_port()}
    watcher = RigWatcher(context=context)
    try:
        with Processes(env, out / 'logs') as procs:
            start_rig(procs, share, 'side_force', 'live', out / 'bags', record=False, live_view=True,
                      overrides={**(overrides or {}), 'live_view': {**ports, **view}}, arguments=arguments)
            deadline = time.monotonic() + PATIENCE_S
            while 'live view: page http://' not in procs.log('live_view'):
                procs.check_alive()
                assert time.monotonic() < deadline, procs.log('live_view')
                time.sleep(0.1)
            yield procs, watcher, {**ports, **page_address(procs.log('live_view'))}
    finally:
        watcher.stop()


def page_address(log: str) -> dict[str, str]:
    """The page's address with the token (``url``) and the token, from the live view's start line."""
    found = re.search(r'live view: page (http://\S+\?token=(\S+)) ', log)
    assert found, log[-2000:]
    return {'url': found.group(1), 'token': found.group(2)}


def watched(watcher: RigWatcher, stamps: Iterable[float]) -> set[float]:
    """Those of ``stamps`` (pairs the view shows) the watcher was matched for: from its first pair on."""
    first = watcher.first_stamp
    return set() if first is None else {t for t in stamps if t >= first}


def wait_for_pairs(procs: Processes, watcher: RigWatcher, count: int, timeout_s: float = PATIENCE_S) -> None:
    """Until the estimator has published ``count`` fitted pairs (the program is running)."""
    deadline = time.monotonic() + timeout_s
    while len(watcher.pairs) < count:
        procs.check_alive(allow_exit=('load_program',))
        assert time.monotonic() < deadline, f'only {len(watcher.pairs)} fitted pairs after {timeout_s:g} s'
        time.sleep(0.1)
