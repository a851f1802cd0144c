"""Node processes the tests start and what they leave: an installed console script in a process of its own (what
``ros2 run crane_stiffness <executable>`` runs), its FINAL_COUNTERS line, the signs of an unclean end in its output,
and a recorded bag as independent readers see it.

(The rig's nodes from a colcon install tree, started as ``ros2 launch`` starts them, are
crane_stiffness.launcher.rig/rosrun's.)
"""
from __future__ import annotations

import json
import subprocess
from pathlib import Path

import yaml

from crane_stiffness.launcher import rosrun

#: Signs of an unclean end in a node's output (rclpy's FATAL callback report, pybind11's abort, faulthandler).
UNCLEAN = ('Traceback', 'FATAL', 'terminate called', 'Fatal Python error', 'KeyboardInterrupt')


def start_node_process(executable: str, args: list[str], log: Path) -> subprocess.Popen:
    """The installed console script (what `ros2 run crane_stiffness <executable>` runs), in its own process."""
    return rosrun.start_installed(executable, args, log)


def stop_node_process(proc: subprocess.Popen, log: Path) -> tuple[int, str]:
    """SIGINT to the process's group (SIGKILL after 10 s); its exit status and output."""
    return rosrun.interrupt(proc, 10.0), log.read_text(errors='replace')


def final_counters(log: str, node: str | None = None) -> dict:
    """The counters on the newest ``FINAL_COUNTERS <node> {json}`` line in ``log`` (a node prints it once, at exit):
    ``node``'s (AssertionError with the log's end if there is none), or any node's if ``node`` is None ({} if there is
    none)."""
    start = 'FINAL_COUNTERS ' if node is None else f'FINAL_COUNTERS {node} '
    for line in reversed(log.splitlines()):
        if line.startswith(start):
            return json.loads(line.split(' ', 2)[2])
    if node is None:
        return {}
    raise AssertionError(f'no FINAL_COUNTERS {node} in:\n{log[-2000:]}')


def assert_bag_complete(bag: Path) -> int:
    """The bag as independent readers see it: metadata.yaml written and counting what the MCAP files hold, every
    file finished (summary section present). Returns the message count."""
    from mcap.reader import make_reader
    from rosbags.rosbag2 import Reader

    meta_file = bag / 'metadata.yaml'
    assert meta_file.is_file(), f'no metadata.yaml in {bag}: {sorted(p.name for p in bag.iterdir())}'
    info = yaml.safe_load(meta_file.read_text())['rosbag2_bagfile_information']
    total = info['message_count']
    assert total > 0, info
    per_topic = {t['topic_metadata']['name']: t['message_count'] for t in info['topics_with_message_count']}
    assert sum(per_topic.values()) == total
    # rosbags: reads metadata.yaml and the MCAP storage
    with Reader(bag) as reader:
        assert reader.message_count == total
        counted: dict[str, int] = {}
        for connection, _, _ in reader.messages():
            counted[connection.topic] = counted.get(connection.topic, 0) + 1
    assert counted == {t: n for t, n in per_topic.items() if n}
    # mcap: every file closed (summary and footer written), its messages those metadata.yaml counts
    in_files = 0
    for name in info['relative_file_paths']:
        with open(bag / name, 'rb') as f:
            reader = make_reader(f)
            summary = reader.get_summary()
            assert summary is not None and summary.statistics is not None, f'{name} has no summary: not closed'
            n = sum(1 for _ in reader.iter_messages())
            assert n == summary.statistics.message_count
            in_files += n
    assert in_files == total
    return total
