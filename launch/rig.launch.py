"""The whole simulated rig: crane model, load program, simulated load cell and LVDT, stiffness estimator, and the
session recorder, as crane_stiffness.launcher.rig_description describes it (its nodes, their parameter files and
parameters,
the arguments; the demo and the tests start the same nodes). All nodes start at once; load_program starts the
program when the rig is ready (it is told what to wait for: the nodes started here). An unknown program or a missing
parameter file stops the launch at once with an error naming the file (rig_description.RigError), and so does what
can only be a typo: an argument the rig does not declare (``transprot:=drivers``: launch itself takes any
``name:=value``) or a parameter-file section no node of the rig reads, each with the closest declared name.

    ros2 launch crane_stiffness rig.launch.py program:=side_force record:=true
    ros2 launch crane_stiffness rig.launch.py transport:=drivers     # through RDT/Modbus emulators and the drivers
    ros2 launch crane_stiffness rig.launch.py transport:=drivers sim_sensors:=false \
        drivers:=/path/to/drivers_ati_labjack.yaml                  # real hardware
    ros2 launch crane_stiffness rig.launch.py --show-args
"""
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction, RegisterEventHandler
from launch.event_handlers import OnProcessExit
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare

from crane_stiffness.launcher.rig_description import (ARGUMENTS, PACKAGE, SIGKILL_AFTER_S, RigError,
                                                     check_argument_names, exit_problem, rig_nodes)

CONFIG = PathJoinSubstitution([FindPackageShare(PACKAGE), 'config'])


def rig(context):
    """The rig's nodes for the launch arguments (crane_stiffness.launcher.rig_description.rig_nodes)."""
    # `ros2 launch` puts every name:=value of the command line into the launch configurations, declared or not
    # (beside the declared arguments' defaults and launch's own): a name the rig does not declare is a typo.
    check_argument_names(context.launch_configurations)
    given = {a.name: LaunchConfiguration(a.name).perform(context) for a in ARGUMENTS}
    return [Node(package=PACKAGE, executable=n.executable, name=n.name,
                 parameters=[*n.parameter_files, n.parameters] if n.parameters else list(n.parameter_files),
                 remappings=list(n.remappings), output='screen',
                 # a node still starting on a busy machine at Ctrl-C ends cleanly once started: not killed at 10 s
                 sigkill_timeout=LaunchConfiguration('sigkill_timeout', default=str(SIGKILL_AFTER_S)))
            for n in rig_nodes(CONFIG.perform(context), given)]


def stop_on_failure(event, context):
    """A node that ends on its own with a non-zero status ends the launch, naming it (rig_description.exit_problem).
    Raised here, launch logs it ('Caught exception in launch ...: crane_model exited with status 2 ...'), shuts
    every other node down with it as the reason, and `ros2 launch` exits with status 1 (a Shutdown event alone
    would end it with 0)."""
    problem = exit_problem(event.process_name, event.returncode, context.is_shutdown)
    if problem:
        raise RigError(problem)


def generate_launch_description() -> LaunchDescription:
    return LaunchDescription([
        # Plain defaults (`--show-args` prints them as written): a bare file name names a file of the package's
        # config/ (rig_description.config_path).
        *(DeclareLaunchArgument(a.name, description=a.description, default_value=a.default) for a in ARGUMENTS),
        RegisterEventHandler(OnProcessExit(on_exit=stop_on_failure)),
        OpaqueFunction(function=rig),
    ])
