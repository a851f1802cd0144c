"""JSON schemas of the derived channels, written the way Foxglove apps parse them.

A Foxglove app turns a channel's JSON schema (schema encoding ``jsonschema``) into the message definition its panels
offer paths from, and refuses the whole channel when one field is outside what it understands (Lichtblick's
``packages/mcap-support/src/parseJsonSchema.ts``): every object needs ``"type": "object"``, every field a type of
boolean, string, number, integer, object or array, and every array ``items`` of one of those types (an array
without ``items`` fails the channel: "Player alert schema" and an empty panel). So these builders always write
``items``; :func:`foxglove_parsable` applies the same rules, for the tests.
"""
from __future__ import annotations

from typing import Any

Schema = dict[str, Any]

NUMBER: Schema = {'type': 'number'}
INTEGER: Schema = {'type': 'integer'}
COUNT: Schema = {'type': 'integer', 'minimum': 0}
STRING: Schema = {'type': 'string'}
BOOLEAN: Schema = {'type': 'boolean'}


def obj(properties: dict[str, Schema], title: str | None = None) -> Schema:
    """An object with these fields (``title``: the schema's name, on a channel's top level)."""
    out: Schema = {'type': 'object', 'properties': properties}
    if title is not None:
        out = {'title': title, **out}
    return out


def array(items: Schema) -> Schema:
    """An array of ``items``."""
    return {'type': 'array', 'items': items}


def enum(**values: int) -> Schema:
    """An integer field with named values (the apps show the names)."""
    return {'type': 'integer', 'oneOf': [{'title': name, 'const': value} for name, value in values.items()]}


_SCALARS = {'boolean', 'string', 'number', 'integer'}


def foxglove_parsable(schema: Schema, path: str = '') -> list[str]:
    """What a Foxglove app would refuse in ``schema`` (an object schema), as ``path: reason`` lines; empty when it
    parses. The rules of Lichtblick's parseJsonSchema (see the module docstring)."""
    if schema.get('type') != 'object':
        return [f'{path or "(root)"}: "type" must be "object", not {schema.get("type")!r}']
    problems = []
    for name, field in (schema.get('properties') or {}).items():
        where = f'{path}.{name}' if path else name
        kind = field.get('type')
        if 'oneOf' in field:
            if not all(isinstance(alt.get('const'), (int, float)) for alt in field['oneOf']):
                problems.append(f'{where}: oneOf alternatives must have number values')
        elif kind == 'object':
            problems += foxglove_parsable(field, where)
        elif kind == 'array':
            items = field.get('items')
            if not isinstance(items, dict):
                problems.append(f'{where}: an array needs "items"')
            elif items.get('type') == 'object':
                problems += foxglove_parsable(items, f'{where}[]')
            elif items.get('type') not in _SCALARS:
                problems.append(f'{where}[]: unsupported item type {items.get("type")!r}')
        elif kind not in _SCALARS:
            problems.append(f'{where}: unsupported type {kind!r}')
    return problems
