"""The rig as data and the rig started as processes.

- ``rig_description.py``: which nodes the rig runs with which parameter files, parameters and arguments (pure; the
  launch file ``launch/rig.launch.py``, the demo and the tests read it).
- ``rosrun.py``: starting the nodes the way ``ros2 run`` / ``ros2 launch`` start them; ``rig.py``: the whole
  simulated rig with its observer and run summary (``campaign run``, the demo, the tests and the benchmarks);
  ``summary6.py``: the 6×6 lines of the run summary; ``ports.py``: free TCP and UDP ports.
"""
