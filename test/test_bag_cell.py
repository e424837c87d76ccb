"""The cell a bag was recorded on (issue 40): parameter documents and the profile's streams read back.

ROS-free: messages are plain objects with a JointState's or a command's fields. The live
end-to-end checks (each shipped profile's lockstep bag reported as the default profile's) are in
test_hardware_nodes.py.
"""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from dualarm_control.app.record.cell import (
    ProfileStreams,
    cell_parameters,
    recorded_topics,
)
from dualarm_control.errors import DualArmError
from dualarm_control.params import params_document, parse_params_text

JOINTS = ["l1", "l2", "r1", "r2"]
PERIOD = 0.01


def test_a_parameter_document_gives_its_values_back() -> None:
    values = {"robot": "lwr4_cell", "control_period": 0.005, "lockstep": True, "hardware.outputs": ["a", "b"],
              "hardware.a.joints": ["l1", "l2"], "hardware.a.topic": "/a/commands", "gain": 10.0}
    text = params_document("controller_node", values)
    assert text.startswith("controller_node:\n  ros__parameters:\n")
    assert parse_params_text(text, "controller_node") == values


def test_cell_parameters_keep_each_nodes_first_document_and_skip_garbage() -> None:
    first = params_document("controller_node", {"gain": 10.0})
    later = params_document("controller_node", {"gain": 3.0})
    sim = params_document("sim_node", {"lockstep": True})
    got = cell_parameters([first, "{not: [yaml", "just text", "controller_node: 3", later, sim])
    assert got == {"controller_node": {"gain": 10.0}, "sim_node": {"lockstep": True}}


def test_without_a_cell_the_default_profile() -> None:
    topics = recorded_topics({})
    assert topics.joint_states == ("/joint_states",)
    assert topics.outputs == ("/velocity_controller/commands",)
    assert topics.period == 0.005


def two_arm_profile(left: str = "velocity", right: str = "position") -> dict[str, Any]:
    return {"control_period": PERIOD, "hardware.outputs": ["left", "right"],
            "hardware.left.topic": "/left/commands", "hardware.left.interface": left,
            "hardware.left.joints": ["l2", "l1"],  # the output's own order, not the description's
            "hardware.right.topic": "/right/commands", "hardware.right.interface": right,
            "hardware.right.joints": ["r1", "r2"], "hardware.right.message": "joint_trajectory",
            "hardware.joint_states": ["/left/joint_states", "/right/joint_states"], "hardware.stamp_tolerance": 0.002}


def state(stamp_ms: float, names: list[str], q: list[float], qd: list[float] | None = None) -> Any:
    ns = round(stamp_ms * 1e6)
    return SimpleNamespace(header=SimpleNamespace(stamp=SimpleNamespace(sec=ns // 10**9, nanosec=ns % 10**9)),
                           name=names, position=q, velocity=qd if qd is not None else [])


def test_two_topics_assemble_into_consistent_states_in_the_description_order() -> None:
    """A state needs a fresh sample of both topics within the tolerance; a topic's extra joints (a
    gripper) are dropped; brute force: the expected states written out by hand."""
    streams = ProfileStreams(recorded_topics(two_arm_profile()))
    msgs = [
        (1, "/left/joint_states", state(0.0, ["l2", "l1", "grip"], [2.0, 1.0, 9.0], [0.2, 0.1, 0.0])),
        (2, "/right/joint_states", state(1.0, ["r1", "r2"], [3.0, 4.0], [0.3, 0.4])),  # within 2 ms: a state
        (3, "/left/joint_states", state(10.0, ["l2", "l1", "grip"], [2.5, 1.5, 9.0], [0.2, 0.1, 0.0])),
        (4, "/right/joint_states", state(13.0, ["r1", "r2"], [3.5, 4.5], [0.3, 0.4])),  # 3 ms apart: none
        (5, "/right/joint_states", state(11.0, ["r1", "r2"], [3.25, 4.25], [0.3, 0.4])),  # 1 ms apart: a state
    ]
    for t, topic, m in msgs:
        assert streams.add(topic, t, m)
    assert not streams.add("/other", 6, msgs[0][2])
    got = streams.states(JOINTS)
    assert [(t, stamp) for t, stamp, _, _ in got] == [(2, 1_000_000), (5, 11_000_000)]
    np.testing.assert_array_equal(got[0][3].position, [1.0, 2.0, 3.0, 4.0])
    np.testing.assert_array_equal(got[0][3].velocity, [0.1, 0.2, 0.3, 0.4])
    np.testing.assert_array_equal(got[1][3].position, [1.5, 2.5, 3.25, 4.25])
    assert got[1][2] == JOINTS


def test_a_starved_recorders_backlog_still_assembles_every_stamp() -> None:
    """A recorder starved under load received the left topic's backlog before the right's (a CI run beside
    stress-ng: the product's reader lost stamp 1.245 s of a lockstep bag that a reading by stamp has): the
    states are assembled by stamp, each one whole, whatever the receive order."""
    streams = ProfileStreams(recorded_topics(two_arm_profile()))
    for t, topic, stamp_ms, names, q in ((1, "/left/joint_states", 0.0, ["l1", "l2"], [1.0, 2.0]),
                                         (2, "/left/joint_states", 10.0, ["l1", "l2"], [1.5, 2.5]),
                                         (3, "/right/joint_states", 0.0, ["r1", "r2"], [3.0, 4.0]),
                                         (4, "/right/joint_states", 10.0, ["r1", "r2"], [3.5, 4.5])):
        streams.add(topic, t, state(stamp_ms, names, q))
    got = streams.states(JOINTS)
    assert [(t, stamp) for t, stamp, _, _ in got] == [(3, 0), (4, 10_000_000)]
    np.testing.assert_array_equal(got[0][3].position, [1.0, 2.0, 3.0, 4.0])
    np.testing.assert_array_equal(got[1][3].position, [1.5, 2.5, 3.5, 4.5])


def command(values: list[float]) -> Any:
    return SimpleNamespace(data=values)


def trajectory(names: list[str], positions: list[float]) -> Any:
    return SimpleNamespace(joint_names=names, points=[SimpleNamespace(positions=positions, velocities=[])])


def test_commands_join_the_outputs_cycle_by_cycle_and_positions_become_velocities() -> None:
    """Cycle k is the k-th message of each output; a position output's velocity is the step from the
    reference (the first state, then the last command) over one period, as the simulator moves it."""
    streams = ProfileStreams(recorded_topics(two_arm_profile()))
    streams.add("/left/joint_states", 1, state(0.0, ["l1", "l2"], [1.0, 2.0]))
    streams.add("/right/joint_states", 2, state(0.0, ["r1", "r2"], [3.0, 4.0]))
    streams.add("/left/commands", 10, command([0.2, 0.1]))  # l2, l1
    streams.add("/right/commands", 11, trajectory(["r2", "r1"], [4.0, 3.01]))  # by name: r1 3.01, r2 4.0
    streams.add("/left/commands", 20, command([0.0, -0.1]))
    streams.add("/right/commands", 19, trajectory(["r1", "r2"], [3.03, 3.99]))
    streams.add("/left/commands", 30, command([9.0, 9.0]))  # no right command for this cycle yet: dropped
    got = streams.commands(JOINTS)
    assert [t for t, _ in got] == [11, 20]
    np.testing.assert_allclose(got[0][1], [0.1, 0.2, 1.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(got[1][1], [-0.1, 0.0, 2.0, -1.0], atol=1e-12)


def test_a_command_of_the_wrong_width_is_named() -> None:
    streams = ProfileStreams(recorded_topics(two_arm_profile("velocity", "velocity") | {
        "hardware.right.message": "float64_multi_array"}))
    streams.add("/left/commands", 1, command([0.1, 0.2, 0.3]))
    streams.add("/right/commands", 1, command([0.1, 0.2]))
    with pytest.raises(DualArmError, match="/left/commands: a command of 3 values for the 2 joints of output left"):
        streams.commands(JOINTS)


def test_a_profile_that_does_not_fit_the_robot_is_named() -> None:
    streams = ProfileStreams(recorded_topics(two_arm_profile()))
    with pytest.raises(DualArmError, match="hardware.left.joints"):
        streams.commands(["a", "b", "c", "d"])
