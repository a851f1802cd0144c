"""What the rig promises on the wire: read this first to write a driver, a tool or a page that talks to the rig.

Everything here is plain Python (numpy at most), no ROS import: nodes, the offline analysis and tools all read the
same definitions, so a change here is a change everywhere.

- ``topics.py``: every topic and service name, its message type and its QoS (``TOPIC_QOS``), the frames
  (``crane_base``: the paper's fixed frame, z down; ``platform``). A real sensor joins the rig by publishing what the
  simulated one publishes, under the same name or remapped onto it:

  - a 6-axis load cell: ``geometry_msgs/WrenchStamped`` [N, N·m] on ``/load_cell/wrench`` in its own frame
    (``frame_id``), sensor-data QoS (best effort, volatile), stamped at the instant of the sample; its tare count
    (``std_msgs/Float64``, latched) on ``/load_cell/tare``;
  - an LVDT: ``geometry_msgs/PointStamped`` on ``/lvdt/displacement``, ``point.x`` the reading [m] along its axis,
    sensor-data QoS; its zero count on ``/lvdt/zero`` (the estimator also takes a DAQ's ``std_msgs/Float64`` in
    volts with a gain and an offset: its parameters);
  - a pose sensor: ``geometry_msgs/PoseStamped`` of the platform centre in ``crane_base`` on ``/pose_sensor/pose``.
- ``axes.py``: the six load axes in the one order used everywhere, ``fx fy fz mx my mz`` (and the matching
  deflections ``ux uy uz thx thy thz``).
- ``status.py``: the status levels WAITING, OK, WARN, ERROR, STALE, what each means, and how WAITING travels in a
  ``diagnostic_msgs/DiagnosticStatus`` (OK with a message that starts "waiting").
- ``stiffness6_layout.py``: the layout of ``/stiffness6/stiffness`` and ``/stiffness6/compliance`` (value and 95 %
  interval of every entry of the 6×6 matrix, labels and strides), both directions.
- ``publishers.py``: which node publishes each rig topic (the simulated sensor or the driver), so a wait that times
  out names the node that should have published.
- ``command_limits.py``: which commanded wrenches are absurd (not finite, or beyond the force and moment limits): the
  model rejects them and the estimator leaves out the time they were in force.
- ``control_events.py``: who asked a node to stop, tare or reset: the control event a caller (the live view) publishes
  on ``/rig/control_events`` before it calls a ``std_srvs/Trigger`` service, naming its client; the serving node
  records or logs it (the recorder: ``stopped_by`` in the session end), else says "a ROS service client".
- The live estimate's statuses on ``/stiffness/estimate`` (``diagnostic_msgs/DiagnosticArray``): each branch's
  key/values carry, beside the fit's numbers (``ci95_low``/``ci95_high``: the repeatability), its measurement
  uncertainty ``U`` (expanded, 95 %), ``U_low``/``U_high`` (k ∓ U), ``coverage_factor``, ``u_c``, ``nu_eff``,
  ``prediction_U`` (the model's U), ``En`` (E_n against the model), ``statistical_only`` and ``calibration`` (what U
  counts); |E_n| > 1 is WARN.
"""
