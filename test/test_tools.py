"""Tools are geometry (issue 40 item 2; docs/robots.md, "Tools"): a tool set's bodies become links of
the resolved URDF (drawn, simulated and collision-checked like the robot's own links); the LWR4
cell's hole block has a real hole; no shipped robot allows a pair between its two arms robot-wide;
a goal driving the peg into the hole block's wall stops at the safety distance, measured on the
simulator's own shapes, and ends stalled naming the pair."""

from __future__ import annotations

import math
from pathlib import Path

import coal
import numpy as np
import pinocchio as pin
import pytest

from dualarm_control.collision import CollisionModel
from dualarm_control.kinematics import DualArmModel
from dualarm_control.robot_files import RobotError
from dualarm_control.robot_params import load_robot, robot_names
from dualarm_control.tool_bodies import ToolBody, load_tool_set
from dualarm_sim.cell import DualArmCell
from dualarm_sim.cell_config import CellConfig

DATA = Path(__file__).parent / "data"
HOLE = ("left_hole_floor", "left_hole_wall_xp", "left_hole_wall_xn", "left_hole_wall_yp", "left_hole_wall_yn")
SAFETY = 0.03


def test_the_tool_sets_bodies_are_links_of_the_cell() -> None:
    """The bodies are links with a visual and a collision shape in the resolved URDF, links of the
    collision model in their arm's end effector, and links of the simulator's multibody."""
    robot = load_robot("lwr4_cell")
    assert robot.tools is not None and robot.tools.links() == [*HOLE, "right_peg"]
    for link in (*HOLE, "right_peg"):
        assert f'<link name="{link}">' in robot.urdf_xml
    collision = CollisionModel(DualArmModel(robot))
    assert set(HOLE) <= set(collision.end_effector("left_tool")) and "right_peg" in collision.end_effector("right_tool")
    assert not set(HOLE) & set(collision.end_effector("right_tool"))
    assert ("left_hole_wall_xp", "right_peg") in collision.pairs  # no allowance: checked like any link
    with DualArmCell(CellConfig.for_robot(robot)) as cell:
        names = set(cell._link_index)
        assert {*HOLE, "right_peg"} <= names, sorted(names)
        assert ("left_hole_wall_xp", "right_peg") in cell.collision_pairs


def _placed(body: ToolBody, frame: pin.SE3) -> tuple[coal.CollisionGeometry, coal.Transform3s]:
    """A body's coal shape and its placement in the world, its tool frame at ``frame``."""
    shape: coal.CollisionGeometry
    if body.shape == "box":
        shape = coal.Box(*body.size)
    elif body.shape == "cylinder":
        shape = coal.Cylinder(*body.size)
    else:
        shape = coal.Sphere(body.size[0])
    local = pin.SE3(pin.rpy.rpyToMatrix(*np.radians(body.rpy_deg)), np.array(body.xyz))
    placed = frame * local
    return shape, coal.Transform3s(placed.rotation, placed.translation)


@pytest.mark.parametrize("depth", [0.03, 0.0])
def test_the_peg_fits_in_the_hole(depth: float) -> None:
    """At the assembly's end (F2 in F1: 3 cm down the hole axis, z axes opposed) the peg is 5 mm
    from each wall and 2 cm above the floor; at the entrance, 5 cm above the floor (a solid block,
    the LWR4 cell's old one, would hold it at -depth, overlapping)."""
    tools = load_tool_set("peg_and_hole")
    peg = next(b for b in tools.bodies if b.name == "peg")
    f2 = pin.SE3(pin.rpy.rpyToMatrix(math.pi, 0.0, 0.0), np.array([0.0, 0.0, -depth]))
    peg_shape, peg_place = _placed(peg, f2)
    for body in tools.bodies:
        if body.side != "left":
            continue
        shape, place = _placed(body, pin.SE3.Identity())
        d = coal.distance(shape, place, peg_shape, peg_place, coal.DistanceRequest(), coal.DistanceResult())
        expected = 0.05 - depth if body.name == "hole_floor" else 0.005
        assert d == pytest.approx(expected, abs=1e-7), body.name  # GJK on the cylinder: 4e-9


def test_no_robot_allows_a_pair_between_its_arms() -> None:
    """Every robot description of config/robots/ allows (robot-wide) only pairs on one arm or an arm
    against the fixed parts (shapes that overlap by construction): never one link of each arm, and
    no tool set body; the tools' contacts belong to the task (the assembly scenario)."""
    for name in robot_names():
        robot = load_robot(name)
        collision = CollisionModel(DualArmModel(robot), allowed=robot.collision_allowed)
        tools = set(robot.tools.links()) if robot.tools is not None else set()
        for a, b in robot.collision_allowed:
            sides = {collision.link_side(a), collision.link_side(b)}
            assert sides != {"left", "right"}, (name, a, b)
            assert not {a, b} & tools, (name, a, b)


@pytest.mark.parametrize(("old", "new", "message"), [
    ("shape: cylinder", "shape: cone", "'tools.peg.shape': got 'cone', expected one of box, cylinder"),
    ("size: [0.015, 0.12]", "size: [0.015]", "'tools.peg.size': got [0.015], expected 2 finite numbers"),
    ("size: [0.015, 0.12]", "size: [0.015, -0.12]", "'tools.peg.size': got [0.015, -0.12], expected values > 0"),
    ("mass: 0.3", "mass: 0", "'tools.peg.mass': got 0, expected a mass > 0"),
    ("right: [peg]", "right: [peg, hole_floor]", "body 'hole_floor' listed twice"),
    ("right: [peg]", "right: []", "'tools.peg.shape': unknown key"),
    ("        xyz: [0.0, 0.0, -0.06]", "        xzy: [0.0, 0.0, -0.06]", "'tools.peg.xzy': unknown key"),
])
def test_bad_tool_sets_name_the_key_and_the_value(tmp_path: Path, old: str, new: str, message: str) -> None:
    text = (Path(__file__).parents[1] / "config" / "tools" / "peg_and_hole.yaml").read_text()
    peg = text.index("      peg:")
    assert old in text
    changed = text[:peg] + text[peg:].replace(old, new, 1) if old in text[peg:] else text.replace(old, new, 1)
    path = tmp_path / "tools.yaml"
    path.write_text(changed)
    with pytest.raises(RobotError) as info:
        load_tool_set(str(path))
    assert message in str(info.value), str(info.value)


def test_a_robot_naming_an_unknown_tool_set_or_a_taken_link_is_refused(tmp_path: Path) -> None:
    desc = (Path(__file__).parents[1] / "config" / "robots" / "lwr4_cell.yaml").read_text()
    bad = tmp_path / "robot.yaml"
    bad.write_text(desc.replace("tools: peg_and_hole", "tools: nope"))
    with pytest.raises(RobotError, match="unknown tool set 'nope'; valid choices: peg_and_hole"):
        load_robot(str(bad))
    tools = tmp_path / "taken.yaml"
    tools.write_text("tools:\n  ros__parameters:\n    tools:\n      name: taken\n      left: [flange]\n"
                     "      flange: {shape: sphere, size: [0.01]}\n")
    bad.write_text(desc.replace("tools: peg_and_hole", f"tools: {tools}"))
    with pytest.raises(RobotError, match="body 'flange' would be link 'left_flange', which the URDF already has"):
        load_robot(str(bad))


def test_a_goal_into_the_hole_blocks_wall_stops_at_the_safety_distance() -> None:
    """The peg driven into the hole block's wall (test/data/peg_into_wall.yaml, no allowance) stops at
    d_s, as measured on the simulator's own shapes (pybullet's closest points over every recorded
    state, every checked pair of the two arms, the tools included), and the goal ends stalled naming a
    pair of the peg and the hole block."""
    from dualarm_control.app.record.report import summarize_run
    from dualarm_control.app.run.experiment import run_scenario
    from dualarm_control.controller_params import controller_params
    from dualarm_control.scenario import load_scenario
    from dualarm_sim.cell_config import robot_collision_pairs
    from dualarm_sim.contacts import min_distances

    scenario = load_scenario(str(DATA / "peg_into_wall.yaml"))
    model = DualArmModel(scenario.robot)
    record = run_scenario(scenario, controller_params({"solver": "sparse_qp"}), model)
    summary = summarize_run(record, scenario, model)
    found = min_distances(scenario.robot, record.positions, robot_collision_pairs(scenario.robot))
    assert found.minimum >= SAFETY - 1e-3, (found.minimum, found.pair)
    outcome = str(summary["goal_outcomes"])
    assert ": stalled: collision constraint: " in outcome, outcome
    pair = outcome.split("collision constraint: ")[1].split(" at ")[0]
    assert "right_peg" in pair and any(link in pair for link in HOLE), outcome
    distance = float(outcome.split(" at ")[1].split(" m")[0])
    assert SAFETY - 1e-3 <= distance < SAFETY + 5e-3, outcome


def test_the_assembly_says_which_allowed_contacts_it_used() -> None:
    """The assembly allows the two end effectors (scenario.collision_allowed: left_tool right_tool): the
    run reports, per segment, the closest allowed pair and whether it came under d_s: the approach ends
    5 cm above the hole (not used), the insertion and the screw hold the peg 5 mm from the walls (used)."""
    from dualarm_control.app.record.report import summarize_run
    from dualarm_control.app.run.experiment import run_scenario
    from dualarm_control.controller_params import controller_params
    from dualarm_control.scenario import load_scenario

    scenario = load_scenario("assembly")
    model = DualArmModel(scenario.robot)
    summary = summarize_run(run_scenario(scenario, controller_params({"solver": "sparse_qp"}), model), scenario, model)
    assert summary["allowances_used"] == "left_tool right_tool"
    parts = str(summary["allowance_outcomes"]).split(" | ")
    assert [p.split(": ")[1] for p in parts] == ["not used", "used", "used"], parts
    for part in parts[1:]:
        pair, at = part.split("closest ")[1].split(" at ")
        assert pair.startswith("left_hole_wall_") and pair.endswith(" – right_peg"), part
        assert float(at.split(" m")[0]) == pytest.approx(0.005, abs=5e-4), part  # centred in the hole


def test_robot_show_lists_the_tools_and_ready_refuses_a_pair_under_its_clearance(
        capsys: pytest.CaptureFixture[str]) -> None:
    """`dualarm robot show` names the tool set's links; `dualarm robot ready` keeps only configurations whose
    checked pairs (tools included) are clear by 5 cm, and says which pair was the clearest one refused."""
    from dualarm_control.app.robot.command import show_command
    from dualarm_control.app.robot.ready import CLEARANCE, find_ready
    from dualarm_control.errors import DualArmError

    assert show_command("lwr4_cell") == 0
    out = capsys.readouterr().out
    assert "tool set 'peg_and_hole' on right_tool: right_peg" in out and "robot-wide, overlapping by construction): none" \
        in out, out
    model = DualArmModel("panda_pair")
    found = find_ready(model, 0.3, np.array([0.5, 0.0, 0.4]), starts=3)
    assert found.clearance[0] >= CLEARANCE and " – " in found.clearance[1], found.clearance
    with pytest.raises(DualArmError, match=r"was the clearest refused: under 5\.0 m"):
        find_ready(model, 0.3, np.array([0.5, 0.0, 0.4]), starts=3, clearance=5.0)
