"""The whole simulated rig: crane model, load program, simulated load cell and LVDT, stiffness estimator, and the
session recorder, as crane_stiffness.launcher.rig_description describes it (its nodes, their parameter files and
parameters,
the arguments; the demo and the tests start the same nodes). All nodes start at once; load_program starts the
program when the rig is ready (it is told what to wait for: the nodes started here). An unknown program or a missing
parameter file stops the launch at once with an error naming the file (rig_description.RigError).

    ros2 launch crane_stiffness rig.launch.py program:=side_force record:=true
    ros2 launch crane_stiffness rig.launch.py transport:=drivers     # through RDT/Modbus emulators and the drivers
    ros2 launch crane_stiffness rig.launch.py transport:=drivers sim_sensors:=false \
        drivers:=/path/to/drivers_ati_labjack.yaml                  # real hardware
    ros2 launch crane_stiffness rig.launch.py --show-args
"""
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare

from crane_stiffness.launcher.rig_description import ARGUMENTS, PACKAGE, rig_nodes

CONFIG = PathJoinSubstitution([FindPackageShare(PACKAGE), 'config'])


def rig(context):
    """The rig's nodes for the launch arguments (crane_stiffness.launcher.rig_description.rig_nodes)."""
    given = {a.name: LaunchConfiguration(a.name).perform(context) for a in ARGUMENTS}
    return [Node(package=PACKAGE, executable=n.executable, name=n.name,
                 parameters=[*n.parameter_files, n.parameters] if n.parameters else list(n.parameter_files),
                 remappings=list(n.remappings), output='screen')
            for n in rig_nodes(CONFIG.perform(context), given)]


def generate_launch_description() -> LaunchDescription:
    return LaunchDescription([
        # Plain defaults (`--show-args` prints them as written): a bare file name names a file of the package's
        # config/ (rig_description.config_path).
        *(DeclareLaunchArgument(a.name, description=a.description, default_value=a.default) for a in ARGUMENTS),
        OpaqueFunction(function=rig),
    ])
