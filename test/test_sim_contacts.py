"""The simulator sees contacts, and an independent check of distances from pybullet (issue 27).

dualarm_sim/contacts.py and dualarm_sim/collision_filter.py; docs/collision.md ("The
simulator's contacts", "Independent check with pybullet") has the figures these tests print.
"""

from __future__ import annotations

import json
import math
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pybullet as p
import pytest
from waiting import exited, node_env, wait_until

from dualarm_control.collision import CollisionModel
from dualarm_control.errors import DimensionError
from dualarm_control.kinematics import DualArmModel
from dualarm_control.robot_params import load_robot
from dualarm_control.scenario import load_scenario
from dualarm_sim.cell import DualArmCell
from dualarm_sim.cell_config import CellConfig, robot_collision_pairs
from dualarm_sim.contacts import ContactCounter, min_distances

ROBOTS = ("lwr4_cell", "baxter")
SHAPE_TOLERANCE = 2.5e-3
"""|pybullet - coal| [m] per pair: pybullet grows hulls and rounds edges by its 1 mm collision margin
and meshes its cylinders (test_collision.py's test_distances_match_pybullet: -2.0 to +1.3 mm)."""
RIGHT_INTO_LEFT = np.array([-1.3, -1.34, -0.26, -0.58, 0.0, -1.09, -0.09])
"""LWR4 right-arm joints [rad] that put right_link_6 7 cm into left_link_3 (left arm at the ready
configuration); found by random search with min_distances. On the straight joint path from the
ready configuration the first pair to touch is left_link_3 - right_link_6, at 92 % of the way."""
FIRST_PAIR = ("left_link_3", "right_link_6")


def into_contact(fraction: float) -> np.ndarray:
    """The LWR4 configuration that fraction of the way from ready to RIGHT_INTO_LEFT [rad], (14,)."""
    ready = load_robot("lwr4_cell").ready
    return ready + fraction * (np.concatenate((ready[:7], RIGHT_INTO_LEFT)) - ready)


# ---- the independent check ----------------------------------------------------------------------

@pytest.mark.parametrize("name", ROBOTS)
def test_min_distances_agree_with_coal_at_ready(name: str) -> None:
    """At the ready configuration, pybullet's distance of every pair within the cutoff agrees with
    coal's to 2.5 mm, and so does the minimum over the pairs (measured, pybullet - coal: lwr4_cell
    -2.00 to -0.53 mm over its 5 pairs within 0.2 m, baxter -1.99 to -0.81 mm over 14: pybullet's
    shapes are grown by its 1 mm margin each)."""
    robot = load_robot(name)
    model = CollisionModel(DualArmModel(robot), allowed=robot.collision_allowed)
    result = min_distances(robot, robot.ready[None], model.pairs)
    coal = {(d.link_a, d.link_b): d.distance for d in model.distances(robot.ready)}
    near = np.isfinite(result.pair_minimum)
    diff = np.array([result.pair_minimum[i] - coal[pair] for i, pair in enumerate(result.pairs) if near[i]])
    closest = model.closest(robot.ready)
    summary = (f"{name}: {near.sum()} of {len(result.pairs)} pairs within {result.cutoff} m, pybullet - coal in "
               f"[{diff.min() * 1e3:.2f}, {diff.max() * 1e3:.2f}] mm; closest pybullet {result.pair} "
               f"{result.minimum:.5f} m, coal {closest.link_a}-{closest.link_b} {closest.distance:.5f} m")
    print(summary)
    assert near.sum() >= 5 and np.abs(diff).max() <= SHAPE_TOLERANCE, summary
    assert abs(result.minimum - closest.distance) <= SHAPE_TOLERANCE, summary
    assert result.minimum > 0.0, summary  # no pair touches at ready once the overlaps are allowed
    assert result.row == 0 and result.row_pair(0) == result.pair


def test_min_distances_sees_penetration_and_finds_the_row() -> None:
    """Along the path into the left arm: inf/positive first, then <= 0 with the right pair, deepest
    at the end; the run's minimum is the last row's."""
    robot = load_robot("lwr4_cell")
    path = np.array([into_contact(f) for f in np.linspace(0.0, 1.0, 26)])
    result = min_distances(robot, path, robot_collision_pairs(robot))
    assert result.distances[0] > 0.1
    first = int(np.flatnonzero(result.distances <= 0.0)[0])
    assert result.row_pair(first) == FIRST_PAIR, (first, result.row_pair(first))
    assert result.row == len(path) - 1 and result.minimum < -0.05 and result.pair == FIRST_PAIR, result.minimum
    coal = CollisionModel(DualArmModel(robot)).closest(path[-1])
    assert (coal.link_a, coal.link_b) == FIRST_PAIR and coal.distance < -0.05
    # the bounding-box prefilter drops no pair that getClosestPoints would give: every pair, every row
    plain = np.full((len(path), len(result.pairs)), math.inf)
    with DualArmCell(CellConfig.for_robot(robot, collisions=False)) as cell:
        links = [(cell.link_index(a), cell.link_index(b)) for a, b in result.pairs]
        for k, q in enumerate(path):
            cell.pose(q)
            for i, (a, b) in enumerate(links):
                points = p.getClosestPoints(cell.body_id, cell.body_id, result.cutoff, a, b,
                                            physicsClientId=cell.client_id)
                plain[k, i] = min((c[8] for c in points), default=math.inf)
    assert np.array_equal(plain.min(axis=1), result.distances)
    assert np.array_equal(plain.min(axis=0), result.pair_minimum)


def test_min_distances_names_bad_input() -> None:
    pairs = robot_collision_pairs("lwr4_cell")
    with pytest.raises(DimensionError, match=r"\(k, 14\)"):
        min_distances("lwr4_cell", np.zeros(14), pairs)
    with pytest.raises(ValueError, match="cutoff"):
        min_distances("lwr4_cell", np.zeros((1, 14)), pairs, cutoff=0.0)
    with pytest.raises(ValueError, match="no link pair"):
        min_distances("lwr4_cell", np.zeros((1, 14)), [])
    with pytest.raises(KeyError, match="nope"):
        min_distances("lwr4_cell", np.zeros((1, 14)), [("left_link_3", "nope")])


# ---- the simulator's contacts -------------------------------------------------------------------

@pytest.mark.parametrize("name", ROBOTS)
def test_no_contact_at_ready_and_at_the_assembly_start(name: str) -> None:
    """Adjacent links, the robot's collision_allowed pairs (Baxter's torso and lower shoulders,
    forearms and wrists) and the end effectors are filtered: 40 steps at rest, no contact."""
    for start in (load_robot(name).ready, load_scenario("assembly", name).initial_positions):
        with DualArmCell(CellConfig.for_robot(name), initial_positions=start) as cell:
            assert len(cell.collision_pairs) >= 100
            counter = ContactCounter()
            for _ in range(40):
                cell.apply_command(np.zeros(len(start)))
                cell.step()
                assert not counter.update(cell.contacts()), cell.contacts()
        assert counter.total == 0 and counter.steps == 40


@pytest.mark.parametrize("name", ROBOTS)
def test_self_collision_does_not_change_motion_without_contact(name: str) -> None:
    """The same commands with and without the collision pairs: the same states, bit for bit (the
    LWR4 and Baxter assemblies and pan cleaning in one process were checked so too: docs)."""
    robot = load_robot(name)
    with (DualArmCell(CellConfig.for_robot(robot), robot.ready) as on,
          DualArmCell(CellConfig.for_robot(robot, collisions=False), robot.ready) as off):
        assert on.collision_pairs and not off.collision_pairs
        for k in range(300):
            qd = 0.3 * np.sin(np.arange(robot.nq) + 0.02 * k)
            on.apply_command(qd)
            off.apply_command(qd)
            a, b = on.step(), off.step()
            assert np.array_equal(a.positions, b.positions) and np.array_equal(a.velocities, b.velocities), k
            assert not on.contacts()


def test_driving_the_right_arm_into_the_left_is_counted() -> None:
    """The right arm driven along the path into the left arm (2 s at constant joint velocity): the
    pair the independent check names first comes into contact, is counted once per step, reported
    by an event, and the physics stops it (it does not pass through as before)."""
    robot = load_robot("lwr4_cell")
    start, goal = into_contact(0.0), into_contact(1.0)
    period, seconds = 0.005, 2.0
    velocity = (goal - start) / seconds
    counter = ContactCounter()
    events = []
    q = []
    with DualArmCell(CellConfig.for_robot(robot, control_period=period), initial_positions=start) as cell:
        for _ in range(round(seconds / period)):
            cell.apply_command(velocity)
            q.append(cell.step().positions)
            events += counter.update(cell.contacts())
    print(f"contacts {counter.total} ({counter.pairs_text()}), deepest {counter.deepest * 1e3:.1f} mm, "
          f"events {[e.text() for e in events]}")
    assert counter.total > 10 and FIRST_PAIR in counter.per_pair, counter.per_pair
    assert events[0].pair == FIRST_PAIR and events[0].started
    assert next(iter(counter.per_pair)) == FIRST_PAIR
    assert 0.0 <= counter.deepest < 0.02  # the physics holds the links at the surface (< 2 cm deep)
    check = min_distances(robot, np.array(q), robot_collision_pairs(robot))
    assert check.minimum > -0.02 and check.pair == FIRST_PAIR, (check.minimum, check.pair)  # not 7 cm through


def test_baxter_allowed_pairs_are_not_counted() -> None:
    """Baxter's right_s0 turned 0.8 rad from ready swings the upper elbow into the torso's hull
    (min_distances: contact from +0.68 rad). torso - right_upper_elbow is one of Baxter's
    collision_allowed pairs (the torso's hull covers the elbows in 62 % of configurations,
    docs/collision.md "Allowed pairs"): not counted, as no pair of collision_allowed is a collision pair
    of the cell. The two grippers (end effectors, with the peg and hole) collide like any links (issue
    40: nothing between the arms is allowed robot-wide) unless the scenario allows them, as the assembly
    does. (Counting: the LWR4 test above.)"""
    robot = load_robot("baxter")
    allowed = set(robot.collision_allowed)
    assert ("torso", "left_lower_shoulder") in allowed
    counter = ContactCounter()
    with DualArmCell(CellConfig.for_robot(robot), initial_positions=robot.ready) as cell:
        pairs = set(cell.collision_pairs)
        assert not pairs & allowed and ("left_hole_wall_xp", "right_peg") in pairs
        assert any("gripper" in a and "gripper" in b for a, b in pairs)
        velocity = np.zeros(robot.nq)
        velocity[robot.joint_names.index("right_s0")] = 0.8
        for _ in range(200):  # 1 s
            cell.apply_command(velocity)
            cell.step()
            counter.update(cell.contacts())
    assert ("torso", "right_upper_elbow") in allowed
    assert list(counter.per_pair) == [], counter.per_pair
    assembly = CellConfig.for_robot(robot, allowed=(("left_tool", "right_tool"),))  # the scenario's allowance
    assert not any("gripper" in a and "gripper" in b for a, b in assembly.collision_pairs)
    assert ("left_hole_wall_xp", "right_peg") not in assembly.collision_pairs


def test_contact_counter_events_and_diagnostics() -> None:
    counter = ContactCounter()
    ab, cd = ("a", "b"), ("c", "d")
    assert counter.diagnostics() == {"contacts": 0, "contact_pairs": "", "deepest_contact_m": 0.0, "in_contact": 0}
    started = counter.update({ab: -0.002})
    assert [(e.pair, e.started, e.step, e.depth) for e in started] == [(ab, True, 1, 0.002)]
    assert counter.update({ab: -0.004, cd: 0.0})[0].pair == cd
    ended = counter.update({cd: -0.001})
    assert [(e.pair, e.started, e.steps, e.depth) for e in ended] == [(ab, False, 2, 0.004)]
    assert "ended after 2 steps" in ended[0].text() and "4.0 mm" in ended[0].text()
    counter.update({})
    assert counter.diagnostics() == {"contacts": 4, "contact_pairs": "a-b:2, c-d:2", "deepest_contact_m": 0.004,
                                     "in_contact": 0}
    assert math.isclose(counter.deepest, 0.004) and counter.steps == 4


def test_sim_node_reports_contacts_on_diagnostics(tmp_path: Path) -> None:
    """sim_node started in contact (a plan whose first configuration is 92 % of the way into the
    left arm), in real time, never commanded: its /diagnostics status counts the contact-steps of
    left_link_3 - right_link_6, and the log names the pair and its depth when the contact starts
    and ends."""
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.executors import SingleThreadedExecutor

    from dualarm_control.planning.plan_file import PLAN_FORMAT
    from dualarm_control.ros.node import init_rclpy

    robot = load_robot("lwr4_cell")
    plan = tmp_path / "plan.json"
    plan.write_text(json.dumps({"format": PLAN_FORMAT, "scenario": "assembly", "joint_names": robot.joint_names,
                                "points": [{"configuration_rad": into_contact(0.95).tolist()}]}))
    sim = subprocess.Popen([sys.executable, "-u", "-m", "dualarm_sim.sim_node", "--ros-args", "-p",
                            "thread_priority:=0", "-p", f"plan:={plan}"],
                           stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=node_env())
    context = init_rclpy([])
    node = rclpy.create_node("contact_listener", context=context)
    statuses: list[dict[str, str]] = []
    node.create_subscription(DiagnosticArray, "/diagnostics", lambda m: statuses.extend(
        {kv.key: kv.value for kv in s.values} | {"_message": s.message, "_level": str(int.from_bytes(s.level))}
        for s in m.status if s.name == "sim_node"), 10)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    try:
        wait_until(lambda: any(int(s.get("contacts", 0)) > 0 for s in statuses), lambda: statuses[-3:],
                   what="a sim_node status counting contacts", timeout=120.0,
                   step=lambda: executor.spin_once(timeout_sec=0.1), gone=exited(sim, "sim_node"))
    finally:
        node.destroy_node()
        context.try_shutdown()
        sim.send_signal(signal.SIGINT)
        output, _ = sim.communicate(timeout=30)
    assert sim.returncode == 0, output
    status = next(s for s in statuses if int(s["contacts"]) > 0)
    assert "left_link_3-right_link_6:" in status["contact_pairs"], status
    assert float(status["deepest_contact_m"]) > 0.0, status
    # the physics pushes the links apart within about 15 steps (measured: 22 mm deep at the start),
    # usually before the first status (1 s): WARN naming the pairs while any touches, else OK
    touching = int(status["in_contact"]) > 0
    assert status["_level"] == ("1" if touching else "0"), status
    assert status["_message"].startswith("links in contact: ") == touching, status
    assert "contact left_link_3 - right_link_6:" in output and "contact-steps (left_link_3" in output, output
