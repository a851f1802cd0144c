"""rosbag2's YAML layout, written by PyYAML: block style as yaml-cpp (rosbag2's emitter) lays it out.

Two-space indent with sequences indented under their key, ``~`` for null, keys in insertion order, no line folding,
no anchors, and double quotes where a string cannot be plain. metadata.yaml and the ``offered_qos_profiles`` strings
of the MCAP channels are written with :func:`dump_yaml` and read with :func:`load_yaml`.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import yaml


class RosbagDumper(yaml.SafeDumper):
    """PyYAML's safe dumper configured for yaml-cpp's layout (see the module docstring)."""

    def increase_indent(self, flow: bool = False, indentless: bool = False) -> None:
        super().increase_indent(flow, False)  # a sequence under a key is indented, as yaml-cpp does

    def choose_scalar_style(self) -> str:
        style = super().choose_scalar_style()
        return '"' if style == "'" else style

    def ignore_aliases(self, data: Any) -> bool:
        return True


RosbagDumper.add_representer(type(None), lambda dumper, _: dumper.represent_scalar('tag:yaml.org,2002:null', '~'))
RosbagDumper.add_representer(tuple, yaml.SafeDumper.represent_list)


def dump_yaml(value: Mapping[str, Any] | Sequence[Any]) -> str:
    """``value`` as block-style YAML in rosbag2's layout; returns text without a trailing newline."""
    text = yaml.dump(value, Dumper=RosbagDumper, default_flow_style=False, sort_keys=False, allow_unicode=True,
                     width=float('inf'))
    return text.rstrip('\n')


#: PyYAML's safe loader in C (libyaml) where PyYAML was built with it: a bag's reader and writer parse the QoS
#: profiles of every channel and metadata.yaml, ten times faster than the pure-Python loader; the same documents.
_SAFE_LOADER: type = getattr(yaml, 'CSafeLoader', yaml.SafeLoader)


def load_yaml(text: str) -> Any:
    """One YAML document as ``yaml.safe_load`` reads it (yaml.YAMLError when it is not YAML)."""
    return yaml.load(text, Loader=_SAFE_LOADER)  # noqa: S506 - a safe loader
