"""The rig's watch on its program (launcher.rig.ProgramWatch) gives up on a program whose progress stalls past its
length, but not on one that says it is waiting for someone (an operator applying a level, a tare): that takes as
long as the person takes."""
from __future__ import annotations

import time

from crane_stiffness.launcher.rig import ProgramWatch


def test_a_stalled_program_is_given_up_but_a_holding_one_is_not():
    stalled = ProgramWatch(duration_s=0.0, margin_s=0.0, stall_s=0.2)
    holding = ProgramWatch(duration_s=0.0, margin_s=0.0, stall_s=0.2)
    assert not stalled.expired(0.4) and not holding.expired(0.4, holding=True)
    time.sleep(0.3)  # (at least this long: past the stall time whatever the load)
    assert stalled.expired(0.4)
    assert not holding.expired(0.4, holding=True)
    time.sleep(0.3)
    assert holding.expired(0.4)  # once it no longer waits, the same progress for the stall time is a stall
