"""A profile names its robot and maps its joint names (issue 40 item 5; dualarm_control/cell_robot.py,
dualarm_control/joint_map.py): the rule every verb follows, the map in both directions, refusals naming
the bad value."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from dualarm_control.cell_robot import (
    cell_robot,
    choose_robot,
    node_scenario,
    params_robot,
    with_absolute_robot,
)
from dualarm_control.errors import ParameterError
from dualarm_control.hardware import (
    StateAssembler,
    StateSample,
    load_profile,
    waiting_reason,
)
from dualarm_control.joint_map import parse_joint_map
from dualarm_control.kinematics import DualArmModel
from dualarm_sim.ports import CommandMerger, state_layout

NAMES = DualArmModel().joint_names
ROOT = Path(__file__).resolve().parents[1]


def renamed(name: str) -> str:
    """franka_ros2's style: left_joint_3 -> panda_left_joint3."""
    side, _, k = name.split("_")
    return f"panda_{side}_joint{k}"


MAP = [f"{n} {renamed(n)}" for n in NAMES]


def test_the_map_renames_both_ways_and_keeps_unmapped_names() -> None:
    m = parse_joint_map(MAP[:3], NAMES)
    assert m.hardware(NAMES)[:4] == ("panda_left_joint1", "panda_left_joint2", "panda_left_joint3", "left_joint_4")
    assert m.description(m.hardware(NAMES)) == tuple(NAMES)
    assert m.label("left_joint_1") == "left_joint_1 (hardware: panda_left_joint1)"


@pytest.mark.parametrize(("entries", "says"), [
    (["left_joint_9 x"], "a joint of the robot description first"),
    (["left_joint_1 a", "left_joint_1 b"], "each joint mapped once"),
    (["left_joint_1 a", "left_joint_2 a"], "a hardware name no other joint has"),
    (["left_joint_1 left_joint_2"], "not another joint's name"),
    (["left_joint_1"], "two names"),
])
def test_a_bad_map_is_refused_naming_the_entry(entries: list[str], says: str) -> None:
    with pytest.raises(ParameterError, match=says) as info:
        load_profile({"hardware.joint_map": entries}, NAMES, "controller_node")
    assert info.value.key == "controller_node.hardware.joint_map"


def test_a_profile_with_a_map_reads_states_and_writes_commands_by_hardware_name() -> None:
    hw = [renamed(n) for n in NAMES]
    profile = load_profile({"hardware.joint_map": MAP, "hardware.outputs": ["arms"],
                            "hardware.arms.joints": hw[::-1]}, NAMES)
    (idx,) = profile.indices(NAMES)
    np.testing.assert_array_equal(idx, np.arange(14)[::-1])  # hardware order -> description order
    assert profile.outputs[0].joints == tuple(hw[::-1])
    (layout,) = state_layout(profile, NAMES, [], ["gripper"], "sorted")  # the simulator publishes hardware names
    assert set(layout.names) == {*hw, "gripper"}
    merger = CommandMerger(profile, NAMES, 0.005)
    merger.put("arms", np.arange(14.0), np.zeros(14))
    np.testing.assert_array_equal(merger.take(), np.arange(14.0)[::-1])
    with pytest.raises(ParameterError, match="a joint of the hardware") as info:
        load_profile({"hardware.joint_map": MAP, "hardware.outputs": ["arms"], "hardware.arms.joints": NAMES}, NAMES)
    assert info.value.value == NAMES[0]  # the description's name where the hardware's is expected


def test_the_waiting_reason_names_both_names_of_a_missing_joint() -> None:
    profile = load_profile({"hardware.joint_map": MAP}, NAMES)
    assembler = StateAssembler(["/joint_states"], 14, 1)
    assembler.put("/joint_states", StateSample(0, 0, np.arange(13), np.zeros(13)))
    reason = waiting_reason([], assembler, NAMES, profile.joint_map)
    assert f"{NAMES[13]} (hardware: {renamed(NAMES[13])})" in reason, reason


def test_the_profiles_robot_wins_and_a_different_robot_is_refused_naming_both() -> None:
    assert choose_robot("lwr4_cell", "") == "lwr4_cell"
    assert choose_robot("", "baxter") == "baxter"
    assert choose_robot("lwr4_cell", str(ROOT / "config" / "robots" / "lwr4_cell.yaml")) == "lwr4_cell"
    with pytest.raises(ParameterError, match="'panda_pair'.*'lwr4_cell'|'lwr4_cell'.*'panda_pair'") as info:
        choose_robot("lwr4_cell", "panda_pair")
    assert info.value.key == "hardware.robot"


def test_a_relative_robot_path_is_the_profile_files(tmp_path: Path) -> None:
    (tmp_path / "cell").mkdir()
    (tmp_path / "cell" / "my_robot.yaml").write_text((ROOT / "config" / "robots" / "lwr4_cell.yaml").read_text())
    profile = tmp_path / "cell" / "profile.yaml"
    profile.write_text("/**:\n  ros__parameters:\n    hardware:\n      robot: my_robot.yaml\n")
    assert params_robot([profile]) == str(tmp_path / "cell" / "my_robot.yaml")
    assert cell_robot([profile], None) == (str(tmp_path / "cell" / "my_robot.yaml"), str(tmp_path / "cell" / "my_robot.yaml"))
    with pytest.raises(ParameterError, match="baxter"):
        cell_robot([profile], "baxter")
    args = ["--ros-args", "--params-file", str(profile), "-p", "scenario:=assembly"]
    assert with_absolute_robot(args) == [*args, "-p", f"hardware.robot:={tmp_path / 'cell' / 'my_robot.yaml'}"]
    assert with_absolute_robot([*args, "-p", "hardware.robot:=baxter"]) == [*args, "-p", "hardware.robot:=baxter"]
    shipped = ["--params-file", str(ROOT / "config" / "hardware" / "lbr_dual_position.yaml")]
    assert with_absolute_robot(shipped) == shipped  # a robot's name: nothing to resolve


def test_a_node_says_where_its_robot_comes_from() -> None:
    scenario, note = node_scenario({"scenario": "assembly", "robot": "", "hardware.robot": ""}, "controller_node")
    assert scenario.robot.name == "lwr4_cell"
    assert "the scenario 'assembly''s" in note and "hardware.robot" in note
    scenario, note = node_scenario({"scenario": "assembly", "robot": "", "hardware.robot": "panda_pair"}, "sim_node")
    assert scenario.robot.name == "panda_pair" and "from the hardware profile" in note
    with pytest.raises(ParameterError, match="sim_node.hardware.robot"):
        node_scenario({"scenario": "assembly", "robot": "baxter", "hardware.robot": "panda_pair"}, "sim_node")


@pytest.mark.parametrize("verb", [["hardware", "check", "--timeout", "1"], ["launch", "assembly", "--lockstep"],
                                  ["experiment", "assembly"], ["view", "--save", "unused.rrd", "--duration", "1"]])
def test_every_verb_refuses_a_robot_the_profile_does_not_name(verb: list[str], capsys: pytest.CaptureFixture[str],
                                                              tmp_path: Path) -> None:
    """Before anything starts: exit 2, naming the profile's robot and the other one."""
    from dualarm_control.app.cli import main

    profile = ROOT / "config" / "hardware" / "lbr_dual_position.yaml"
    out = ["--output", str(tmp_path)] if verb[0] == "experiment" else []
    assert main([*verb, *out, "--robot", "baxter", "--params", str(profile)]) == 2
    err = capsys.readouterr().err
    assert "hardware.robot" in err and "'lwr4_cell'" in err and "'baxter'" in err, err
    assert not (tmp_path / "metrics.json").exists()
