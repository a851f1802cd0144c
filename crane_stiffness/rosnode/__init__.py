"""What every node of the package shares (the nodes themselves are :mod:`crane_stiffness.nodes`):

- ``run``: every node's ``main`` (start-up checks, executor, signals, clean shutdown, final counters) and
  :class:`~crane_stiffness.rosnode.run.RunnableNode`, what it reads of a node;
- ``parameters``: declaring and checking a node's parameters, the --params-file checks; ``parameter_reader``:
  reading other nodes' parameters over ROS; ``device_params``: the checks the driver and emulator nodes share;
- ``qos``, ``session_qos``: QoS profiles (those of recorded and replayed topics);
- ``diagnostics``: counters, status and input lag on /diagnostics; ``messages``: small helpers over messages;
- ``sensor_timing``: what the simulated sensors share; ``sim_time``: a node's part in simulated time;
- ``malloc_trim``: handing freed memory back to the system in a long-running node;
- ``session_recorder_params``: the session recorder's parameters and their validation;
- ``entry``: the node executables' entry points (signals held from the first instant); ``discovery``: the Fast DDS
  profile (``fastdds_discovery.xml``) that lets nodes started at once find each other quickly.
"""
