"""One parameter, declared once: name, default (its type is the parameter's type), description with the unit, and
its rule. No ROS import.

A :class:`ParamSpec` is what a node declares (crane_stiffness.rosnode.parameters turns it into the descriptor
``ros2 param describe`` shows and checks values against it), what the offline CLI turns into a flag, and what the
docs' parameter reference lists. Settings classes of the pure cores (e.g. the live estimator's settings) declare their
fields with :func:`declared`; :func:`specs_of` gives their specs, and :func:`check_spec` is the one check of a value
against its declared rule, used by the cores' own validation and by the nodes alike.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

from crane_stiffness.errors import ParameterError

SPEC_KEY = 'crane_stiffness.param'  # where declared() keeps a field's spec in the dataclass field's metadata


@dataclass(frozen=True)
class ParamSpec:
    """One parameter: name, default (its type is the parameter's type), description with the unit in brackets.

    ``low``/``high`` bound a number (inclusive; they become the descriptor's ``floating_point_range`` or
    ``integer_range``, which rclpy enforces too, with its own wording, before the node's checks); ``at_least``,
    ``at_most`` (inclusive) and ``above`` (exclusive) bound a number and ``choices`` list the allowed values of a
    string: checked by :func:`check_spec` (the node's wording, ``name = value: must be ...``) and shown in the
    descriptor's words; ``rule`` is any remaining rule in words (e.g. '<= max_age_s'), checked by the owner's own
    validation.
    """

    name: str
    default: Any
    description: str
    low: float | int | None = None
    high: float | int | None = None
    rule: str = ''
    above: float | None = None
    at_least: float | None = None
    at_most: float | None = None
    choices: tuple[str, ...] = ()

    def rule_text(self) -> str:
        """The whole rule in words ('0 .. 1', '> 0; <= max_age_s', 'one of fx, fy'), '' when there is none."""
        parts = []
        if self.choices:
            parts.append('one of ' + ', '.join(self.choices))
        if self.above is not None:
            parts.append(f'> {self.above:g}')
        if self.at_least is not None:
            parts.append(f'>= {self.at_least:g}')
        if self.at_most is not None:
            parts.append(f'<= {self.at_most:g}')
        if self.low is not None or self.high is not None:
            parts.append(range_text(self))
        if self.rule:
            parts.append(self.rule)
        return '; '.join(parts)

    @property
    def unit(self) -> str:
        """The unit the description ends with in brackets ('m', 'N/m', '-'), '' when it names none."""
        text = self.description.rstrip()
        if text.endswith(']') and '[' in text:
            return text[text.rindex('[') + 1:-1]
        return ''


def range_text(spec: ParamSpec) -> str:
    """The inclusive range of ``spec`` in words: '0 .. 1', '>= 0' or '<= 5'."""
    if spec.low is not None and spec.high is not None:
        return f'{spec.low} .. {spec.high}'
    return f'>= {spec.low}' if spec.low is not None else f'<= {spec.high}'


def is_number(value: Any) -> bool:
    """A Python int or float, not a bool."""
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def check_spec(spec: ParamSpec, value: Any) -> None:
    """Check ``value`` against the declared rule of ``spec`` (choices; for a number: finite, ``above``, ``low``,
    ``high``). Raises :class:`~crane_stiffness.errors.ParameterError` ('name = value: must be ...'). The type and
    the rule in words (``rule``) are the owner's to check."""
    if spec.choices:
        if value not in spec.choices:
            raise ParameterError(spec.name, value, f'must be one of {", ".join(spec.choices)}')
        return
    bounds = (spec.above, spec.at_least, spec.at_most, spec.low, spec.high)
    if all(b is None for b in bounds):
        return
    if not is_number(value) or not math.isfinite(value):
        raise ParameterError(spec.name, value, 'must be a finite number')
    if spec.above is not None and value <= spec.above:
        raise ParameterError(spec.name, value, f'must be > {spec.above:g}')
    if spec.at_least is not None and value < spec.at_least:
        raise ParameterError(spec.name, value, f'must be >= {spec.at_least:g}')
    if spec.at_most is not None and value > spec.at_most:
        raise ParameterError(spec.name, value, f'must be <= {spec.at_most:g}')
    if (spec.low is not None and value < spec.low) or (spec.high is not None and value > spec.high):
        raise ParameterError(spec.name, value, f'must be {range_text(spec)}')


def declared(default: Any, description: str, **rule: Any) -> Any:
    """A dataclass field that declares its parameter: the default, the description with the unit in brackets, and
    the rule (``low``, ``high``, ``above``, ``at_least``, ``at_most``, ``choices``, ``rule``; see :class:`ParamSpec`).
    Its name is the field's."""
    meta = {SPEC_KEY: (description, rule)}
    if isinstance(default, (list, dict)):
        raise TypeError('declared(): a mutable default; give a tuple')
    return dataclasses.field(default=default, metadata=meta)


def specs_of(settings: Any, prefix: str = '') -> tuple[ParamSpec, ...]:
    """The :class:`ParamSpec` of every field of the dataclass ``settings`` declared with :func:`declared`, in field
    order (a tuple default becomes a list: a ROS array parameter)."""
    out = []
    for f in dataclasses.fields(settings):
        if SPEC_KEY not in f.metadata:
            continue
        description, rule = f.metadata[SPEC_KEY]
        default = list(f.default) if isinstance(f.default, tuple) else f.default
        out.append(ParamSpec(prefix + f.name, default, description, **rule))
    return tuple(out)


__all__ = ['ParamSpec', 'check_spec', 'declared', 'is_number', 'range_text', 'specs_of']
