"""Helpers for tests, benchmarks and the demo (installed, like numpy.testing, because scripts/demo.py and the
benchmarks use them too); nothing in the package proper imports them.

- ``rosrun.py``: start nodes the way ``ros2 run`` does, from a colcon install tree (also ``python -m``).
- ``rig.py``: the simulated rig as separate node processes, wired from crane_stiffness.rig_description.
- ``synthetic.py``: synthetic session bags, as session_recorder writes them, with their truth.
"""
