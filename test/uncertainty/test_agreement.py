"""E_n (ISO 13528): the number, the verdict at |E_n| <= 1, the sentence, bad input refused."""
from __future__ import annotations

import math

import pytest

from crane_stiffness.uncertainty.agreement import en_number
from crane_stiffness.uncertainty.errors import InputError


def test_en_cases():
    ok = en_number(53792.9, 3300.0, 53793.5, 3284.0, unit='N/m')
    assert ok.en == pytest.approx(-0.6 / math.hypot(3300.0, 3284.0)) and ok.agrees
    assert 'agree within' in ok.sentence and 'N/m' in ok.sentence and 'E_n = -0.00' in ok.sentence
    far = en_number(10.0, 0.3, 9.0, 0.4)
    assert far.en == pytest.approx(2.0) and not far.agrees and 'do not agree' in far.sentence
    below = en_number(9.0, 0.3, 10.0, 0.4)
    assert below.en == pytest.approx(-2.0) and not below.agrees
    edge = en_number(10.5, 0.3, 10.0, 0.4)  # exactly 1: agrees (|E_n| <= 1)
    assert edge.en == pytest.approx(1.0) and edge.agrees
    exact_reference = en_number(10.1, 0.2, 10.0, 0.0)
    assert exact_reference.en == pytest.approx(0.5) and exact_reference.to_dict()['agrees'] is True


@pytest.mark.parametrize('args, field', [((1.0, -0.1, 1.0, 0.1), 'U_measured'), ((1.0, 0.1, 1.0, -0.1), 'U_reference'),
                                         ((float('nan'), 0.1, 1.0, 0.1), 'measured'),
                                         ((1.0, 0.1, float('inf'), 0.1), 'reference'), ((1.0, 0.0, 1.0, 0.0),
                                                                                      'U_measured')])
def test_bad_input_is_refused_naming_the_field(args, field):
    with pytest.raises(InputError) as info:
        en_number(*args)
    assert info.value.field == field
