"""What the tests share, in one place: a test imports helpers from here, never from conftest.py or another test.

conftest.py holds only what pytest itself uses (the environment, fixtures, markers). This module imports no rclpy at
import time (pure tests import it too); the submodules for ROS tests do:

- ``helpers``: paths, spinning an executor, calling a service, publishing a wrench.
"""
from __future__ import annotations

import time
from pathlib import Path
from typing import Callable

#: The repository (the work tree the tests run from).
REPO = Path(__file__).resolve().parents[2]


def spin_until(executor, predicate: Callable[[], bool], timeout_s: float) -> bool:
    """Spin ``executor`` until ``predicate()`` holds or the timeout passes; returns the predicate's last value."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        executor.spin_once(timeout_sec=0.01)
    return predicate()


def call_trigger(executor, node, service: str, timeout_s: float = 5.0):
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
