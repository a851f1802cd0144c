"""Write docs/parameters.md, the reference of every node's parameters, from their declarations (ParamSpec).

Each parameter is declared once (crane_stiffness.params.spec); this page is generated from those declarations, so it
cannot drift from what the nodes declare: ``test/params/test_parameter_reference.py`` fails when the page is out of
date.

Run: .venv/bin/python scripts/parameter_reference.py [--check]
"""
from __future__ import annotations

import argparse
import importlib
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

PAGE = REPO / 'docs' / 'parameters.md'


def _cell(text: object) -> str:
    return str(text).replace('|', '\\|').replace('\n', ' ')


def _type(default: object) -> str:
    if isinstance(default, bool):
        return 'bool'
    if isinstance(default, (list, tuple)):
        inner = _type(default[0]) if default else 'value'
        return f'{inner}[]'
    return type(default).__name__


def _default(default: object) -> str:
    if isinstance(default, str):
        return repr(default)
    if isinstance(default, (list, tuple)) and len(default) > 8:
        return f'{len(default)} values'
    return repr(list(default) if isinstance(default, tuple) else default)


def render() -> str:
    """The page's text."""
    from crane_stiffness.rosnode.parameters import node_modules

    lines = ['# Parameters', '',
             'Every parameter of every node, generated from its single declaration '
             '(`scripts/parameter_reference.py`; do not edit by hand). The unit is the bracket at the end of the '
             'description; "rule" is what the node checks on start and on every change (a rejected value keeps the '
             'old one and says why). `ros2 param describe <node> <name>` shows the same.', '']
    for name in sorted(node_modules()):
        module = importlib.import_module(f'crane_stiffness.nodes.{name}')
        lines += [f'## {name}', '', '| parameter | type | default | rule | description |', '|---|---|---|---|---|']
        for spec in module.PARAMS:
            lines.append(f'| `{spec.name}` | {_type(spec.default)} | {_cell(_default(spec.default))} | '
                         f'{_cell(spec.rule_text())} | {_cell(spec.description)} |')
        lines.append('')
    return '\n'.join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--check', action='store_true', help='exit 1 if docs/parameters.md is not up to date')
    args = ap.parse_args(argv)
    text = render()
    if args.check:
        if not PAGE.exists() or PAGE.read_text() != text:
            print(f'{PAGE} is out of date: run scripts/parameter_reference.py', file=sys.stderr)
            return 1
        return 0
    PAGE.write_text(text)
    print(f'wrote {PAGE}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
