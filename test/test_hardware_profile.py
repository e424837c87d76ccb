"""Hardware profiles (issue 29), ROS-free: parsing and validation, position integration and clamping,
joint states from several topics matched by name, the simulator's side (state layout, command merge)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from dualarm_control.errors import ParameterError
from dualarm_control.hardware import (
    PositionIntegrator,
    StateAssembler,
    StateSample,
    TopicView,
    load_profile,
    position_command,
    waiting_reason,
)
from dualarm_control.params import read_params_file
from dualarm_control.robot_params import load_robot
from dualarm_sim.ports import CommandMerger, state_layout

CONFIG = Path(__file__).parents[1] / "config" / "hardware"
NAMES = load_robot().joint_names
LEFT, RIGHT = NAMES[:7], NAMES[7:]


def per_arm(interface: str = "velocity", **changes: object) -> dict[str, object]:
    given: dict[str, object] = {
        "hardware.outputs": ["left", "right"],
        "hardware.left.joints": list(reversed(LEFT)), "hardware.left.interface": interface,
        "hardware.right.joints": RIGHT, "hardware.right.interface": interface,
        "hardware.joint_states": ["/left/joint_states", "/right/joint_states"],
    }
    given.update(changes)
    return given


def test_default_profile_is_the_simulators_graph() -> None:
    profile = load_profile({}, NAMES)
    assert profile.joint_states == ("/joint_states",)
    (out,) = profile.outputs
    assert (out.topic, out.message, out.interface, out.joints) == (
        "/velocity_controller/commands", "float64_multi_array", "velocity", tuple(NAMES))
    np.testing.assert_array_equal(profile.indices(NAMES)[0], np.arange(14))


def test_per_arm_outputs_in_their_own_order() -> None:
    profile = load_profile(per_arm("position"), NAMES)
    assert profile.topics == ("/left/commands", "/right/commands")
    left, right = profile.indices(NAMES)
    np.testing.assert_array_equal(left, np.arange(6, -1, -1))
    np.testing.assert_array_equal(right, np.arange(7, 14))
    assert all(o.position for o in profile.outputs)


@pytest.mark.parametrize(("changes", "words"), [
    ({"hardware.left.joints": [*LEFT[:6], "lbr_A7"]}, ["hardware.left.joints", "lbr_A7", "a joint of the robot"]),
    ({"hardware.right.joints": [*RIGHT, LEFT[0]]}, ["hardware.right.joints", LEFT[0], "hardware.left.joints"]),
    ({"hardware.right.joints": RIGHT[:6]}, ["hardware.outputs", RIGHT[6], "in none"]),
    ({"hardware.right.topic": "/left/commands"}, ["hardware.right.topic", "/left/commands", "hardware.left.topic"]),
    ({"hardware.right.topic": "right/commands"}, ["hardware.right.topic", "absolute"]),
    ({"hardware.left.interface": "effort"}, ["hardware.left.interface", "effort", "velocity, position"]),
    ({"hardware.left.message": "twist"}, ["hardware.left.message", "'twist'",
                                          "one of: float64_multi_array, joint_trajectory"]),
    ({"hardware.joint_states": ["joint_states"]}, ["hardware.joint_states", "absolute"]),
    ({"hardware.outputs": ["left", "left"]}, ["hardware.outputs", "no duplicates"]),
    ({"hardware.outputs": ["left", "joint_states"]}, ["hardware.outputs", "not outputs, joint_states"]),
    ({"hardware.stamp_tolerance": 0.0}, ["hardware.stamp_tolerance", "> 0"]),
])
def test_a_bad_profile_is_refused_naming_the_key_and_the_joint_or_topic(changes: dict[str, object],
                                                                         words: list[str]) -> None:
    with pytest.raises(ParameterError) as info:
        load_profile(per_arm(**changes), NAMES, "controller_node")
    for word in words:
        assert word in str(info.value)


@pytest.mark.parametrize("name", ["sim", "ros2_control_velocity", "lbr_dual_position"])
def test_shipped_profiles_are_valid(name: str) -> None:
    profile = load_profile(read_params_file(CONFIG / f"{name}.yaml", "controller_node"), NAMES)
    assert sorted(j for o in profile.outputs for j in o.joints) == sorted(NAMES)


def test_position_command_integrates_and_clamps() -> None:
    q_min, q_max, qd_max = np.full(3, -1.0), np.full(3, 1.0), np.full(3, 2.0)
    measured = np.array([0.0, 0.995, 0.0])
    reference = np.array([0.001, 0.995, 0.05])  # the last one 5 cm beyond one cycle at the limit (1 cm)
    got = position_command(reference, np.array([1.0, 1.0, 0.0]), measured, 0.005, q_min, q_max, qd_max)
    np.testing.assert_allclose(got, [0.006, 1.0, 0.01])


def test_position_integrator_restarts_from_the_measurement_after_a_safe_stop() -> None:
    integ = PositionIntegrator(np.full(2, -3.0), np.full(2, 3.0), np.full(2, 1.0), 0.01)
    v = np.array([0.5, -0.5])
    first = integ.command(v, np.zeros(2))
    np.testing.assert_allclose(first, [0.005, -0.005])
    np.testing.assert_allclose(integ.command(v, np.zeros(2)), [0.01, -0.01])  # from its own reference
    np.testing.assert_allclose(integ.hold(np.array([0.2, 4.0])), [0.2, 3.0])  # hold, inside the limits
    np.testing.assert_allclose(integ.command(v, np.array([0.2, 0.1])), [0.205, 0.095])  # from the measurement


def test_position_commands_never_farther_than_one_cycle_at_the_limit() -> None:
    rng = np.random.default_rng(3)
    q_min, q_max, qd_max, period = np.full(4, -2.0), np.full(4, 2.0), np.full(4, 1.5), 0.005
    integ = PositionIntegrator(q_min, q_max, qd_max, period)
    q = np.zeros(4)
    for _ in range(500):
        cmd = integ.command(rng.normal(0, 3.0, 4), q)
        assert np.all(np.abs(cmd - q) <= qd_max * period + 1e-15)
        assert np.all((cmd >= q_min) & (cmd <= q_max))
        q = q + 0.5 * (cmd - q)  # a lagging robot


def sample(stamp: int, idx: list[int], values: list[float]) -> StateSample:
    return StateSample(stamp, 0, np.array(idx), np.array(values))


def test_one_topic_gives_every_sample() -> None:
    a = StateAssembler(["/joint_states"], 2, 1000)
    assert a.put("/joint_states", sample(5, [0, 1], [1.0, 2.0])) == (5, pytest.approx([1.0, 2.0]))


def test_two_topics_give_one_state_per_pair_within_the_tolerance() -> None:
    a = StateAssembler(["/l", "/r"], 4, 1000)
    assert a.put("/l", sample(0, [1, 0], [1.0, 0.0])) is None
    stamp, q = a.put("/r", sample(500, [2, 3], [2.0, 3.0]))  # type: ignore[misc]
    assert stamp == 500
    np.testing.assert_array_equal(q, [0.0, 1.0, 2.0, 3.0])
    assert a.put("/l", sample(5000, [1, 0], [1.0, 0.0])) is None  # /r not fresh yet
    assert a.put("/r", sample(7000, [2, 3], [2.0, 3.0])) is None  # 2 ms apart: not consistent
    assert a.stale_reason(0, 1e9).startswith("joint_states inconsistent: stamps of /l, /r differ by")
    assert a.put("/l", sample(7500, [1, 0], [1.0, 0.0])) is not None


def test_stale_reason_names_the_silent_topic() -> None:
    a = StateAssembler(["/left/joint_states", "/right/joint_states"], 2, 1000)
    a.put("/left/joint_states", StateSample(0, 10_000_000, np.array([0]), np.array([0.0])))
    a.put("/right/joint_states", StateSample(0, 40_000_000, np.array([1]), np.array([0.0])))
    assert a.stale_reason(50_000_000, 15e6) == "joint_states stale: /left/joint_states by 40.0 ms"


JS = "[sensor_msgs/msg/JointState]"


def test_waiting_reason_names_every_cause() -> None:
    """issue 38: why a controller has no consistent state yet, one cause per case."""
    names = ["l1", "l2", "r1", "r2"]
    a = StateAssembler(["/left/joint_states", "/right/joint_states"], 4, 2_500_000)
    views = [TopicView("/left/joint_states", (), 0, ""), TopicView("/right/joint_states", (f"/sim_node {JS}",), 0, "")]
    assert waiting_reason(views, a, names) == ("no publisher on /left/joint_states; /right/joint_states: nothing "
                                               f"delivered from /sim_node {JS}")
    second = (f"/sim_node {JS}", "/probe [std_msgs/msg/Float64MultiArray]")
    views = [TopicView("/left/joint_states", second, 3, ""),
             TopicView("/right/joint_states", (f"/sim_node {JS}", f"/sim_node {JS}"), 5, "missing 1 of the 2 joints")]
    assert waiting_reason(views, a, names) == (
        f"2 publishers on /left/joint_states (of another type): /sim_node {JS}, /probe [std_msgs/msg/Float64MultiArray]; "
        f"2 publishers on /right/joint_states: /sim_node {JS}, /sim_node {JS}; "
        "/right/joint_states: samples refused: missing 1 of the 2 joints")
    one = [TopicView(t, (f"/sim_node {JS}",), 1, "") for t in ("/left/joint_states", "/right/joint_states")]
    a.put("/left/joint_states", sample(0, [0, 1], [0.0, 0.0]))
    a.put("/right/joint_states", sample(7_000_000, [2], [0.0]))
    assert waiting_reason(one, a, names) == ("joints of the description missing from every topic: r2; stamps of "
                                             "/left/joint_states, /right/joint_states differ by 7.0 ms > 2.5 ms")
    a.put("/right/joint_states", sample(1_000_000, [2, 3], [0.0, 0.0]))
    assert waiting_reason(one, a, names) == ""
    # the topics named in the profile's order, whichever arrived first (the right one here)
    late = StateAssembler(["/left/joint_states", "/right/joint_states"], 4, 2_500_000)
    late.put("/right/joint_states", sample(7_000_000, [2, 3], [0.0, 0.0]))
    late.put("/left/joint_states", sample(0, [0, 1], [0.0, 0.0]))
    assert waiting_reason(one, late, names) == "stamps of /left/joint_states, /right/joint_states differ by 7.0 ms > 2.5 ms"


def test_sim_state_layout_per_namespace_in_its_own_order() -> None:
    profile = load_profile(per_arm(), NAMES)
    # per_arm's outputs are /left/commands, /right/commands
    layout = state_layout(profile, NAMES, [], ["left_gripper", "right_gripper"], "sorted")
    assert [s.topic for s in layout] == ["/left/joint_states", "/right/joint_states"]
    assert layout[0].names == tuple(sorted([*LEFT, "left_gripper", "right_gripper"]))
    full = [*NAMES, "left_gripper", "right_gripper"]
    assert [full[i] for i in layout[1].indices] == list(layout[1].names)
    (default,) = state_layout(load_profile({}, NAMES), NAMES, [])
    assert default.names == tuple(NAMES)
    np.testing.assert_array_equal(default.indices, np.arange(14))


def test_sim_merges_outputs_and_turns_positions_into_one_period_of_velocity() -> None:
    profile = load_profile(per_arm("position", **{"hardware.right.interface": "velocity"}), NAMES)
    merger = CommandMerger(profile, NAMES, 0.005)
    reference = np.linspace(0.0, 1.3, 14)
    merger.put("left", reference[6::-1] + 0.001, reference)
    assert not merger.complete
    merger.put("right", np.full(7, 0.3), reference)
    assert merger.complete
    np.testing.assert_allclose(merger.take(), [0.2] * 7 + [0.3] * 7)
    assert not merger.complete
    np.testing.assert_array_equal(merger.position_mask, [True] * 7 + [False] * 7)


def test_graph_check_names_each_problem() -> None:
    from types import SimpleNamespace

    from dualarm_control.ros.hardware_check import check_graph

    def info(node: str, type_name: str) -> SimpleNamespace:
        return SimpleNamespace(node_name=node, node_namespace="/left", topic_type=type_name)

    graph = {"/left/joint_states": [info("joint_state_broadcaster", "sensor_msgs/msg/JointState")],
             "/right/joint_states": [info("joint_state_broadcaster", "sensor_msgs/msg/JointState")],
             "/left/commands": [info("left", "trajectory_msgs/msg/JointTrajectory")]}
    node = SimpleNamespace(get_publishers_info_by_topic=lambda t: graph.get(t, []) if "states" in t else [
                               info("controller_node", "std_msgs/msg/Float64MultiArray")],
                           get_subscriptions_info_by_topic=lambda t: graph.get(t, []) if "commands" in t else [])
    seen = {"/left/joint_states": [*LEFT, "gripper"], "/right/joint_states": RIGHT[:6]}
    report = check_graph(node, load_profile(per_arm(), NAMES), NAMES, seen)
    assert report.problems == (
        f"joint {RIGHT[6]} is on no joint-state topic",
        ("/left/commands is subscribed as trajectory_msgs/msg/JointTrajectory, the profile sends "
         "std_msgs/msg/Float64MultiArray"),
        "no subscriber on /right/commands")
    assert "  8 joints, 7 of the robot's, extra: gripper" in report.lines
    assert ("command /right/commands (velocity, 7 joints): subscribers none; publishers /left/controller_node "
            "[std_msgs/msg/Float64MultiArray]") in report.lines
    assert not report.ok


@pytest.mark.parametrize("interface", ["velocity", "position"])
def test_one_point_trajectory_command_is_exact_cdr(interface: str) -> None:
    """The JointTrajectory command is the message's exact CDR (rosbags refuses a byte too many)."""
    from rosbags.typesys import Stores, get_typestore

    from dualarm_control.hardware import OutputSpec

    spec = OutputSpec("servo", "/servo", "joint_trajectory", interface, ("b", "a"))
    msg = get_typestore(Stores.ROS2_JAZZY).deserialize_cdr(spec.kind.encode(spec, np.array([0.5, -1.0]), 0.005),
                                                           "trajectory_msgs/msg/JointTrajectory")
    (point,) = msg.points
    assert list(msg.joint_names) == ["b", "a"]
    assert list(point.positions if interface == "position" else point.velocities) == [0.5, -1.0]
    assert len(point.velocities if interface == "position" else point.positions) == 0
    assert (point.time_from_start.sec, point.time_from_start.nanosec) == (0, 5_000_000)


WIRE = {
    "float64_multi_array": "0001000000000000000000000200000000000000000000000000e03f000000000000f0bf",
    "joint_trajectory.velocity": "000100000000000000000000010000000000000002000000020000006200000002000000610000000100"
                                 "00000000000002000000000000000000e03f000000000000f0bf000000000000000000000000404b4c00",
    "joint_trajectory.position": "000100000000000000000000010000000000000002000000020000006200000002000000610000000100"
                                 "00000200000000000000000000000000e03f000000000000f0bf00000000000000000000000000000000"
                                 "404b4c00",
}
"""The commands of [0.5, -1.0] for joints (b, a) at 5 ms as the controller sent them before the output registry
(issue 39): ``convert.float_array`` and ``hardware_io.trajectory_bytes``."""


@pytest.mark.parametrize("case", sorted(WIRE))
def test_the_registry_sends_the_bytes_sent_before_it(case: str) -> None:
    from dualarm_control.hardware import OutputSpec
    from dualarm_control.outputs import output_type

    message, _, interface = case.partition(".")
    spec = OutputSpec("servo", "/servo", message, interface or "velocity", ("b", "a"))
    assert output_type(message).encode(spec, np.array([0.5, -1.0]), 0.005).hex() == WIRE[case]


def test_an_unknown_message_type_is_refused_where_the_simulator_sets_up_its_ports() -> None:
    from dualarm_control.errors import UnknownOutputError
    from dualarm_control.hardware import HardwareProfile, OutputSpec

    spec = OutputSpec("left", "/left/commands", "twist", "velocity", tuple(NAMES))
    with pytest.raises(UnknownOutputError, match="unknown output message type 'twist'; known: float64_multi_array, "
                                                 "joint_trajectory"):
        CommandMerger(HardwareProfile((spec,), ("/joint_states",), 0.0025), NAMES, 0.005)


def test_a_recording_takes_the_profiles_topics() -> None:
    from dualarm_control.app.run.launcher import GRAPH_TOPICS, with_profile_topics

    assert with_profile_topics(GRAPH_TOPICS, [], NAMES) == GRAPH_TOPICS
    got = with_profile_topics(GRAPH_TOPICS, [str(CONFIG / "lbr_dual_position.yaml")], NAMES)
    assert got[:4] == ("/left/joint_states", "/right/joint_states", "/left/forward_position_controller/commands",
                       "/right/forward_position_controller/commands")
    assert "/joint_states" not in got and "/diagnostics" in got
