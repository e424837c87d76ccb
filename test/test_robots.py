"""Robot descriptions (issue 26): validation with errors naming the key and the value, the
resolved URDF (pairs, tool frames, meshes, locked joints), the arms' model against pybullet, and
the assembly task on a robot given only as a user's YAML file."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from dualarm_control.kinematics import DualArmModel
from dualarm_control.robot import LEFT_TOOL, RIGHT_TOOL
from dualarm_control.robot_files import RobotError
from dualarm_control.robot_params import load_robot, robot_names
from dualarm_control.scenario import load_scenario
from dualarm_sim.cell import DualArmCell
from dualarm_sim.cell_config import CellConfig

# no ROS node, no wall-clock verdict: make test runs it at idle CPU priority beside the parallel tests (docs/testing.md)
pytestmark = pytest.mark.background

REPO = Path(__file__).resolve().parents[1]
DATA = Path(__file__).parent / "data"
SHIPPED = ("lwr4_cell", "lwr4_pan_cell", "baxter", "panda_pair", "ur5_pair")
BAXTER = REPO / "config" / "robots" / "baxter.yaml"


def test_shipped_robots_are_listed_and_load() -> None:
    assert set(SHIPPED) <= set(robot_names())
    for name in SHIPPED:
        robot = load_robot(name)
        model = DualArmModel(robot)
        assert model.joint_names == robot.joint_names and model.nq == robot.nq
        assert np.all(model.q_min <= robot.ready) and np.all(robot.ready <= model.q_max)


@pytest.mark.parametrize("name", ["baxter", "panda_pair", "ur5_pair", str(DATA / "xarm7_pair.yaml")])
def test_model_and_simulator_agree_on_the_tools(name: str) -> None:
    """pinocchio (the arms' reduced model) and pybullet (the resolved URDF, locked joints held)
    give the same tool poses at random configurations inside the limits."""
    model = DualArmModel(name)
    rng = np.random.default_rng(3)
    with DualArmCell(CellConfig.for_robot(model.description)) as cell:
        assert cell.joint_names == model.joint_names
        for _ in range(5):
            q = rng.uniform(np.maximum(model.q_min, -3.0), np.minimum(model.q_max, 3.0))
            cell.reset(q)
            o1, o2 = model.tool_poses(q)
            for frame, pose in ((LEFT_TOOL, o1), (RIGHT_TOOL, o2)):
                p, r = cell.link_pose(frame)
                np.testing.assert_allclose(p, pose.translation, atol=1e-6)
                np.testing.assert_allclose(r, pose.rotation, atol=1e-6)


def test_pair_prefixes_names_and_places_the_bases() -> None:
    robot = load_robot("panda_pair")
    assert robot.joint_names[0] == "left_panda_joint1" and robot.joint_names[7] == "right_panda_joint1"
    assert set(robot.locked_positions()) == {f"{s}_panda_finger_joint{i}" for s in ("left", "right") for i in (1, 2)}
    model = DualArmModel(robot)
    o1, o2 = model.tool_poses(np.zeros(14) + np.array([0, 0, 0, -1.5, 0, 1.5, 0] * 2))
    assert o1.translation[1] - o2.translation[1] == pytest.approx(0.7, abs=1e-9)  # the two bases' offset
    xml = robot.urdf_xml
    assert "package://" not in xml and 'name="left_tool_joint"' in xml and 'name="right_tool_joint"' in xml


def test_tool_offset_moves_the_frame(tmp_path: Path) -> None:
    text = re.sub(r"      right_tool_offset: .*\n", "", BAXTER.read_text())  # F2 at right_gripper itself
    (tmp_path / "baxter_base.yaml").write_text(text)
    text = text.replace("      right_tool: right_gripper\n",
                        "      right_tool: right_gripper\n      right_tool_offset: [0.0, 0.0, 0.1, 0.0, 0.0, 90.0]\n")
    path = tmp_path / "baxter_offset.yaml"
    path.write_text(text)
    q = load_robot("baxter").ready
    base = DualArmModel(str(tmp_path / "baxter_base.yaml")).tool_poses(q)[1]
    shifted = DualArmModel(str(path)).tool_poses(q)[1]
    expected = base * pin.SE3(pin.rpy.rpyToMatrix(0, 0, np.pi / 2), np.array([0, 0, 0.1]))
    np.testing.assert_allclose(shifted.homogeneous, expected.homogeneous, atol=1e-12)


def test_locked_joints_are_held_and_published_names(tmp_path: Path) -> None:
    robot = load_robot("baxter")
    with DualArmCell(CellConfig.for_robot(robot), initial_positions=robot.ready) as cell:
        assert cell.held_names == ["head_pan", "l_gripper_l_finger_joint", "l_gripper_r_finger_joint",
                                   "r_gripper_l_finger_joint", "r_gripper_r_finger_joint"]
        cell.apply_command(np.zeros(14))
        for _ in range(200):
            state = cell.step()
            cell.apply_command(np.zeros(14))
        held_q, _ = cell.held_state()
        np.testing.assert_allclose(held_q, 0.0, atol=1e-4)
        np.testing.assert_allclose(state.positions, robot.ready, atol=1e-4)


def bad(tmp_path: Path, old: str, new: str, base: Path = BAXTER) -> str:
    """A copy of a description with one line changed (asserting the line is there)."""
    text = base.read_text()
    assert old in text, old
    path = tmp_path / "bad.yaml"
    path.write_text(text.replace(old, new))
    return str(path)


@pytest.mark.parametrize(("old", "new", "message"), [
    ("left_joints: [left_s0,", "left_joints: [left_sX,", "'robot.left_joints': 'left_sX' is not a joint"),
    ("right_tool: right_gripper", "right_tool: left_gripper",
     "'robot.right_tool': 'left_gripper' is not moved by its arm's joints"),
    ("right_joints: [right_s0,", "right_joints: [left_s0,", "left_s0 in both arms"),
    ("urdf: example-robot-data:baxter_description/urdf/baxter.urdf", "urdf: nowhere/baxter.urdf",
     "'robot.urdf': got 'nowhere/baxter.urdf': no such file"),
    ("98.46, 0.06]", "98.46]", "'robot.ready_positions_deg': got 13 values, expected 14"),
    ("left_tool: left_gripper", "left_tool: no_such_link", "'robot.left_tool': got 'no_such_link', expected a link"),
    ("left_tool: left_gripper", "left_tool: left_gripper\n      locked.left_s0: 0.0",
     "'robot.locked.left_s0': left_s0 is an arm joint"),
    ("left_tool: left_gripper", "left_tool: left_gripper\n      frobnicate: 1", "'robot.frobnicate': unknown key"),
    ("ready_positions_deg: [6.85,", "ready_positions_deg: [300.0,", "left_s0 = 300 deg is outside its range"),
])
def test_bad_descriptions_name_the_key_and_the_value(tmp_path: Path, old: str, new: str, message: str) -> None:
    with pytest.raises(RobotError, match=re.escape(message)):
        load_robot(bad(tmp_path, old, new))


def test_missing_mesh_and_continuous_joint_are_refused(tmp_path: Path) -> None:
    urdf = load_robot("ur5_pair").urdf.read_text()
    mesh = tmp_path / "ur5_missing_mesh.urdf"
    mesh.write_text(urdf.replace("visual/base.dae", "visual/no_such_mesh.dae", 1))
    desc = REPO / "config" / "robots" / "ur5_pair.yaml"
    with pytest.raises(RobotError, match="mesh 'package://example-robot-data/.*no_such_mesh.dae' not found"):
        load_robot(bad(tmp_path, "urdf: example-robot-data:ur_description/urdf/ur5_robot.urdf", f"urdf: {mesh}", desc))
    continuous = tmp_path / "ur5_continuous.urdf"
    continuous.write_text(urdf.replace('name="wrist_3_joint" type="revolute"', 'name="wrist_3_joint" type="continuous"'))
    with pytest.raises(RobotError, match="'wrist_3_joint' is a continuous joint"):
        load_robot(bad(tmp_path, "urdf: example-robot-data:ur_description/urdf/ur5_robot.urdf",
                       f"urdf: {continuous}", desc))


def test_cli_exits_2_naming_the_key(tmp_path: Path) -> None:
    path = bad(tmp_path, "left_joints: [left_s0,", "left_joints: [left_sX,")
    out = subprocess.run([sys.executable, "-m", "dualarm_control.app.cli", "experiment", "assembly", "--robot", path,
                          "--output", str(tmp_path / "out")], capture_output=True, text=True, timeout=120, check=False)
    assert out.returncode == 2, out.stderr
    assert "'robot.left_joints': 'left_sX' is not a joint of baxter.urdf" in out.stderr


def test_scenario_start_belongs_to_its_robot() -> None:
    own = load_scenario("assembly")
    assert own.robot.name == "lwr4_cell" and own.initial_positions[0] == pytest.approx(np.radians(19.0))
    baxter = load_scenario("assembly", "baxter")  # its ready positions with left_w2 at 90 deg
    np.testing.assert_array_equal(np.delete(baxter.initial_positions, 6), np.delete(load_robot("baxter").ready, 6))
    assert baxter.initial_positions[6] == pytest.approx(np.radians(90.0))
    panda = load_scenario("assembly", "panda_pair")  # the scenario's per-robot start
    assert panda.initial_positions[6] == pytest.approx(np.radians(150.0))


def test_a_users_robot_runs_the_assembly(tmp_path: Path) -> None:
    """A pair of xArm7 given only as YAML files (robot and scenario), no code change: the sparse QP
    completes the assembly (the three-solver comparison is the slow test below)."""
    out = subprocess.run([sys.executable, "-m", "dualarm_control.app.cli", "experiment",
                          str(DATA / "xarm_assembly.yaml"), "--solver", "sparse_qp", "--output", str(tmp_path)],
                         capture_output=True, text=True, timeout=600, check=False)
    assert out.returncode == 0, out.stderr[-3000:]
    m = json.loads((tmp_path / "metrics.json").read_text())["sparse_qp"]
    # measured 2026-12 (deterministic): 2.76e-7 m / 1.12e-7 rad; bounds 10 x these
    assert m["final_position_error_m"] < 2.8e-6 and m["final_orientation_error_rad"] < 1.1e-6, m
    assert m["joint_position_limit_violations"] == 0 and m["solver_failures"] == 0, m


@pytest.mark.slow
@pytest.mark.parametrize("robot", ["baxter", "panda_pair", "ur5_pair", str(DATA / "xarm7_pair.yaml")])
def test_table_one_on_every_robot(tmp_path: Path, robot: str) -> None:
    """Issue 26's criteria on each robot: final error < 1 mm / 0.01 rad, no limit violation, no
    solver failure, l0(sparse) < l0(hierarchical) < l0(standard)."""
    scenario = str(DATA / "xarm_assembly.yaml") if robot.endswith(".yaml") else "assembly"
    args = [] if robot.endswith(".yaml") else ["--robot", robot]
    out = subprocess.run([sys.executable, "-m", "dualarm_control.app.cli", "experiment", scenario, *args,
                          "--output", str(tmp_path)], capture_output=True, text=True, timeout=1800, check=False)
    assert out.returncode == 0, out.stderr[-3000:]
    m = json.loads((tmp_path / "metrics.json").read_text())
    for solver, row in m.items():
        assert row["final_position_error_m"] < 1e-3 and row["final_orientation_error_rad"] < 1e-2, (solver, row)
        assert row["joint_position_limit_violations"] == 0 and row["solver_failures"] == 0, (solver, row)
    l0 = {s: row["l0_mean"] for s, row in m.items()}
    assert l0["sparse_qp"] < l0["hierarchical_sparse_qp"] < l0["standard_qp"], l0


def test_the_video_draws_baxter_with_its_meshes() -> None:
    """The video's renderer (pybullet's, on the bag's /robot_description) draws Baxter's red arm
    meshes (the LWR4 cell, built of grey and orange primitives, has no such pixel): what a person
    sees in `dualarm view BAG --video` of a Baxter run."""
    from dualarm_control.app.view.video import CellCamera

    def red_pixels(name: str) -> int:
        robot = load_robot(name)
        camera = CellCamera(robot.urdf_xml, (320, 240), tuple(robot.joint_names))
        try:
            image = camera.render(robot.ready)
        finally:
            camera.close()
        return int(((image[:, :, 0] > 100) & (image[:, :, 1] < 60) & (image[:, :, 2] < 60)).sum())

    baxter, lwr4 = red_pixels("baxter"), red_pixels("lwr4_cell")
    assert baxter > 200 and lwr4 == 0, (baxter, lwr4)  # measured: 566 and 0 at 320x240
