"""The whole simulated rig: crane model, load program, simulated load cell and LVDT, stiffness estimator, and the
session recorder.

    ros2 launch crane_stiffness rig.launch.py program:=side_force record:=true

Arguments: program (side_force | side_force_slack | moment_z | force_z, or a path to a program YAML), crane (a
geometry YAML; default the lab model), sensors (sensor YAML), record (true/false), session (bag name).
To use real sensors, set sim_sensors:=false and remap the drivers' topics onto /load_cell/wrench and
/lvdt/displacement (see README, "Real drivers").
"""
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution, PythonExpression
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare

PACKAGE = 'crane_stiffness'


def generate_launch_description() -> LaunchDescription:
    config = PathJoinSubstitution([FindPackageShare(PACKAGE), 'config'])
    program = LaunchConfiguration('program')
    program_file = PythonExpression([
        "'", program, "' if '", program, "'.endswith('.yaml') else '", config, "/program_' + '", program,
        "' + '.yaml'"])
    crane = LaunchConfiguration('crane')
    sensors = LaunchConfiguration('sensors')
    sim = IfCondition(LaunchConfiguration('sim_sensors'))
    return LaunchDescription([
        DeclareLaunchArgument('program', default_value='side_force', description='test program name or file'),
        DeclareLaunchArgument('crane', default_value=PathJoinSubstitution([config, 'crane_lab.yaml']),
                              description='crane geometry parameters (ROS parameter YAML)'),
        DeclareLaunchArgument('sensors', default_value=PathJoinSubstitution([config, 'sensors.yaml']),
                              description='sensor and estimator parameters'),
        DeclareLaunchArgument('sim_sensors', default_value='true', description='start the simulated sensors'),
        DeclareLaunchArgument('record', default_value='true', description='record the session to bags/'),
        DeclareLaunchArgument('session', default_value='', description='bag name (default: time stamped)'),
        Node(package=PACKAGE, executable='crane_model', name='crane_model', parameters=[crane], output='screen'),
        Node(package=PACKAGE, executable='load_cell', name='load_cell', parameters=[sensors], condition=sim,
             output='screen'),
        Node(package=PACKAGE, executable='lvdt', name='lvdt', parameters=[sensors], condition=sim,
             output='screen'),
        Node(package=PACKAGE, executable='stiffness_estimator', name='stiffness_estimator',
             parameters=[crane, sensors], output='screen'),
        Node(package=PACKAGE, executable='session_recorder', name='session_recorder',
             parameters=[crane, sensors, program_file, {'session': LaunchConfiguration('session')}],
             condition=IfCondition(LaunchConfiguration('record')), output='screen'),
        Node(package=PACKAGE, executable='load_program', name='load_program', parameters=[program_file],
             output='screen'),
    ])
