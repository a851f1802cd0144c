"""crane_stiffness: stiffness test rig for the NIST six-wire parallel-link robot crane.

Its rooms (each subpackage says in its own docstring what it holds; the root holds only this face and the base
error, ``errors.py``):

- ``contract``: what the rig promises on the wire: topics, message types and QoS, axes, status levels, the 6×6
  layout, the absurd-command rule. Read it first to write a driver or a tool.
- ``model``: the physics, pure numpy/numba, no ROS: geometry and wire model, equilibrium, stiffness matrices.
- ``estimation``: the live and offline one-axis stiffness estimate (pure); ``full6``: the whole 6×6 from one test.
- ``sim``: simulated sensor models, load programs and simulated time (pure).
- ``params``: parameter declarations and ROS parameter YAML files, read by nodes and the command line alike.
- ``serde``: CDR encoding and decoding; ``bag``: rosbag2/MCAP reading and writing and the session record.
- ``analysis``, ``campaign``, ``design``: offline analysis, test campaigns and calibration, design over the workspace.
- ``drivers``, ``devices``: real F/T and DAQ protocols, and the device emulators they are tested against.
- ``nodes``: the node executables, thin rclpy adapters (``NODES``); ``rosnode``: what they share (``run``,
  parameters, QoS, diagnostics, the executables' entry); ``view``: the live view's pure parts and its page.
- ``launcher``: the rig as data (``rig_description``) and started as processes; ``cli``: the ``crane-stiffness``
  command line; ``testing``: helpers of the tests, demo and benchmarks.
"""

__version__ = '0.1.0'
#: The ROS package: its share/ and lib/ directories, the ament index entry, the launch files' package.
PACKAGE = 'crane_stiffness'
