"""``dualarm hardware check [--params FILE]``: does the profile the controller would run with match the
live graph? Prints the joint-state and command topics found, their publishers and subscribers with
types, the joint names matched or missing, one line per problem; exit 0 only when the profile can run."""

from __future__ import annotations

from collections.abc import Sequence

from dualarm_control.cell_robot import cell_robot, robot_note
from dualarm_control.hardware import load_profile
from dualarm_control.params import read_params_files
from dualarm_control.ros.hardware_check import wait_for_graph
from dualarm_control.scenario import load_scenario

NODE_NAME = "dualarm_hardware_check"
EXIT_PROBLEMS = 1


def check_command(params: Sequence[str], robot: str | None, timeout_s: float) -> int:
    """Check the profile of ``params`` (the controller's parameter files: its ``hardware.*``, ``scenario``
    and ``robot``; the robot is the profile's ``hardware.robot``, dualarm_control/cell_robot.py) for ``timeout_s`` at most, answering as soon as it matches."""
    from dualarm_control.ros.hardware_io import JointStates
    from dualarm_control.ros.node import tool_node
    from dualarm_control.ros.qos import stream_qos

    given = read_params_files(params, "controller_node")
    chosen, profile_robot = cell_robot(params, robot)  # the profile's robot (hardware.robot) first
    scenario = load_scenario(str(given.get("scenario", "assembly")), chosen)
    description = scenario.robot
    names = description.joint_names
    profile = load_profile(given, names, "controller_node")
    print(robot_note(scenario, profile_robot, chosen or ""))
    print(f"profile: {', '.join(params) or 'default'} on robot '{description.name}' ({len(names)} joints)")
    with tool_node(NODE_NAME) as (node, executor, _):
        states = JointStates(node, profile, names, stream_qos("best_effort"), lambda *_: None,
                             lambda *_: None, lambda _: None)
        report = wait_for_graph(node, executor, profile, names, states.names_seen, timeout_s, NODE_NAME)
    print(report.text(), flush=True)
    return 0 if report.ok else EXIT_PROBLEMS
