"""Agreement of a measured value with a reference value: the normalised error E_n (ISO 13528:2022, 9.7).

    E_n = (x_measured − x_reference) / √(U_measured² + U_reference²),

with both expanded uncertainties U at about 95 % coverage (k ≈ 2). |E_n| <= 1: the two agree within their stated
uncertainties; |E_n| > 1: they do not (an "action signal" in ISO 13528's words). For this rig the measured value is
the estimated stiffness, the reference the model's prediction (:mod:`.prediction`), each with its own U.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from crane_stiffness.uncertainty.errors import InputError


@dataclass(frozen=True)
class Agreement:
    """E_n of a measured value against a reference, the verdict and a sentence for people."""

    measured: float
    U_measured: float
    reference: float
    U_reference: float
    en: float
    agrees: bool
    unit: str = ''

    @property
    def sentence(self) -> str:
        unit = f' {self.unit}' if self.unit else ''
        verdict = ('agree within their expanded uncertainties' if self.agrees
                   else 'do not agree within their expanded uncertainties')
        return (f'measured {self.measured:.6g} ± {self.U_measured:.4g}{unit} and reference {self.reference:.6g} '
                f'± {self.U_reference:.4g}{unit} {verdict} (E_n = {self.en:+.2f}, |E_n| <= 1 agrees)')

    def to_dict(self) -> dict[str, Any]:
        return {'measured': self.measured, 'U_measured': self.U_measured, 'reference': self.reference,
                'U_reference': self.U_reference, 'en': self.en, 'agrees': self.agrees, 'unit': self.unit,
                'sentence': self.sentence}


def _number(field: str, value: float, *, uncertainty: bool = False) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise InputError(field, value, 'must be a number') from None
    if not math.isfinite(x):
        raise InputError(field, value, 'must be finite')
    if uncertainty and x < 0.0:
        raise InputError(field, value, 'an expanded uncertainty must be >= 0')
    return x


def en_number(measured: float, U_measured: float, reference: float, U_reference: float, *,
              unit: str = '') -> Agreement:
    """E_n of ``measured`` ± ``U_measured`` against ``reference`` ± ``U_reference`` (both U at ~95 %)."""
    x = _number('measured', measured)
    ux = _number('U_measured', U_measured, uncertainty=True)
    ref = _number('reference', reference)
    uref = _number('U_reference', U_reference, uncertainty=True)
    scale = math.hypot(ux, uref)
    if scale == 0.0:
        raise InputError('U_measured', ux, 'E_n needs U_measured or U_reference > 0')
    en = (x - ref) / scale
    return Agreement(x, ux, ref, uref, en, abs(en) <= 1.0, unit)
