"""The collision limit's parameters (issue 27): validated with the key named, allowed pairs from the
robot, the scenario and the parameter, live changes that keep the collision model."""

from __future__ import annotations

from pathlib import Path

import pytest

from dualarm_control.controller import ControllerParams, RelativeController
from dualarm_control.controller_params import controller_params
from dualarm_control.errors import ParameterError, ScenarioError
from dualarm_control.kinematics import DualArmModel
from dualarm_control.robot_files import RobotError
from dualarm_control.robot_params import robot_from_parameters
from dualarm_control.scenario import load_scenario


@pytest.mark.parametrize(("values", "key"), [
    ({"collision.safety_distance": 0.2}, "collision.influence_distance"),
    ({"collision.gain": 0.0}, "collision.gain"),
    ({"collision.shape_margin": -1.0}, "collision.shape_margin"),
    ({"collision.allowed": ["left_flange"]}, "collision.allowed"),
    ({"collision.enabled": 1}, "collision.enabled"),
])
def test_bad_values_are_refused_naming_the_key(values: dict[str, object], key: str) -> None:
    with pytest.raises(ParameterError, match=key.replace(".", r"\.")):
        controller_params(values)


def test_bad_allowed_entries_in_a_robot_or_a_scenario_name_the_key(tmp_path: Path) -> None:
    flat = {"robot.name": "x", "robot.urdf": "dualarm_cell.urdf", "robot.left_joints": ["a"],
            "robot.right_joints": ["b"], "robot.left_tool": "t", "robot.right_tool": "u",
            "robot.ready_positions_deg": [0.0, 0.0], "robot.collision_allowed": ["only_one_link"]}
    with pytest.raises(RobotError, match=r"robot\.collision_allowed.*'only_one_link'"):
        robot_from_parameters(flat)
    path = tmp_path / "bad.yaml"
    path.write_text((Path(__file__).resolve().parents[1] / "config" / "scenarios" / "assembly.yaml").read_text()
                     .replace('collision_allowed: ["left_tool right_tool"]', 'collision_allowed: ["a b c"]'))
    with pytest.raises(ScenarioError, match=r"scenario\.collision_allowed.*'a b c'"):
        load_scenario(str(path))


def test_the_assemblys_tools_are_allowed_as_whole_end_effectors() -> None:
    scenario = load_scenario("assembly", "baxter")
    params = scenario.controller_params(ControllerParams())
    controller = RelativeController(DualArmModel(scenario.robot), params)
    assert controller.collision_model is not None
    pairs = set(controller.collision_model.pairs)
    assert not any(a.startswith(("l_gripper", "left_gripper")) and b.startswith(("r_gripper", "right_gripper"))
                   for a, b in pairs), "an end-effector pair is still checked"
    assert ("left_gripper_base_link", "right_upper_forearm") in pairs or any("forearm" in b for _, b in pairs)


def test_a_live_change_keeps_the_collision_model_and_off_means_no_rows() -> None:
    model = DualArmModel()
    old = RelativeController(model, ControllerParams())
    new = RelativeController(model, ControllerParams(gain=8.0), collision=old.collision_model).continue_from(old)
    assert new.collision_model is old.collision_model
    off = RelativeController(model, controller_params({"collision.enabled": False}))
    assert off.collision_model is None and [c.name for c in off.constraints] == ["joint_velocity"]
