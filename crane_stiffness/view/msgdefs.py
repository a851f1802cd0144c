"""ROS 2 message definitions as Foxglove clients want them (schema encoding ``ros2msg``): the type's ``.msg`` text
followed by every type it uses, each after a line of 80 ``=`` and ``MSG: pkg/Type`` (what foxglove_bridge and
rosbag2 send). Read from ``<prefix>/share/<pkg>/msg/<Type>.msg`` of the ament prefixes. Pure Python, no ROS.
"""
from __future__ import annotations

import os
import re
from typing import Sequence

from crane_stiffness.view.errors import ViewError

PRIMITIVES = frozenset({'bool', 'byte', 'char', 'float32', 'float64', 'int8', 'uint8', 'int16', 'uint16', 'int32',
                        'uint32', 'int64', 'uint64', 'string', 'wstring'})
_SEPARATOR = '=' * 80


def _field_type(line: str) -> str | None:
    """The type of a field line ('pkg/Type', 'Type' or a primitive), None for comments, blanks and constants."""
    line = line.split('#', 1)[0].strip()
    if not line:
        return None
    parts = line.split()
    if len(parts) < 2 or '=' in parts[1] or (len(parts) > 2 and parts[2].startswith('=')):
        return None  # a constant (TYPE NAME=VALUE)
    return re.sub(r'(\[.*\]|<=\d+)', '', parts[0])


def _read(type_name: str, prefixes: Sequence[str]) -> str:
    pkg, _, name = type_name.partition('/msg/') if '/msg/' in type_name else type_name.partition('/')
    for prefix in prefixes:
        path = os.path.join(prefix, 'share', pkg, 'msg', name + '.msg')
        if os.path.isfile(path):
            with open(path, encoding='utf-8') as f:
                return f.read()
    raise ViewError(f'message type {type_name}: no {pkg}/msg/{name}.msg in the ament prefixes {list(prefixes)}')


def definition(type_name: str, prefixes: Sequence[str] | None = None) -> str:
    """The full ros2msg definition of ``type_name`` ('pkg/msg/Type'); ``prefixes``: default AMENT_PREFIX_PATH."""
    if prefixes is None:
        prefixes = [p for p in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep) if p]
    pkg = type_name.split('/')[0]
    main = _read(type_name, prefixes)
    parts = [main.strip()]
    seen: set[str] = set()
    queue = [(pkg, main)]
    while queue:
        own_pkg, text = queue.pop(0)
        for line in text.splitlines():
            t = _field_type(line)
            if t is None or t in PRIMITIVES:
                continue
            full = 'std_msgs/Header' if t == 'Header' else (t if '/' in t else f'{own_pkg}/{t}')
            if full in seen:
                continue
            seen.add(full)
            sub = _read(full, prefixes)
            parts.append(f'{_SEPARATOR}\nMSG: {full}\n{sub.strip()}')
            queue.append((full.split('/')[0], sub))
    return '\n'.join(parts) + '\n'
