"""Topic and service names, message types and QoS of the rig: the contract real drivers plug into.

Change a topic here and every node, the launch file, the recorder and the offline analysis follow.
Frames: ``crane_base`` is the paper's fixed frame (origin at the unloaded platform centre, z down); ``platform``
is the body frame; each sensor stamps its own ``frame_id`` (a parameter).
"""
from __future__ import annotations

# Commanded wrench on the platform [N, N·m], geometry_msgs/WrenchStamped, frame crane_base, reliable.
WRENCH_COMMAND = '/crane/wrench_command'
# Platform pose, geometry_msgs/PoseStamped, frame crane_base (z down), reliable.
PLATFORM_POSE = '/crane/platform_pose'
# Wire lengths [m] and tensions [N], sensor_msgs/JointState (names wire_1..wire_6; position, effort).
WIRE_STATES = '/crane/wire_states'
# Tangent stiffness at the current equilibrium, std_msgs/Float64MultiArray 6×6 row-major, order
# [u_x, u_y, u_z, θ_x, θ_y, θ_z].
PREDICTED_STIFFNESS = '/crane/predicted_stiffness'
# Predicted stiffness along the commanded axis (other DOFs free), std_msgs/Float64 [N/m or N·m/rad].
PREDICTED_AXIS_STIFFNESS = '/crane/predicted_axis_stiffness'
# The model's state, std_msgs/String 'ok: N slack wire(s)' or 'no_equilibrium: ...', transient local.
MODEL_STATUS = '/crane/model_status'
# Load program progress, std_msgs/Float64 in [0, 1], and its state, std_msgs/String.
PROGRAM_PROGRESS = '/load_program/progress'
PROGRAM_STATE = '/load_program/state'
# Load cell, geometry_msgs/WrenchStamped [N, N·m] in the sensor frame, sensor-data QoS.
LOAD_CELL_WRENCH = '/load_cell/wrench'
# LVDT, geometry_msgs/PointStamped: point.x = reading [m] along the sensor axis, sensor-data QoS.
LVDT_DISPLACEMENT = '/lvdt/displacement'
# Estimates: diagnostic_msgs/DiagnosticArray for people, std_msgs/Float64MultiArray for plots (see
# crane_stiffness.nodes.stiffness_estimator.VALUE_FIELDS), std_msgs/Float64 for the headline number.
STIFFNESS_ESTIMATE = '/stiffness/estimate'
STIFFNESS_VALUES = '/stiffness/estimate_values'
STIFFNESS = '/stiffness/stiffness'
DIAGNOSTICS = '/diagnostics'

FRAME_BASE = 'crane_base'
FRAME_PLATFORM = 'platform'

#: Every topic the rig publishes, with its type: what the recorder records by default.
RIG_TOPICS: dict[str, str] = {
    WRENCH_COMMAND: 'geometry_msgs/msg/WrenchStamped',
    PLATFORM_POSE: 'geometry_msgs/msg/PoseStamped',
    WIRE_STATES: 'sensor_msgs/msg/JointState',
    PREDICTED_STIFFNESS: 'std_msgs/msg/Float64MultiArray',
    PREDICTED_AXIS_STIFFNESS: 'std_msgs/msg/Float64',
    PROGRAM_PROGRESS: 'std_msgs/msg/Float64',
    PROGRAM_STATE: 'std_msgs/msg/String',
    LOAD_CELL_WRENCH: 'geometry_msgs/msg/WrenchStamped',
    LVDT_DISPLACEMENT: 'geometry_msgs/msg/PointStamped',
    STIFFNESS_ESTIMATE: 'diagnostic_msgs/msg/DiagnosticArray',
    STIFFNESS_VALUES: 'std_msgs/msg/Float64MultiArray',
    STIFFNESS: 'std_msgs/msg/Float64',
}

#: Sensor streams use best-effort delivery (so reliable and best-effort publishers both match a subscriber) with
#: a deeper queue than rclpy's qos_profile_sensor_data (5), because DAQ drivers publish in bursts: 1 s at 1 kHz.
#: A sensor stalled for a moment (Fast DDS matching a node that joins can block a publisher for ~0.3 s) publishes
#: its backlog at once; a 200-deep queue lost the burst's oldest samples.
SENSOR_QUEUE_DEPTH = 1000
