"""Topic and service names, message types and QoS of the rig: the contract real drivers plug into.

Change a topic here and every node, the launch file, the recorder and the offline analysis follow.
Frames: ``crane_base`` is the paper's fixed frame (origin at the unloaded platform centre, z down); ``platform``
is the body frame; each sensor stamps its own ``frame_id`` (a parameter).
"""
from __future__ import annotations

from dataclasses import dataclass

# Commanded wrench on the platform [N, N·m], geometry_msgs/WrenchStamped, frame crane_base, reliable.
WRENCH_COMMAND = '/crane/wrench_command'
# The load the model has in force after each command it received, geometry_msgs/WrenchStamped [N, N·m], frame
# crane_base, reliable, stamped with that command's stamp: the command itself when accepted, the previous load when
# the model rejected it. The simulated sensors apply this, never the raw command.
APPLIED_WRENCH = '/crane/applied_wrench'
#: What a simulated force sensor (and its device emulator) waits for before it measures anything.
WAITING_FOR_LOAD = f'waiting for {APPLIED_WRENCH} (the load crane_model has in force)'
# Every command the model rejected (absurd, or no equilibrium), republished unchanged (its stamp too), reliable;
# the reason is on MODEL_STATUS and /diagnostics. The estimator excludes the time such a command was in force.
REJECTED_COMMAND = '/crane/rejected_command'
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
# Zero epochs of the sensors, std_msgs/Float64, latched: the number of zero (LVDT ``~/zero``) or tare/bias (load cell
# ``~/tare``) operations since the sensor node started [-] (0 = none yet; a whole number held in a float). Published
# at start (the simulated LVDT zeroing at its first pose: 1 then instead) and after every zero/tare, also by the
# real drivers (modbus_lvdt, netft). The estimator starts a new fit
# segment when the epoch changes while it holds readings of that sensor: a re-zero without a
# restart steps the readings, and the two zero points must not share a window. They are topics of their own: a user
# who remaps a sensor topic must remap its zero topic alongside (nothing does it for them); without them the
# estimator still works, it only cannot see a re-zero (a restart it sees by the sequence numbers).
LVDT_ZERO = '/lvdt/zero'
LOAD_CELL_TARE = '/load_cell/tare'
# Pose sensor (vrpn_mocap publishes the same; mocap4r2's RigidBodies need a relay), geometry_msgs/PoseStamped:
# the platform centre's position [m] and orientation (quaternion, body -> frame) in frame_id (crane_base), sensor-data
# QoS. What the 6x6 identification measures deflections with (crane_stiffness.full6).
POSE_SENSOR_POSE = '/pose_sensor/pose'
# The pose an LVDT array solves (node lvdt_array, which publishes it on POSE_SENSOR_POSE too),
# geometry_msgs/PoseWithCovarianceStamped: the same pose and stamp, with the covariance the LVDTs' noise propagates
# to, 6x6 row-major in the order x y z, rotation about the fixed x y z [m², m·rad, rad²], sensor-data QoS.
LVDT_ARRAY_POSE = '/lvdt_array/pose'
# The 6x6 identification (crane_stiffness.full6, node stiffness6_estimator), std_msgs/Float64MultiArray laid out as
# dims ('quantity', 3: value, ci95_low, ci95_high) x ('row', 6) x ('column', 6), row-major; rows and columns in the
# order fx fy fz mx my mz (loads) and ux uy uz thx thy thz (deflections): STIFFNESS6 K [N/m, N/rad, N·m/m, N·m/rad],
# COMPLIANCE6 C = K^-1. Both written and read only through crane_stiffness.contract.stiffness6_layout (labels, strides,
# the
# (3, 6, 6) array). STIFFNESS6_STATUS: diagnostic_msgs/DiagnosticArray (level, message, the numbers behind it).
STIFFNESS6 = '/stiffness6/stiffness'
# STIFFNESS6_EXPANDED: the same K with its expanded uncertainty U (GUM law of propagation, 95 %, from the step means
# and the sensors' declared calibrations: crane_stiffness.full6.live_uncertainty), in the same layout: quantity
# (value, value - U, value + U) x row x column; NaN ends where no U is stated (the status's 'uncertainty' says why).
# Published with every STIFFNESS6 message, of the same fit.
STIFFNESS6_EXPANDED = '/stiffness6/stiffness_expanded'
COMPLIANCE6 = '/stiffness6/compliance'
STIFFNESS6_STATUS = '/stiffness6/status'
# Estimates: diagnostic_msgs/DiagnosticArray for people, std_msgs/Float64MultiArray for plots (see
# crane_stiffness.nodes.stiffness_estimator.VALUE_FIELDS), std_msgs/Float64 for the headline number.
STIFFNESS_ESTIMATE = '/stiffness/estimate'
STIFFNESS_VALUES = '/stiffness/estimate_values'
STIFFNESS = '/stiffness/stiffness'
DIAGNOSTICS = '/diagnostics'
# For looking, not recorded (the estimate topics above hold the numbers): std_msgs/Float64MultiArray, reliable.
# FITTED_PAIRS: the pairs the estimator fitted since its previous message, rows × PAIR_FIELDS of
# crane_stiffness.estimation.live (stamp s, displacement m or rad, force N or N·m, branch 0 loading / 1 unloading,
# segment); about 20 messages a second. FIT_LINES: each branch's window as a line with its 95 % band, rows loading,
# unloading × FIT_LINE_FIELDS, at the estimator's diagnostics rate.
FITTED_PAIRS = '/stiffness/fitted_pairs'
FIT_LINES = '/stiffness/fit_lines'

# Simulated time (crane_stiffness.sim.lockstep): the clock source publishes the time on /clock
# (rosgraph_msgs/Clock, as Gazebo does; every node of the simulated rig runs with use_sim_time) and, with it, one
# watermark per stage on SIM_WATERMARKS; each participant reports its progress on SIM_PROGRESS. Both std_msgs/String
# holding JSON, reliable, volatile (the fields: crane_stiffness.rosnode.sim_time).
CLOCK = '/clock'
SIM_WATERMARKS = '/sim/watermarks'
SIM_PROGRESS = '/sim/progress'

FRAME_BASE = 'crane_base'
FRAME_PLATFORM = 'platform'

#: Every topic the rig publishes, with its type: what the recorder records by default.
RIG_TOPICS: dict[str, str] = {
    WRENCH_COMMAND: 'geometry_msgs/msg/WrenchStamped',
    APPLIED_WRENCH: 'geometry_msgs/msg/WrenchStamped',
    REJECTED_COMMAND: 'geometry_msgs/msg/WrenchStamped',
    PLATFORM_POSE: 'geometry_msgs/msg/PoseStamped',
    WIRE_STATES: 'sensor_msgs/msg/JointState',
    PREDICTED_STIFFNESS: 'std_msgs/msg/Float64MultiArray',
    PREDICTED_AXIS_STIFFNESS: 'std_msgs/msg/Float64',
    PROGRAM_PROGRESS: 'std_msgs/msg/Float64',
    PROGRAM_STATE: 'std_msgs/msg/String',
    LOAD_CELL_WRENCH: 'geometry_msgs/msg/WrenchStamped',
    LVDT_DISPLACEMENT: 'geometry_msgs/msg/PointStamped',
    LVDT_ZERO: 'std_msgs/msg/Float64',
    LOAD_CELL_TARE: 'std_msgs/msg/Float64',
    STIFFNESS_ESTIMATE: 'diagnostic_msgs/msg/DiagnosticArray',
    STIFFNESS_VALUES: 'std_msgs/msg/Float64MultiArray',
    STIFFNESS: 'std_msgs/msg/Float64',
    POSE_SENSOR_POSE: 'geometry_msgs/msg/PoseStamped',
    STIFFNESS6: 'std_msgs/msg/Float64MultiArray',
    STIFFNESS6_EXPANDED: 'std_msgs/msg/Float64MultiArray',
    COMPLIANCE6: 'std_msgs/msg/Float64MultiArray',
    STIFFNESS6_STATUS: 'diagnostic_msgs/msg/DiagnosticArray',
}


@dataclass(frozen=True)
class QoS:
    """A class of QoS: reliability and durability as rosbag2 and rmw name the policies, and the KEEP_LAST depth of
    the rig's publishers (and of the subscribers that must keep up with them). History is always KEEP_LAST."""

    reliability: str  # 'reliable' | 'best_effort'
    durability: str   # 'volatile' | 'transient_local'
    depth: int


#: Sensor streams use best-effort delivery (so reliable and best-effort publishers both match a subscriber) with
#: a deeper queue than rclpy's qos_profile_sensor_data (5), because DAQ drivers publish in bursts: 1 s at 1 kHz.
#: A sensor stalled for a moment (Fast DDS matching a node that joins can block a publisher for ~0.3 s) publishes
#: its backlog at once; a 200-deep queue lost the burst's oldest samples.
SENSOR_QUEUE_DEPTH = 1000
SENSOR_DATA = QoS('best_effort', 'volatile', SENSOR_QUEUE_DEPTH)
#: Commands and model outputs: nothing may be lost. 1000 deep = 10 s of commands at 100 Hz, so a reader starved of CPU
#: for a while (a recorder on a busy machine) catches up instead of losing what the writer overwrote.
RELIABLE = QoS('reliable', 'volatile', 1000)
#: Latest-value topics a late joiner should still get (program state, predicted stiffness, model status).
LATCHED = QoS('reliable', 'transient_local', 1)
#: The estimator's values for tools: nothing lost, and a reader that joins late still gets the recent ones (DDS may
#: match a reader seconds after it starts; a campaign's observer, or a page opened later): 1000, ~50 s at 20 Hz. What
#: people read (the status, the headline number, the 6x6 fit) is LATCHED: a late reader gets the latest only.
KEPT = QoS('reliable', 'transient_local', 1000)

#: The QoS of every topic of the contract, the one table the rest is built from: the nodes' rclpy profiles
#: (crane_stiffness.rosnode.run), the recorder's and player's QoS (crane_stiffness.rosnode.session_qos) and the
#: offered QoS a synthetic session records (crane_stiffness.testing.synthetic).
TOPIC_QOS: dict[str, QoS] = {
    WRENCH_COMMAND: RELIABLE,
    APPLIED_WRENCH: RELIABLE,
    REJECTED_COMMAND: RELIABLE,
    PLATFORM_POSE: RELIABLE,
    WIRE_STATES: RELIABLE,
    PREDICTED_STIFFNESS: LATCHED,
    PREDICTED_AXIS_STIFFNESS: LATCHED,
    MODEL_STATUS: LATCHED,
    PROGRAM_PROGRESS: LATCHED,
    PROGRAM_STATE: LATCHED,
    LOAD_CELL_WRENCH: SENSOR_DATA,
    LVDT_DISPLACEMENT: SENSOR_DATA,
    LVDT_ZERO: LATCHED,
    LOAD_CELL_TARE: LATCHED,
    STIFFNESS_ESTIMATE: LATCHED,  # for people: a late reader (`ros2 topic echo --once`) gets the latest
    STIFFNESS_VALUES: KEPT,  # for tools: a reader matched late still gets the run's estimates (up to 1000)
    STIFFNESS: LATCHED,
    POSE_SENSOR_POSE: SENSOR_DATA,
    LVDT_ARRAY_POSE: SENSOR_DATA,
    STIFFNESS6: LATCHED,  # the latest fit is what a late reader (`ros2 topic echo --once`) wants
    STIFFNESS6_EXPANDED: LATCHED,
    COMPLIANCE6: LATCHED,
    STIFFNESS6_STATUS: LATCHED,
    FITTED_PAIRS: RELIABLE,
    FIT_LINES: RELIABLE,
}

#: Topics published for the live view only (not in RIG_TOPICS: the recorder does not record them by default).
VIEW_TOPICS: dict[str, str] = {
    FITTED_PAIRS: 'std_msgs/msg/Float64MultiArray',
    FIT_LINES: 'std_msgs/msg/Float64MultiArray',
}

#: The recorder's subscriptions and the player's publishers are at least this deep: a latched topic's publishers
#: keep one value, but progress is published at the command rate and the recorder must not lose updates while it
#: writes. Also the depth for topics outside the table (their publishers' depth is unknown: DDS does not tell).
RECORD_QUEUE_DEPTH = 100
