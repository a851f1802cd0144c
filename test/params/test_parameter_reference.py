"""docs/parameters.md is generated from the parameters' single declarations and must match them."""
from __future__ import annotations

import importlib.util

from helpers import REPO


def test_the_parameter_reference_is_the_declarations():
    spec = importlib.util.spec_from_file_location('parameter_reference', REPO / 'scripts' / 'parameter_reference.py')
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    text = module.render()
    assert (REPO / 'docs' / 'parameters.md').read_text() == text, \
        'docs/parameters.md is out of date: run .venv/bin/python scripts/parameter_reference.py'
    # every parameter of the estimator is there, with its rule
    assert '| `slop_s` | float | 0.0006 | >= 0 |' in text
    assert '| `force_axis` | str | \'fy\' | one of fx, fy, fz, mx, my, mz |' in text
