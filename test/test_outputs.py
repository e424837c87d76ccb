"""Command outputs as an open set (issue 39): a message type registered from this file (no change to the
package) is a valid profile message; the controller's hardware IO encodes it and the simulator's command
ports decode it, in process and over rclpy with the real simulator node.

The type is docs/outputs.md's example: sensor_msgs/JointState as a command, by joint name (the joint
commands of topic_based_ros2_control, Isaac Sim's articulation controller).
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from dualarm_control.errors import InputRejected, ParameterError
from dualarm_control.hardware import HardwareProfile, load_profile, profile_parameters
from dualarm_control.outputs import (
    OutputSpec,
    OutputType,
    by_name,
    output_names,
    register,
    unregister,
)
from dualarm_control.robot_params import load_robot
from dualarm_control.ros import cdr
from dualarm_control.ros.cdr import CdrError
from dualarm_sim.ports import CommandMerger

NAMES = load_robot().joint_names
LEFT, RIGHT = NAMES[:7], NAMES[7:]
PERIOD = 0.005


class JointStateOutput(OutputType):
    """sensor_msgs/JointState as a command: ``name`` the output's joints, ``position`` or ``velocity`` (per
    the interface; the other field empty) the values, stamp zero. Read back by joint name."""

    key = "joint_state"
    type_name = "sensor_msgs/msg/JointState"

    def encode(self, spec: OutputSpec, values: np.ndarray, period: float) -> bytes:
        empty = np.zeros(0)
        return cdr.joint_state(0, spec.joints, values if spec.position else empty, empty if spec.position else values)

    def decode(self, spec: OutputSpec, msg: Any) -> np.ndarray:
        return by_name(spec, msg.name, msg.position if spec.position else msg.velocity, "joint_state command")

    def decode_bytes(self, spec: OutputSpec, data: bytes) -> np.ndarray:
        _, names, position, velocity = cdr.JointStateReader()(data)
        return self.decode(spec, SimpleNamespace(name=names, position=position, velocity=velocity))


@pytest.fixture
def joint_state_output() -> Iterator[None]:
    register(JointStateOutput)
    yield
    unregister(JointStateOutput.key)


def per_arm(left: str = "joint_state", right: str = "joint_state") -> dict[str, object]:
    """The left arm by velocity in reversed order, the right by position; ``left``, ``right``: their message types."""
    return {"hardware.outputs": ["left", "right"],
            "hardware.left.joints": list(reversed(LEFT)), "hardware.left.message": left,
            "hardware.right.joints": RIGHT, "hardware.right.interface": "position", "hardware.right.message": right,
            "hardware.joint_states": ["/left/joint_states", "/right/joint_states"]}


def test_a_registered_type_is_a_valid_profile_message_and_gone_once_unregistered(joint_state_output: None) -> None:
    assert output_names() == ["float64_multi_array", "joint_state", "joint_trajectory"]
    profile = load_profile(per_arm(), NAMES, "controller_node")
    assert {o.kind.type_name for o in profile.outputs} == {"sensor_msgs/msg/JointState"}
    (message,) = [p for p in profile_parameters(per_arm()) if p.name == "hardware.left.message"]
    assert message.constraints == "one of: float64_multi_array, joint_state, joint_trajectory"
    unregister(JointStateOutput.key)
    try:
        with pytest.raises(ParameterError, match="got 'joint_state', expected one of: float64_multi_array, "
                                                 "joint_trajectory"):
            load_profile(per_arm(), NAMES, "controller_node")
    finally:
        register(JointStateOutput)


def test_a_type_registered_twice_is_refused(joint_state_output: None) -> None:
    with pytest.raises(ValueError, match="'joint_state' registered twice"):
        register(JointStateOutput)


class Wire:
    """What CommandSink needs of an rclpy node: publishers that keep what they send."""

    def __init__(self) -> None:
        self.sent: dict[str, list[bytes]] = {}
        self.types: dict[str, Any] = {}

    def create_publisher(self, msg_type: Any, topic: str, qos: Any) -> Any:
        self.types[topic] = msg_type
        sent = self.sent.setdefault(topic, [])
        return SimpleNamespace(publish=sent.append, get_subscription_count=lambda: 1)


@pytest.mark.parametrize(("left", "right"), [("joint_state", "joint_state"), ("joint_state", "joint_trajectory"),
                                             ("float64_multi_array", "joint_state")])
def test_the_controller_encodes_it_and_the_simulator_decodes_it(joint_state_output: None, left: str,
                                                                right: str) -> None:
    """In process: CommandSink's bytes, read by the simulator's command ports (the CDR fast path and the
    rclpy message), merge into the cell's command as the default profile's would."""
    from rclpy.serialization import deserialize_message

    from dualarm_control.ros.hardware_io import CommandSink

    profile = load_profile(per_arm(left, right), NAMES)
    limits = (np.full(14, -3.0), np.full(14, 3.0), np.full(14, 2.0))
    wire = Wire()
    sink = CommandSink(wire, profile, NAMES, limits, PERIOD, 10)
    assert wire.types["/left/commands"] is profile.outputs[0].kind.message_class()
    measured = np.linspace(-0.5, 0.5, 14)
    velocities = np.linspace(0.1, 1.4, 14)
    sink.measure(measured)
    sink.send(velocities, safe=False)
    merger = CommandMerger(profile, NAMES, PERIOD)
    for o in profile.outputs:
        (data,) = wire.sent[o.topic]
        decoder = merger.decoders[o.name]
        slow = decoder.from_message(deserialize_message(data, wire.types[o.topic]))
        try:  # the CDR fast path, where the type has one (subscribe_checked falls back to rclpy otherwise)
            np.testing.assert_array_equal(decoder.from_bytes(data), slow)
        except CdrError:
            assert o.message == "joint_trajectory"
        merger.put(o.name, slow, measured)
    np.testing.assert_allclose(merger.take(), velocities, rtol=1e-12)  # the right arm's within one cycle's limit


def test_a_joint_state_command_missing_a_joint_is_refused_naming_it(joint_state_output: None) -> None:
    spec = OutputSpec("left", "/left/commands", "joint_state", "velocity", ("a", "b"))
    merger = CommandMerger(HardwareProfile((spec,), ("/joint_states",), 0.0025), ["a", "b"], PERIOD)
    with pytest.raises(InputRejected, match=re.escape(
            "joint_state command is missing 1 of the 2 joints, e.g. ['a'] (got ['b', 'c']...)")) as caught:
        merger.decoders["left"].from_bytes(cdr.joint_state(0, ["b", "c"], np.zeros(0), np.ones(2)))
    assert caught.value.field == "name" and caught.value.value == ["a"]


def test_the_simulator_node_speaks_it_over_rclpy(joint_state_output: None) -> None:
    """The real sim_node in this process with a profile of the registered type: it subscribes each output
    as its ROS type (the graph check passes), and the controller's commands reach its cell."""
    import rclpy
    from rclpy.node import Node

    from dualarm_control.ros.hardware_check import check_graph
    from dualarm_control.ros.hardware_io import CommandSink
    from dualarm_control.ros.node import init_rclpy
    from dualarm_sim.sim_node import SimNode

    given = per_arm("joint_state", "joint_trajectory")
    args = ["--ros-args", "-p", "hardware.outputs:=[left, right]", "-p", "hardware.right.interface:=position",
            "-p", "hardware.joint_states:=[/left/joint_states, /right/joint_states]",
            "-p", "hardware.left.message:=joint_state", "-p", "hardware.right.message:=joint_trajectory",
            "-p", f"hardware.left.joints:=[{', '.join(reversed(LEFT))}]", "-p", f"hardware.right.joints:=[{', '.join(RIGHT)}]"]
    context = init_rclpy(args)
    sim = None
    try:
        sim = SimNode(context)
        node = Node("controller_probe", context=context)
        profile = load_profile(given, NAMES)
        sink = CommandSink(node, profile, NAMES, (np.full(14, -3.0), np.full(14, 3.0), np.full(14, 2.0)), PERIOD, 10)
        executor = rclpy.executors.SingleThreadedExecutor(context=context)
        executor.add_node(sim.node)
        executor.add_node(node)
        for _ in range(100):  # discovery, in process
            report = check_graph(node, profile, NAMES, {}, ignore_node="controller_probe")
            if sink.get_subscription_count() and not [p for p in report.problems if "commands" in p]:
                break
            executor.spin_once(timeout_sec=0.05)
        assert not [p for p in report.problems if "commands" in p], report.problems
        assert "command /left/commands (velocity, 7 joints): subscribers /sim_node [sensor_msgs/msg/JointState]" in \
            " ".join(report.lines)
        sink.measure(sim.cell.state().positions)
        sink.send(np.full(14, 0.1), safe=False)
        for _ in range(100):
            if sim.received >= 2:
                break
            executor.spin_once(timeout_sec=0.05)
        assert (sim.received, sim.rejected) == (2, 0)
        np.testing.assert_allclose(sim.merger.velocity, np.full(14, 0.1), rtol=1e-9)
        node.destroy_node()
    finally:
        if sim is not None:
            sim.close()
            sim.node.destroy_node()
        rclpy.shutdown(context=context)


def test_an_unknown_type_is_refused_by_the_simulator_node_naming_the_known_ones() -> None:
    import rclpy

    from dualarm_control.ros.node import init_rclpy
    from dualarm_sim.sim_node import SimNode

    context = init_rclpy(["--ros-args", "-p", "hardware.velocity_controller.message:=twist"])
    try:
        with pytest.raises(ParameterError, match="sim_node.hardware.velocity_controller.message': got 'twist', "
                                                 "expected one of: float64_multi_array, joint_trajectory"):
            SimNode(context)
    finally:
        rclpy.shutdown(context=context)
