"""crane_stiffness: stiffness test rig for the NIST six-wire parallel-link robot crane.

Layout (where to change what):

- ``crane_stiffness.model``: the physics, pure numpy/numba, no ROS. Wire model and geometry in ``geometry.py``,
  equilibrium solver in ``equilibrium.py`` and ``_kernels.py``, stiffness matrices in ``stiffness.py``.
- ``crane_stiffness.estimation``: fitting force against displacement (pure).
- ``crane_stiffness.sim``: simulated sensor models and load programs (pure).
- ``crane_stiffness.bag``: MCAP / rosbag2 reading and writing (no ROS needed to read).
- ``crane_stiffness.nodes``: thin rclpy adapters, one executable each (``NODES``); what they share (``run``,
  parameters, QoS, diagnostics) is ``crane_stiffness.rosnode``; topic names live in ``crane_stiffness.topics``.
- ``crane_stiffness.cli``: the ``crane-stiffness`` command line.
"""

__version__ = '0.1.0'
#: The ROS package: its share/ and lib/ directories, the ament index entry, the launch files' package.
PACKAGE = 'crane_stiffness'
