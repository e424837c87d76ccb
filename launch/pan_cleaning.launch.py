"""ROS 2 launch file: the pan-cleaning task of paper 001 (a task scenario): simulator and controller.

    ros2 launch dualarm_control pan_cleaning.launch.py lockstep:=true force:=true

A task scenario has no relative trajectory stream: controller_node runs the scenario's tasks
(``scenario``, solver ``constraint_based``), its task time comes from the joint-state stamps,
and it exits when the scenario's duration is reached, which ends the launch. Machines without
the ros2 CLI use ``dualarm launch pan_cleaning --params config/solvers/constraint_based.yaml
[--lockstep] [--force]`` (the same two executables).
"""

from launch.actions import DeclareLaunchArgument, RegisterEventHandler, Shutdown
from launch.event_handlers import OnProcessExit
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue

from launch import LaunchDescription


def generate_launch_description() -> LaunchDescription:
    scenario = LaunchConfiguration("scenario")
    lockstep = ParameterValue(LaunchConfiguration("lockstep"), value_type=bool)
    force = ParameterValue(LaunchConfiguration("force"), value_type=bool)
    sim = Node(package="dualarm_control", executable="sim_node", name="sim_node", output="screen",
               parameters=[{"scenario": scenario, "lockstep": lockstep, "force": force,
                            "lockstep_subscribers": 1}])
    controller = Node(package="dualarm_control", executable="controller_node", name="controller_node",
                      output="screen",
                      parameters=[{"solver": "constraint_based", "scenario": scenario, "force": force,
                                   "lockstep": lockstep, "use_sim_time": lockstep}])
    return LaunchDescription([
        DeclareLaunchArgument("scenario", default_value="pan_cleaning", description="task scenario name or YAML path"),
        DeclareLaunchArgument("lockstep", default_value="false", description="deterministic lockstep stepping"),
        DeclareLaunchArgument("force", default_value="false", description="force feedback variant (eq 9)"),
        controller,
        sim,
        RegisterEventHandler(OnProcessExit(target_action=controller, on_exit=[Shutdown(reason="task complete")])),
    ])
