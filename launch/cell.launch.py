"""ROS 2 launch file: the dual-arm cell, the controller and the trajectory streamer.

    ros2 launch dualarm_control cell.launch.py scenario:=assembly solver:=sparse_qp lockstep:=true

Machines without the ros2 CLI use ``dualarm launch assembly --solver sparse_qp --lockstep``.
"""

from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from launch import LaunchDescription


def generate_launch_description() -> LaunchDescription:
    scenario = LaunchConfiguration("scenario")
    solver = LaunchConfiguration("solver")
    lockstep = LaunchConfiguration("lockstep")
    return LaunchDescription([
        DeclareLaunchArgument("scenario", default_value="assembly", description="scenario name or YAML path"),
        DeclareLaunchArgument("solver", default_value="hierarchical_sparse_qp", description="controller solver"),
        DeclareLaunchArgument("lockstep", default_value="false", description="deterministic lockstep stepping"),
        Node(package="dualarm_control", executable="sim_node", name="sim_node", output="screen",
             parameters=[{"scenario": scenario, "lockstep": lockstep}]),
        Node(package="dualarm_control", executable="controller_node", name="controller_node", output="screen",
             parameters=[{"solver": solver, "lockstep": lockstep}]),
        Node(package="dualarm_control", executable="trajectory_node", name="trajectory_node", output="screen",
             parameters=[{"scenario": scenario, "lockstep": lockstep}]),
    ])
