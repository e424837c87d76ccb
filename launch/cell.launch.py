"""ROS 2 launch file: the dual-arm cell, the controller and the trajectory streamer.

    ros2 launch dualarm_control cell.launch.py scenario:=assembly solver:=sparse_qp lockstep:=true

In lockstep mode the controller and trajectory nodes run on the simulation clock
(``use_sim_time``, /clock from sim_node). The launch ends when the trajectory node reports
the scenario complete. Machines without the ros2 CLI use
``dualarm launch assembly --solver sparse_qp --lockstep`` (the same three executables).
"""

from launch.actions import DeclareLaunchArgument, RegisterEventHandler, Shutdown
from launch.event_handlers import OnProcessExit
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue

from launch import LaunchDescription


def generate_launch_description() -> LaunchDescription:
    scenario = LaunchConfiguration("scenario")
    solver = LaunchConfiguration("solver")
    lockstep = ParameterValue(LaunchConfiguration("lockstep"), value_type=bool)
    sim = Node(package="dualarm_control", executable="sim_node", name="sim_node", output="screen",
               parameters=[{"scenario": scenario, "lockstep": lockstep}])
    controller = Node(package="dualarm_control", executable="controller_node", name="controller_node",
                      output="screen",
                      parameters=[{"solver": solver, "lockstep": lockstep, "use_sim_time": lockstep}])
    trajectory = Node(package="dualarm_control", executable="trajectory_node", name="trajectory_node",
                      output="screen",
                      parameters=[{"scenario": scenario, "lockstep": lockstep, "use_sim_time": lockstep}])
    return LaunchDescription([
        DeclareLaunchArgument("scenario", default_value="assembly", description="scenario name or YAML path"),
        DeclareLaunchArgument("solver", default_value="hierarchical_sparse_qp", description="controller solver"),
        DeclareLaunchArgument("lockstep", default_value="false", description="deterministic lockstep stepping"),
        controller,
        trajectory,
        sim,
        RegisterEventHandler(OnProcessExit(target_action=trajectory, on_exit=[Shutdown(reason="scenario complete")])),
    ])
