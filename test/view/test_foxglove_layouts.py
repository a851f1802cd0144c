"""The shipped Foxglove/Lichtblick layouts (foxglove/*.json) against what the rig publishes, without an app: every
panel of a layout's tree has its config; every topic a panel reads is one the live view offers (its default ROS
topics, with their types, or one of its derived channels, with their JSON schemas), and every message path resolves
field by field in that type or schema; a path into a /stiffness6/* matrix's ``data[n]`` is labelled with the entry
the layout's strides put at n (crane_stiffness.contract.stiffness6_layout); the status indicators name every level. And
the
6x6 layout shows K's whole diagonal and the estimator's status. (Opened in a real app: test_live_view_lichtblick.)"""
from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any, Iterator

import pytest

from crane_stiffness.contract import stiffness6_layout, topics
from crane_stiffness.full6.reference import entry_name
from crane_stiffness.nodes.live_view import _TYPES, DEFAULT_TOPICS, DERIVED_CHANNELS
from crane_stiffness.rosnode.session_qos import message_class
from crane_stiffness.contract.status import NAMES
from helpers import REPO

LAYOUTS = sorted((REPO / 'foxglove').glob('*.json'))
#: Every topic or channel a layout may read: what the live view offers by default.
OFFERED = set(DEFAULT_TOPICS) | set(DERIVED_CHANNELS)
#: One step of a message path: ``.name`` with an optional ``[index]`` or ``[:]`` (Foxglove's message path syntax).
_STEP = re.compile(r'\.([A-Za-z_]\w*)(\[(?::|\d+)\])?')
_MATRICES = {topics.STIFFNESS6: False, topics.COMPLIANCE6: True}  # topic -> compliance (C's rows are deflections)
_SUFFIX = {'value': '', 'ci95_low': ' 95 % low', 'ci95_high': ' 95 % high'}


def _load(path: Path) -> dict[str, Any]:
    return json.loads(path.read_text())


def _panels(node: Any) -> Iterator[str]:
    """The panel ids in a layout's split tree."""
    if isinstance(node, str):
        yield node
    else:
        yield from _panels(node['first'])
        yield from _panels(node['second'])


def _topic_strings(value: Any) -> Iterator[str]:
    """Every string in a panel's config (values and keys) that starts with '/': a topic or a message path."""
    if isinstance(value, str):
        if value.startswith('/'):
            yield value
    elif isinstance(value, dict):
        for key, item in value.items():
            yield from _topic_strings(key)
            yield from _topic_strings(item)
    elif isinstance(value, list):
        for item in value:
            yield from _topic_strings(item)


def _split(path: str) -> tuple[str, list[tuple[str, str | None]]]:
    """(topic, [(field, index or None), ...]) of a message path; the topic is the longest offered one it starts
    with (AssertionError when there is none, or the rest is not a message path)."""
    topic = max((t for t in OFFERED if path == t or path.startswith(t + '.')), key=len, default=None)
    assert topic is not None, f'{path}: reads a topic the live view does not offer'
    rest, steps = path[len(topic):], []
    while rest:
        m = _STEP.match(rest)
        assert m, f'{path}: {rest!r} is not a message path'
        steps.append((m.group(1), m.group(2)))
        rest = rest[m.end():]
    return topic, steps


def _element(ros_type: str) -> str | None:
    """The element type of a ROS sequence or array field type, or None for a single value."""
    if ros_type.startswith('sequence<'):
        return ros_type[len('sequence<'):-1].split(', ')[0]
    if ros_type.endswith(']'):
        return ros_type[:ros_type.index('[')]
    return None


def _check_ros(path: str, msg_type: str, steps: list[tuple[str, str | None]]) -> None:
    cls: Any = message_class(msg_type)
    for n, (name, index) in enumerate(steps):
        assert cls is not None, f'{path}: {name} below a value that has no fields'
        fields = cls.get_fields_and_field_types()
        assert name in fields, f'{path}: {cls.__name__} has no field {name} (it has {sorted(fields)})'
        field_type = fields[name]
        if index is not None:
            element = _element(field_type)
            assert element is not None, f'{path}: {name} ({field_type}) is not an array'
            field_type = element
        cls = message_class(field_type) if '/' in field_type else None


def _check_schema(path: str, schema: dict[str, Any], steps: list[tuple[str, str | None]]) -> None:
    for name, index in steps:
        assert schema.get('type') == 'object' and name in schema.get('properties', {}), \
            f'{path}: no field {name} in the channel schema here'
        schema = schema['properties'][name]
        if index is not None:
            assert schema.get('type') == 'array', f'{path}: {name} is not an array'
            schema = schema['items']


@pytest.mark.parametrize('path', LAYOUTS, ids=lambda p: p.name)
def test_every_panel_reads_what_the_live_view_offers_by_a_path_that_resolves(path: Path) -> None:
    layout = _load(path)
    panels = list(_panels(layout['layout']))
    assert panels and all(p in layout['configById'] for p in panels), set(panels) - set(layout['configById'])
    read = [s for p in panels for s in _topic_strings(layout['configById'][p])]
    assert read, f'{path.name}: no panel reads a topic'
    for message_path in read:
        topic, steps = _split(message_path)
        if topic in DERIVED_CHANNELS:
            _check_schema(message_path, DERIVED_CHANNELS[topic][1], steps)
        else:
            _check_ros(message_path, _TYPES[topic], steps)


def test_the_checks_refuse_a_wrong_topic_field_or_index() -> None:
    """The checker itself: what a mistyped layout would have."""
    with pytest.raises(AssertionError, match='does not offer'):
        _split('/stiffness6/stifness.data[0]')
    with pytest.raises(AssertionError, match='no field w'):
        _check_ros('p', 'geometry_msgs/msg/WrenchStamped', _split('/load_cell/wrench.wrench.force.w')[1])
    with pytest.raises(AssertionError, match='not an array'):
        _check_ros('p', 'geometry_msgs/msg/WrenchStamped', _split('/load_cell/wrench.wrench[0].force.x')[1])
    with pytest.raises(AssertionError, match='no field relative'):
        _check_schema('p', DERIVED_CHANNELS['/live_view/stiffness6'][1],
                      _split('/live_view/stiffness6.rows[0].cells[0].relative')[1])
    _check_ros('p', 'std_msgs/msg/Float64MultiArray', _split('/stiffness6/stiffness.layout.dim[0].stride')[1])


@pytest.mark.parametrize('path', LAYOUTS, ids=lambda p: p.name)
def test_a_path_into_a_6x6_matrix_is_labelled_with_the_entry_its_index_holds(path: Path) -> None:
    """``/stiffness6/stiffness.data[n]`` must say which entry n is, by the layout's strides (36 per quantity, 6 per
    row): a plot labelled K[fy, u_y] reading data[7] and not, say, data[8]."""
    for config in _load(path)['configById'].values():
        for series in config.get('paths', []):
            topic, steps = _split(series['value'])
            if topic not in _MATRICES:
                continue
            assert len(steps) == 1 and steps[0][0] == 'data' and steps[0][1] not in (None, '[:]'), series
            quantity, row, column = stiffness6_layout.entry(int(steps[0][1].strip('[]')))
            assert series['label'] == entry_name(row, column, compliance=_MATRICES[topic]) + _SUFFIX[quantity], \
                series


@pytest.mark.parametrize('path', LAYOUTS, ids=lambda p: p.name)
def test_every_status_indicator_names_every_level(path: Path) -> None:
    indicators = [c for k, c in _load(path)['configById'].items() if k.startswith('Indicator!')]
    for indicator in indicators:
        assert {int(r['rawValue']): r['label'] for r in indicator['rules']} == NAMES, indicator


def test_the_6x6_layout_shows_k_s_diagonal_and_the_estimator_s_status() -> None:
    layout = _load(REPO / 'foxglove' / 'stiffness6.json')
    shown = {layout['configById'][p].get('topicPath') for p in _panels(layout['layout'])}
    assert topics.STIFFNESS6_STATUS in shown
    plotted = {s['value'] for p in _panels(layout['layout']) for s in layout['configById'][p].get('paths', [])}
    for i in range(6):
        for quantity in ('value', 'ci95_low', 'ci95_high') if i < 3 else ('value',):
            assert f'{topics.STIFFNESS6}.data[{stiffness6_layout.index(quantity, i, i)}]' in plotted, (quantity, i)
    assert '/live_view/stiffness6.level' in {layout['configById'][p].get('path') for p in _panels(layout['layout'])}


def test_every_layout_is_documented() -> None:
    docs = (REPO / 'docs' / 'live_view.md').read_text()
    assert {p.name for p in LAYOUTS} >= {'stiffness_test.json', 'sensors.json', 'stiffness6.json'}
    for path in LAYOUTS:
        assert f'`{path.name}`' in docs, f'{path.name} is not described in docs/live_view.md'
