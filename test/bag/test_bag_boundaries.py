"""Bag content stays inside the bag, and the player's ends and counters.

- Files: metadata.yaml's ``relative_file_paths`` and the ``*.mcap`` found in a bag directory are read only inside
  that directory (``..``, absolute paths and symlinks leading out are refused, naming the entry), by the reader,
  ``crane-stiffness analyze`` and ``recover`` alike.
- Types: a topic type in a bag resolves only to an interface the ament index lists; ``this/msg/Foo`` is refused by
  name and nothing is imported (the issue saw "The Zen of Python" printed by the player).
- Player: ``start_offset_s`` past the end is an error naming the offset and the bag's duration (exit 2 at start-up,
  failure from ~/start); its counters account for every message read (read = published + skipped_*).
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml
from geometry_msgs.msg import WrenchStamped
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.serialization import serialize_message
from std_msgs.msg import String

from helpers import PATIENCE_S, call_trigger, spin_until
from crane_stiffness.bag import BagPathError, BagReader, BagWriter, UnsupportedTypeError
from crane_stiffness.bag.msgdef import interface_prefix
from crane_stiffness.cli.main import main as cli_main
from crane_stiffness.rosnode.qos import SENSOR_QOS
from crane_stiffness.nodes.session_player import SessionPlayer
from crane_stiffness.rosnode.session_qos import message_class
from crane_stiffness.launcher import rosrun

NS = 1_000_000_000
T0 = 1_700_000_000 * NS


def _wrench(log_ns: int, fy: float) -> bytes:
    m = WrenchStamped()
    m.header.stamp.sec, m.header.stamp.nanosec = divmod(log_ns, NS)
    m.wrench.force.y = fy
    return serialize_message(m)


def _bag(path: Path, fy: float, n: int = 101, extra_type: str | None = None) -> Path:
    """/w WrenchStamped n × at 100 Hz (force.y = fy), /s String 3 ×; with ``extra_type`` also /evil of that type."""
    with BagWriter(path) as w:
        w.add_topic('/w', 'geometry_msgs/msg/WrenchStamped')
        w.add_topic('/s', 'std_msgs/msg/String')
        if extra_type:
            w.add_topic('/evil', extra_type, message_definition_text='int32 x', type_hash='')
            w.write('/evil', b'\0\1\0\0\7\0\0\0', T0)
        for i in range(n):
            w.write('/w', _wrench(T0 + i * 10_000_000, fy), T0 + i * 10_000_000)
        for i in range(3):
            w.write('/s', serialize_message(String(data=f's{i}')), T0 + i * 400_000_000)
    return path


def _set_files(bag: Path, names: list[str]) -> None:
    meta_path = bag / 'metadata.yaml'
    meta = yaml.safe_load(meta_path.read_text())
    meta['rosbag2_bagfile_information']['relative_file_paths'] = names
    meta_path.write_text(yaml.safe_dump(meta))


# ---------------------------------------------------------------------------------------------- files --
def test_bag_files_are_read_only_inside_the_bag_directory(tmp_path, capsys):
    other = _bag(tmp_path / 'other', fy=666.0)
    other_file = other / 'other_0.mcap'
    cases = {
        'dotdot': (['../other/other_0.mcap'], "'../other/other_0.mcap' leads out of the bag with .."),
        'absolute': ([str(other_file)], f"{str(other_file)!r} is an absolute path"),
        'link': (['away.mcap'], f"'away.mcap' is a link to {other_file.resolve()}, outside the bag"),
    }
    for name, (files, expected) in cases.items():
        bag = _bag(tmp_path / name, fy=1.0)
        (bag / 'away.mcap').symlink_to(other_file)
        _set_files(bag, files)
        with pytest.raises(BagPathError) as caught:
            BagReader(bag)
        text = str(caught.value)
        assert expected in text and str(bag / 'metadata.yaml') in text and 'inside its directory' in text, text
        assert cli_main(['analyze', str(bag), '--out', str(tmp_path / 'out' / name), '--quiet']) == 2
        err = capsys.readouterr().err
        assert expected in err, err
        assert not (tmp_path / 'out' / name / 'results.json').exists()

    # without metadata.yaml the directory's *.mcap are read: a link among them leading out is refused too
    bare = tmp_path / 'bare'
    bare.mkdir()
    (bare / 'bare_0.mcap').symlink_to(other_file)
    with pytest.raises(BagPathError, match=r"'bare_0.mcap' is a link to .*outside the bag"):
        BagReader(bare)
    assert cli_main(['recover', str(bare)]) == 2
    assert 'outside the bag' in capsys.readouterr().err
    assert other_file.is_file() and not (other / 'other_0.mcap.bak').exists()  # the other bag untouched
    with BagReader(other) as reader:
        assert reader.complete and reader.decode('/w')['fy'].tolist() == [666.0] * 101

    # a link that stays inside the bag is an ordinary file of it
    inside = _bag(tmp_path / 'inside', fy=2.0)
    os.replace(inside / 'inside_0.mcap', inside / 'data.bin')
    (inside / 'inside_0.mcap').symlink_to('data.bin')
    with BagReader(inside) as reader:
        assert reader.decode('/w')['fy'].tolist() == [2.0] * 101


# ---------------------------------------------------------------------------------------------- types --
def test_message_types_resolve_only_to_interfaces_listed_in_the_ament_index():
    assert (interface_prefix('std_msgs/msg/String') / 'share' / 'ament_index' / 'resource_index'
            / 'rosidl_interfaces' / 'std_msgs').is_file()
    assert message_class('geometry_msgs/msg/WrenchStamped') is WrenchStamped
    for bad in ('this/msg/Foo', 'os/msg/path', 'std_msgs/msg/NotAType', 'crane_stiffness/msg/Foo'):
        with pytest.raises(UnsupportedTypeError, match=f"message type '{bad}' is not an installed interface"):
            interface_prefix(bad)
        with pytest.raises(ValueError, match=f"'{bad}'"):
            message_class(bad)
    with pytest.raises(ValueError, match='expected pkg/msg/Type'):
        message_class('std_msgs/srv/String')
    # In a fresh interpreter: refusing the type imports nothing (``import this`` prints the Zen of Python).
    code = ('import sys\nfrom crane_stiffness.rosnode.session_qos import message_class\n'
            'try:\n    message_class("this/msg/Foo")\nexcept ValueError as e:\n    print("refused:", e)\n'
            'print("imported:", "this" in sys.modules)\n')
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, timeout=PATIENCE_S)
    assert out.returncode == 0, out.stderr
    assert "refused: message type 'this/msg/Foo' is not an installed interface" in out.stdout
    assert 'imported: False' in out.stdout and 'Zen of Python' not in out.stdout + out.stderr


def test_the_player_refuses_a_type_outside_the_index(rclpy_context, tmp_path, capfd):
    ctx = rclpy_context
    assert 'this' not in sys.modules
    bag = _bag(tmp_path / 'crafted', fy=1.0, extra_type='this/msg/Foo')
    player = SessionPlayer(context=ctx, parameter_overrides=[
        Parameter('bag', value=str(bag)), Parameter('autostart', value=False)])
    try:
        assert sorted(player.playing_topics) == ['/s', '/w']
        assert any("/evil not played: message type 'this/msg/Foo' is not an installed interface" in p
                   for p in player.problems), player.problems
    finally:
        player.destroy_node()
    only = tmp_path / 'only'
    with BagWriter(only) as w:
        w.add_topic('/evil', 'this/msg/Foo', message_definition_text='int32 x', type_hash='')
        w.write('/evil', b'\0\1\0\0\7\0\0\0', T0)
    with pytest.raises(ValueError, match=r"no topic of .* to play; /evil not played: message type 'this/msg/Foo' "
                       r"is not an installed interface"):
        SessionPlayer(context=ctx, parameter_overrides=[Parameter('bag', value=str(only))])
    assert 'this' not in sys.modules and 'Zen of Python' not in capfd.readouterr().out


# --------------------------------------------------------------------------------------- player ends --
def test_start_offset_past_the_end_is_an_error_and_counters_add_up(rclpy_context, tmp_path):
    ctx = rclpy_context
    bag = _bag(tmp_path / 'b', fy=3.0)  # 1.000 s long (/s at 0, 0.4, 0.8 s; /w 0 .. 1.0 s)
    with pytest.raises(ValueError, match=r'start_offset_s = 1.5 s is past the end of the bag .* \(1.000 s long\)'):
        SessionPlayer(context=ctx, parameter_overrides=[Parameter('bag', value=str(bag)),
                                                        Parameter('start_offset_s', value=1.5)])
    ex = SingleThreadedExecutor(context=ctx)
    client = Node('offset_client', context=ctx)
    got: list = []
    client.create_subscription(WrenchStamped, '/w', got.append, SENSOR_QOS)
    player = SessionPlayer(context=ctx, parameter_overrides=[
        Parameter('bag', value=str(bag)), Parameter('autostart', value=False), Parameter('exit_on_end', value=False),
        Parameter('start_offset_s', value=1.0)])  # exactly the end: the last message plays
    ex.add_node(player)
    ex.add_node(client)
    try:
        assert spin_until(ex, lambda: player.playing_topics['/w'].get_subscription_count() >= 1, PATIENCE_S)
        res = call_trigger(ex, client, '/session_player/start')
        assert res.success, res.message
        assert spin_until(ex, lambda: player.finished, PATIENCE_S)
        spin_until(ex, lambda: len(got) >= 1, PATIENCE_S)
        assert [m.wrench.force.y for m in got] == [3.0]
        c = player.counters
        assert c['read'] == c['published'] == 1 and c['skipped_stopped'] == 0

        assert player.set_parameters([Parameter('start_offset_s', value=2.5)])[0].successful
        res = call_trigger(ex, client, '/session_player/start')
        assert not res.success
        assert 'start_offset_s = 2.5 s is past the end of the bag' in res.message and '1.000 s long' in res.message

        # stopped half-way: what was read and not published is counted as skipped. At rate 0.005 the bag's 1 s
        # plays in 200 s, longer than the patience of any wait here: the stop, sent once the first message is out,
        # comes mid-bag at any load.
        assert player.set_parameters([Parameter('start_offset_s', value=0.0), Parameter('rate', value=0.005)])[0] \
            .successful
        assert call_trigger(ex, client, '/session_player/start').success
        assert spin_until(ex, lambda: player.counters['published'] >= 1, PATIENCE_S), player.counters
        assert call_trigger(ex, client, '/session_player/stop').success
        c = player.counters
        assert 0 < c['published'] < 104 and c['read'] == c['published'] + c['skipped_stopped'] \
            + c['skipped_publish_error'], c
        assert c['skipped_stopped'] == 1, c  # the message waiting for its time
    finally:
        ex.shutdown()
        player.destroy_node()


def test_player_process_exits_2_on_an_offset_past_the_end_and_counts_every_message(install_tree, tmp_path):
    install, env = install_tree
    bag = _bag(tmp_path / 'b', fy=4.0)
    with rosrun.Processes(env, tmp_path / 'logs') as procs:
        procs.start('past', 'crane_stiffness', 'session_player',
                    ['--ros-args', '-p', f'bag:={bag}', '-p', 'start_offset_s:=7.0'])
        procs.start('whole', 'crane_stiffness', 'session_player',
                    ['--ros-args', '-p', f'bag:={bag}', '-p', 'start_delay_s:=0.2', '-p', 'rate:=4.0'])
        deadline = time.monotonic() + PATIENCE_S
        while any(p.poll() is None for p in procs.procs.values()) and time.monotonic() < deadline:
            time.sleep(0.1)
        codes = {n: p.returncode for n, p in procs.procs.items()}
        logs = {n: procs.log(n) for n in procs.procs}
    assert codes == {'past': 2, 'whole': 0}, logs
    assert 'start_offset_s = 7 s is past the end of the bag' in logs['past'] and '(1.000 s long)' in logs['past']
    assert 'Traceback' not in logs['past'] + logs['whole']
    line = next(x for x in logs['whole'].splitlines() if x.startswith('FINAL_COUNTERS session_player '))
    counters = json.loads(line.split(' ', 2)[2])
    assert counters['read'] == counters['published'] == 104 and counters['skipped_stopped'] == 0, counters
