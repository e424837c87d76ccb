"""Issue 27's shipped scenario ``collision_demo``: goals that drive one arm through the other.

With the collision limit on (the default), every run keeps the smallest link-pair distance over the
recorded joint positions at or above d_s - 1 mm (d_s = 0.03 m), computed independently of the
controller (pybullet's closest points on the URDF's collision shapes, ``dualarm_sim.contacts``) and
by coal, and ends the three collision goals
``stalled`` with "collision constraint: <pair> at 0.0xx m"; the safe goals are reached. With
``collision.enabled: false`` the same scenario drives the links into each other, until the
simulator's contacts stop them (the check can fail: d < 1 mm). In one process and over ROS in lockstep
(the bag's numbers equal the in-process run's) on the LWR4 cell; behind the ``slow`` marker, over ROS
in real time on the LWR4 cell (46 s: the lockstep run over ROS and the in-process run stay in the
default run) and on Baxter (a Baxter run takes about a minute in one process, with 515 link pairs).
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from concurrent.futures import Future
from pathlib import Path
from typing import Any

import pytest
from launching import in_background, selected_tests
from test_ros_live import Launch, dualarm

from dualarm_control.app.record.bag import read_bag
from dualarm_control.app.record.report import summarize_run
from dualarm_control.app.run.experiment import run_scenario
from dualarm_control.controller_params import controller_params
from dualarm_control.kinematics import DualArmModel
from dualarm_control.scenario import load_scenario
from dualarm_sim.cell_config import robot_collision_pairs
from dualarm_sim.contacts import min_distances

SAFETY = 0.03
STATES = ["stalled", "reached", "stalled", "reached", "stalled"]
SOLVER = "sparse_qp"


FIRST_GOAL = str(Path(__file__).parent / "data" / "collision_demo_first_goal.yaml")


def in_process(robot: str, name: str = "collision_demo", **values: Any) -> dict[str, Any]:
    """The run's metrics, and ``pybullet_min_distance_m``: the independent check (pybullet's closest
    points on the URDF's collision shapes, over every recorded joint state, no coal)."""
    scenario = load_scenario(name, robot)
    model = DualArmModel(scenario.robot)
    record = run_scenario(scenario, controller_params({"solver": SOLVER, **values}), model)
    return {**summarize_run(record, scenario, model), **pybullet_check(scenario.robot, record.positions)}


def pybullet_check(robot: Any, positions: Any) -> dict[str, Any]:
    found = min_distances(robot, positions, robot_collision_pairs(robot))
    return {"pybullet_min_distance_m": found.minimum, "pybullet_min_pair": found.pair}


def outcomes(summary: dict[str, Any]) -> list[str]:
    return [part.split(": ")[1].split(",")[0] for part in str(summary["goal_outcomes"]).split(" | ")]


def assert_stops_at_the_safety_distance(summary: dict[str, Any]) -> None:
    assert summary["pybullet_min_distance_m"] >= SAFETY - 1e-3, summary["pybullet_min_pair"]
    assert summary["collision_min_distance_m"] >= SAFETY - 1e-3, summary["collision_min_pair"]
    assert summary["solver_failures"] == 0
    states = outcomes(summary)
    assert [s for i, s in enumerate(states) if i % 2 == 0] == ["stalled"] * 3, summary["goal_outcomes"]
    for part in str(summary["goal_outcomes"]).split(" | ")[::2]:
        assert ": stalled: collision constraint: " in part, part
        distance = float(part.split(" at ")[1].split(" m")[0])
        assert SAFETY - 1e-3 <= distance < 0.10, part  # held near d_s, inside the influence distance


LOCKSTEP_TEST = "test_lockstep_over_ros_equals_the_in_process_run"


@pytest.fixture(scope="module")
def lwr4_lockstep_over_ros(request: pytest.FixtureRequest,
                           tmp_path_factory: pytest.TempPathFactory) -> Iterator[Future[dict[str, Any]] | None]:
    """The lockstep run over ROS on the LWR4 cell (when its test is selected), started in the background
    on a ROS domain of its own, so that it runs while this process computes the in-process runs (the
    other tests of the module use no ROS); its future. It has ended when the module's tests have."""
    if LOCKSTEP_TEST not in selected_tests(request):
        yield None
        return
    out = tmp_path_factory.mktemp("lockstep_over_ros")
    with in_background(lambda env: run_over_ros(out, "lwr4_cell", "--lockstep", env=env)) as run:
        yield run


@pytest.fixture(scope="module")
def lwr4_on(lwr4_lockstep_over_ros: Future[dict[str, Any]] | None) -> dict[str, Any]:
    """The in-process run with the limit on (once the lockstep run over ROS is on its way)."""
    return in_process("lwr4_cell")


def test_in_process_the_goals_stop_at_the_safety_distance(lwr4_on: dict[str, Any]) -> None:
    assert_stops_at_the_safety_distance(lwr4_on)
    assert outcomes(lwr4_on) == STATES, lwr4_on["goal_outcomes"]


def test_with_the_limit_off_the_same_goals_go_through_the_other_arm() -> None:
    """Without the limit the arms are driven into each other: the simulator's contacts stop them at the
    surface (before its self-collision was on, right_link_5 went 10.2 cm into left_flange), so the
    links touch (d < 1 mm by coal and by pybullet) and the collision goal ends short of its pose. The first
    goal alone (test/data/collision_demo_first_goal.yaml: 1,407 cycles of the demo's 6,644) shows it."""
    summary = in_process("lwr4_cell", FIRST_GOAL, **{"collision.enabled": False})
    assert outcomes(summary) == ["stalled"], summary["goal_outcomes"]
    assert summary["collision_min_distance_m"] < 1e-3, summary["collision_min_pair"]
    assert summary["pybullet_min_distance_m"] < 1e-3, summary["pybullet_min_pair"]


def test_a_shipped_hardware_profile_bounds_the_collision_demos_acceleration() -> None:
    """Issue 40: the shipped hardware profiles turn the joint acceleration bound on (10 rad/s^2); with it the
    collision demo peaks at the bound (91.8 rad/s^2 without), and still stops at the safety distance."""
    from dualarm_control.params import read_params_file

    root = Path(__file__).parents[1] / "config" / "hardware"
    bounds = {f.stem: read_params_file(f, "controller_node")["acceleration_limit"]
              for f in (root / "ros2_control_velocity.yaml", root / "lbr_dual_position.yaml")}
    assert set(map(tuple, bounds.values())) == {(10.0,)}, bounds
    summary = in_process("lwr4_cell", acceleration_limit=[10.0])
    assert summary["max_joint_acceleration"] <= 10.0 * (1 + 1e-6), summary["max_joint_acceleration"]
    assert_stops_at_the_safety_distance(summary)


def run_over_ros(tmp_path: Path, robot: str, *mode: str, env: dict[str, str] | None = None) -> dict[str, Any]:
    """The run's metrics from its bag, and ``pybullet_min_distance_m``; ``env`` adds to the launch's
    environment (a ROS domain of its own)."""
    bag = tmp_path / "bag"
    launch = Launch("collision_demo", "--robot", robot, "--solver", SOLVER, *mode, "--record", str(bag), env=env)
    try:
        code = launch.finish(timeout=900)
    finally:
        launch.kill()
    assert code == 0, "\n".join(launch.lines[-40:])
    assert any("collision constraint active:" in line for line in launch.lines), "\n".join(launch.lines[-40:])
    report = dualarm("report", str(bag), "--output", str(tmp_path / "report"), timeout=600)
    assert report.returncode == 0, report.stderr[-2000:]
    assert "stalled: collision constraint: " in report.stdout, report.stdout[-2000:]
    recorded = read_bag(bag)
    states, _ = recorded.joint_states(recorded.robot.joint_names)
    # /diagnostics carries the closest pair every cycle (issue 27)
    cycles = [v for _, v in recorded.cycles if "stamp_ns" in v]
    assert cycles and all("collision_distance_m" in v and "collision_active" in v for v in cycles)
    held = [v for v in cycles if int(v["collision_active"]) > 0]
    assert held and all(v["collision_pair"] and float(v["collision_distance_m"]) < 0.1 for v in held)
    metrics = json.loads((tmp_path / "report" / "metrics.json").read_text())[SOLVER]
    return {**metrics, **pybullet_check(recorded.robot, states.values)}


def test_lockstep_over_ros_equals_the_in_process_run(lwr4_lockstep_over_ros: Future[dict[str, Any]] | None,
                                                     lwr4_on: dict[str, Any]) -> None:
    assert lwr4_lockstep_over_ros is not None
    bag = lwr4_lockstep_over_ros.result()
    assert_stops_at_the_safety_distance(bag)
    assert bag["goal_outcomes"] == lwr4_on["goal_outcomes"]  # to the printed 0.01 mm and 1e-4 rad
    # Not bit for bit as the assembly (1e-9): at a stall the commands follow the last bits of their inputs
    # (docs/collision.md, "At a stall"), and the target's quaternion round trip through /relative_target
    # changes those. Measured 2026-12-07: l0_mean equal, l1_integral 1.7e-8 and l2_integral 3.0e-7 apart
    # (relative). Until then a pytest worker's history also changed coal's box (test_box_support.py): l0_mean
    # 1.8e-3 apart, l1_integral 8e-5.
    print("lockstep bag against the in-process run, relative:",
          {key: abs(bag[key] - lwr4_on[key]) / abs(lwr4_on[key]) for key in ("l0_mean", "l1_integral", "l2_integral")})
    assert abs(bag["collision_min_distance_m"] - lwr4_on["collision_min_distance_m"]) <= 1e-6
    for key, share in (("l0_mean", 1e-3), ("l1_integral", 1e-5), ("l2_integral", 1e-5)):
        assert abs(bag[key] - lwr4_on[key]) <= share * abs(lwr4_on[key]), (key, bag[key], lwr4_on[key])


@pytest.mark.slow
def test_real_time_over_ros_stops_at_the_safety_distance(tmp_path: Path) -> None:
    """The same assertions as the lockstep run, in real time (``slow``: 46 s; the lockstep run over ROS
    and the in-process run cover the same limit in the default run)."""
    assert_stops_at_the_safety_distance(run_over_ros(tmp_path, "lwr4_cell"))


@pytest.mark.slow
def test_baxter_in_process_on_and_off() -> None:
    on = in_process("baxter")
    assert_stops_at_the_safety_distance(on)
    off = in_process("baxter", **{"collision.enabled": False})
    assert off["collision_min_distance_m"] < 1e-3, off["collision_min_pair"]
    assert off["pybullet_min_distance_m"] < 1e-3, off["pybullet_min_pair"]


@pytest.mark.slow
@pytest.mark.parametrize("mode", [("--lockstep",), ()], ids=["lockstep", "real_time"])
def test_baxter_over_ros_stops_at_the_safety_distance(tmp_path: Path, mode: tuple[str, ...]) -> None:
    assert_stops_at_the_safety_distance(run_over_ros(tmp_path, "baxter", *mode))
