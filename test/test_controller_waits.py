"""issue 38: a controller with no consistent joint state says why, once a second, and a trajectory node in
real time does not run its scenario out in front of a controller that never cycled.

The causes are made on purpose on the test's ROS domain (``lbr_dual_position``: two joint-state topics
assembled by stamp): no publisher, a publisher whose samples are never delivered (best-effort against the
controller's reliable reader), a second publisher of another type, joints missing, stamps apart. Each
named cause is waited for in the controller's log (the line a user reads), never slept for.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from waiting import NodeProcess, tail, wait_until

from dualarm_control.kinematics import DualArmModel

ROOT = Path(__file__).parents[1]
SHORT = ROOT / "test" / "data" / "short.yaml"
PROFILE = ROOT / "config" / "hardware" / "lbr_dual_position.yaml"
CELL = ("-p", f"scenario:={SHORT}", "--params-file", str(PROFILE))


@pytest.fixture
def probe() -> Iterator[tuple[Any, Any]]:
    from dualarm_control.ros.node import tool_node

    with tool_node("probe", signals=False) as (node, executor, _):
        yield node, executor


def test_the_controller_names_why_it_waits_for_joint_states(probe: tuple[Any, Any]) -> None:
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray

    from dualarm_control.ros.node import tool_node

    node, executor = probe
    names = DualArmModel().joint_names
    left, right = names[:7], names[7:]
    controller = NodeProcess("controller_node", *CELL)
    state: dict[str, Any] = {}

    def says(text: str) -> None:
        """The controller's log, from where the last cause was seen, names ``text``; meanwhile the
        probe publishes ``state`` (topic -> (names, stamp offset [ns])) every 10 ms."""
        start = len(controller.lines)

        def step() -> None:
            now = node.get_clock().now().nanoseconds
            for pub, joints, offset in state.values():
                msg = JointState(name=list(joints), position=[0.1] * len(joints))
                msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(now + offset, 1_000_000_000)
                pub.publish(msg)
            executor.spin_once(timeout_sec=0.01)

        wait_until(lambda: any(text in line for line in controller.lines[start:]), lambda: tail(controller.lines),
                   what=f"the controller's log naming '{text}'", step=step,
                   gone=lambda: None if controller.popen.poll() is None else "controller_node exited")

    try:
        says("waiting for joint_states: no publisher on /left/joint_states; no publisher on /right/joint_states")
        best_effort = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)
        state["/left/joint_states"] = (node.create_publisher(JointState, "/left/joint_states", best_effort), left, 0)
        says("/left/joint_states: nothing delivered from /probe [sensor_msgs/msg/JointState]")
        node.destroy_publisher(state["/left/joint_states"][0])
        state["/left/joint_states"] = (node.create_publisher(JointState, "/left/joint_states", 10), left[:6], 0)
        state["/right/joint_states"] = (node.create_publisher(JointState, "/right/joint_states", 10), right, 0)
        says("joints of the description missing from every topic: left_joint_7")
        with tool_node("stray", signals=False) as (other, _, _):  # a participant of its own (one type per topic)
            other.create_publisher(Float64MultiArray, "/right/joint_states", 10)
            says("2 publishers on /right/joint_states (of another type): ")
        state["/left/joint_states"] = (state["/left/joint_states"][0], left, 0)
        state["/right/joint_states"] = (state["/right/joint_states"][0], right, 7_000_000)
        says("stamps of /left/joint_states, /right/joint_states differ by 7.0 ms > 2.5 ms")
        state["/right/joint_states"] = (state["/right/joint_states"][0], right, 0)
        says("waiting for relative_target")  # a consistent state: the controller now waits for its targets
        assert controller.popen.poll() is None, tail(controller.lines)
    finally:
        assert controller.stop() == 0, tail(controller.lines)
    waits = [line for line in controller.lines if "waiting for joint_states" in line]
    assert all(": " in line.split("waiting for joint_states", 1)[1] for line in waits), waits  # always a cause


def test_the_trajectory_node_holds_its_first_target_until_the_controller_cycles() -> None:
    """Real time, a simulator and a trajectory node but no controller: the first target is held and the
    node says so; the scenario (1.55 s) starts only when a controller cycles, then completes."""
    sim = NodeProcess("sim_node", *CELL)
    trajectory = NodeProcess("trajectory_node", *CELL)
    controller = None
    try:
        held = trajectory.wait_for("holding the first target: no controller_node cycle on /diagnostics after")
        assert not any("complete" in line for line in trajectory.lines[:held + 1]), tail(trajectory.lines)
        controller = NodeProcess("controller_node", *CELL)
        cycling = trajectory.wait_for("controller_node cycling", start=held)
        complete = trajectory.wait_for("scenario 'short' complete", start=cycling)
        assert trajectory.popen.wait(timeout=60) == 0, tail(trajectory.lines)
        assert held < cycling < complete
    finally:
        codes = [p.stop() for p in (controller, sim) if p is not None]
        trajectory.stop()
    assert codes == [0, 0], (codes, tail(sim.lines))
