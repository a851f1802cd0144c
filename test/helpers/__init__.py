"""What the tests share, in one place: a test imports helpers from here, never from conftest.py or another test.

conftest.py holds only what pytest itself uses (the environment, fixtures, markers). This module and
helpers.processes import no rclpy (pure tests import them too); helpers.probe and helpers.estimator do:

- ``helpers``: paths, stamps, topic names of one test's own, spinning an executor, calling a service, publishing a
  wrench;
- ``helpers.probe``: ProbeNode, the test node the probes of the node tests build on;
- ``helpers.processes``: node processes started as ``ros2 run`` does, their logs and the bags they leave;
- ``helpers.estimator``: the synthetic rig and the probe of the estimator tests.
"""
from __future__ import annotations

import itertools
import os
import time
from pathlib import Path
from typing import Callable

import numpy as np

from crane_stiffness.contract import topics

#: The repository (the work tree the tests run from).
REPO = Path(__file__).resolve().parents[2]
NS = 1_000_000_000
#: The suite's patience [s]: how long a test waits for an event before it calls the program under test hung. Only a
#: hung program takes this long: a loaded machine (two cores, a build beside the tests, load average 10) delays
#: discovery, a node's start and a burst of samples by seconds, never by minutes. Every wait for something a loaded
#: machine may delay is bounded by this, by name; a test waits for the event it needs, then asserts. A check that
#: something does NOT happen waits for a later event that proves it instead of sleeping.
PATIENCE_S = 120.0
_ids = itertools.count()


def stamp_ns(stamp) -> int:
    """A builtin_interfaces/Time (a header's stamp) in ns."""
    return stamp.sec * NS + stamp.nanosec


def wrench_vector(msg) -> np.ndarray:
    """A WrenchStamped's wrench as [fx fy fz mx my mz]."""
    f, m = msg.wrench.force, msg.wrench.torque
    return np.array([f.x, f.y, f.z, m.x, m.y, m.z])


def isolated(base: str) -> tuple[str, str, list[str]]:
    """A unique node name, a topic prefix and the cli_args remapping the rig's topics under that prefix (the topics
    of the model, the sensors, the drivers and the emulators; the estimator's: helpers.estimator.isolated_estimator)."""
    name = f'{base}_{os.getpid()}_{next(_ids)}'
    prefix = f'/{name}_t'
    args = ['--ros-args', '-r', f'__node:={name}']
    for topic in (topics.WRENCH_COMMAND, topics.APPLIED_WRENCH, topics.REJECTED_COMMAND, topics.PLATFORM_POSE,
                  topics.LOAD_CELL_WRENCH, topics.LVDT_DISPLACEMENT, topics.LVDT_ZERO, topics.LOAD_CELL_TARE,
                  topics.MODEL_STATUS, topics.DIAGNOSTICS):
        args += ['-r', f'{topic}:={prefix}{topic}']
    return name, prefix, args


def spin_until(executor, predicate: Callable[[], bool], timeout_s: float = PATIENCE_S) -> bool:
    """Spin ``executor`` until ``predicate()`` holds or ``timeout_s`` [s] of wall time pass (the suite's patience
    unless given); returns the predicate's last value."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        executor.spin_once(timeout_sec=0.01)
    return predicate()


def collect_for(executor, seconds: float) -> None:
    """Spin ``executor`` for ``seconds``, whatever arrives."""
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        executor.spin_once(timeout_sec=0.01)


def call_trigger(executor, node, service: str, timeout_s: float = PATIENCE_S):
    """Call the std_srvs/Trigger ``service`` from ``node``, spinning ``executor``; returns the response."""
    from std_srvs.srv import Trigger
    client = node.create_client(Trigger, service)
    assert client.wait_for_service(timeout_sec=timeout_s), service
    future = client.call_async(Trigger.Request())
    assert spin_until(executor, future.done, timeout_s)
    return future.result()


def publish_wrench_now(node, publisher, wrench, frame_id: str = 'crane_base') -> int:
    """Publish ``wrench`` [fx fy fz mx my mz] (N, N·m) as a WrenchStamped stamped with ``node``'s clock now; returns
    the stamp [ns]."""
    from geometry_msgs.msg import WrenchStamped
    msg = WrenchStamped()
    now = node.get_clock().now()
    msg.header.stamp = now.to_msg()
    msg.header.frame_id = frame_id
    f, m = msg.wrench.force, msg.wrench.torque
    f.x, f.y, f.z, m.x, m.y, m.z = (float(v) for v in wrench)
    publisher.publish(msg)
    return now.nanoseconds


def run_without_ros(body: str, blocked: tuple[str, ...] = ('rclpy',), timeout_s: float = PATIENCE_S):
    """Run ``body`` (Python statements) in a fresh interpreter where importing any of ``blocked`` fails and no ROS
    environment is set, from the repository's source; then check that no ROS module got imported. Returns the
    CompletedProcess (its stdout for the caller); asserts exit 0 with stderr shown."""
    import subprocess
    import sys
    import textwrap
    code = ('import sys\n' + ''.join(f'sys.modules[{name!r}] = None\n' for name in blocked)
            + textwrap.dedent(body) + '\nassert not [m for m in sys.modules if m.split(".")[0] in '
            '("rclpy", "rosidl_runtime_py", "std_msgs") and sys.modules[m] is not None]\n')
    env = {k: v for k, v in os.environ.items() if not k.startswith(('AMENT', 'ROS'))}
    env['PYTHONPATH'] = str(REPO)
    result = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, env=env, timeout=timeout_s)
    assert result.returncode == 0, result.stderr
    return result
