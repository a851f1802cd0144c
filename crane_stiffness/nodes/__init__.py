"""The package's nodes, one executable each: ``crane_stiffness.nodes.<name>`` holds the node and its ``main`` (and
``PARAMS``, the parameters it declares), installed as ``<prefix>/lib/crane_stiffness/<name>`` for ``ros2 run``.

:data:`NODES` is the one list of them: setup.py installs ``nodes_bin/<name>`` for each (and refuses a build where
nodes_bin/ differs), :func:`crane_stiffness.rosnode.parameters.node_modules` imports them, and
:mod:`crane_stiffness.rosnode.entry` starts only these. What the nodes share (``run``, parameters, QoS, diagnostics,
...) is
:mod:`crane_stiffness.rosnode`. This module imports nothing: the entry points and setup.py read it before anything
heavy is loaded.
"""

#: The node executables, by name (module ``crane_stiffness.nodes.<name>``, script ``nodes_bin/<name>``).
NODES = (
    'crane_model',
    'live_view',
    'load_cell',
    'load_program',
    'lvdt',
    'lvdt_array',
    'modbus_emulator',
    'modbus_lvdt',
    'netft',
    'pose_sensor',
    'rdt_emulator',
    'session_player',
    'session_recorder',
    'sim_clock',
    'stiffness6_estimator',
    'stiffness_estimator',
)
