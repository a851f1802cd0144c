"""Helpers for tests, benchmarks and the demo (installed, like numpy.testing, because scripts/demo.py and the
benchmarks use them too); nothing in the package proper imports them.

- ``synthetic.py``: synthetic session bags, as session_recorder writes them, with their truth.
- ``synthetic_full6.py``: synthetic (wrench, pose deflection) pairs of a multi-axis program, with their truth.
- ``synthetic_full6_bag.py``: synthetic six-axis session bags (load cell, pose sensor, commands), with their truth.
- ``lab_network.py``: the rig split across two network namespaces (the lab network test).

Starting nodes as ``ros2 run`` does and the simulated rig as processes are in crane_stiffness.launcher (the
campaign runner uses them).
"""
