"""Issue 40: every segment of a relative trajectory gets a verdict, and a stall names what held the arms.

``judge_segments`` on hand-made records of the LWR4 cell: arms that stay put (the first segment's end is
their pose, the second is 1 cm off), arms that arrive within the window after a moving segment's end,
and a stall at a joint limit; the report's segment keys on the shipped ur5_pair assembly, which reaches
every segment with the collision limit on (its peg and hole are geometry: docs/robots.md); and a target behind the other arm, in one process
and over ROS (the trajectory node's verdict in the launch's output and on /diagnostics, the bag's report).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from dualarm_control.app.cli import main as main_cli
from dualarm_control.drive_monitor import (
    POSITION_TOLERANCE,
    SEGMENT_WINDOW,
    judge_segments,
)
from dualarm_control.kinematics import DualArmModel
from dualarm_control.scenario import load_scenario

PERIOD = 0.005


@pytest.fixture(scope="module")
def model() -> DualArmModel:
    return DualArmModel()


def start(model: DualArmModel) -> np.ndarray:
    return load_scenario("assembly").initial_positions


def test_arms_that_stay_put_reach_their_own_pose_and_stall_one_centimetre_short(model: DualArmModel) -> None:
    q0 = start(model)
    p0, r0 = model.relative_pose(q0)
    time = np.arange(400) * PERIOD
    positions = np.repeat(q0[None, :], len(time), axis=0)
    got = judge_segments(model, ["hold", "move"], [1.0, 2.0], [(p0, r0), (p0 + [0.01, 0.0, 0.0], r0)], time,
                         positions, q0)
    assert [o.state for o in got] == ["reached", "stalled"]
    assert got[0].text().startswith("segment 1 'hold' (t = 1 s): reached, error 0.000 mm")
    assert got[1].distance == pytest.approx(0.01, abs=1e-12)
    assert "remaining error 10.00 mm, 0.0000 rad at the end of the run; joints at a limit: " in got[1].reason


def test_a_segment_is_judged_at_its_closest_cycle_in_the_window(model: DualArmModel) -> None:
    """The arms pass the end pose 0.1 s after the segment's end (a tracking lag): reached. Passing it later
    than the window (SEGMENT_WINDOW after) is a stall, with the error at the closest cycle in the window."""
    q0 = start(model)
    time = np.arange(600) * PERIOD
    positions = np.repeat(q0[None, :], len(time), axis=0)
    moved = q0.copy()
    moved[0] += 0.02  # the left shoulder: the relative pose moves by centimetres
    end_pose = model.relative_pose(moved)
    arrive = 1.0 + 0.1
    positions[time >= arrive] = moved
    final = q0  # the run's final positions belong to the last segment, judged separately
    got = judge_segments(model, ["lagging", "last"], [1.0, 3.0], [end_pose, model.relative_pose(q0)], time,
                         positions, final)
    assert got[0].state == "reached" and got[0].distance < POSITION_TOLERANCE
    late = np.repeat(q0[None, :], len(time), axis=0)
    late[time >= 1.0 + SEGMENT_WINDOW[1] + 0.05] = moved
    stalled = judge_segments(model, ["lagging", "last"], [1.0, 3.0], [end_pose, model.relative_pose(q0)], time,
                             late, final)[0]
    distance = float(np.linalg.norm(model.relative_pose(q0)[0] - end_pose[0]))
    angle = float(np.linalg.norm(pin.log3(end_pose[1] @ model.relative_pose(q0)[1].T)))
    assert stalled.state == "stalled"
    assert (stalled.distance, stalled.angle) == pytest.approx((distance, angle), abs=1e-12)


def test_a_stall_at_a_joint_limit_names_the_joint(model: DualArmModel) -> None:
    q = start(model).copy()
    q[3] = model.q_max[3] - 1e-3
    p, r = model.relative_pose(q)
    time = np.arange(10) * PERIOD
    got = judge_segments(model, ["out"], [0.02], [(p + [0.0, 0.0, 0.05], r)], time, np.repeat(q[None], 10, axis=0), q)
    assert got[0].state == "stalled" and model.joint_names[3] in got[0].reason.split("joints at a limit: ")[1]


def test_the_ur5_pairs_assembly_reaches_every_segment_with_the_limit_on() -> None:
    """The shipped assembly on ur5_pair, the collision limit on, its peg and hole as geometry (issue 40
    item 2; before, the limit held the bare wrists 2.67 cm short): every segment reached, each one's
    verdict in the run's keys, the final error under 1 mm (1.3e-7 m measured)."""
    from dualarm_control.app.record.report import summarize_run
    from dualarm_control.app.run.experiment import run_scenario
    from dualarm_control.controller_params import controller_params

    scenario = load_scenario("assembly", "ur5_pair")
    model = DualArmModel(scenario.robot)
    summary = summarize_run(run_scenario(scenario, controller_params({"solver": "sparse_qp"}), model), scenario, model)
    assert (summary["segments_reached"], summary["segments_stalled"]) == (3, 0), summary["segment_outcomes"]
    assert summary["final_position_error_m"] < 1e-3, summary["final_position_error_m"]
    assert summary["joint_position_limit_violations"] == 0


BEHIND = str(Path(__file__).parent / "data" / "behind_the_arm.yaml")


def test_a_target_behind_the_other_arm_is_named_in_process_over_ros_and_in_the_bag(tmp_path: Path) -> None:
    """Issue 40: one segment that drives the peg through the hole arm (test/data/behind_the_arm.yaml). In one
    process, metrics.json names the stall; in lockstep over ROS the trajectory node says it in the launch's
    output and as a WARN on /diagnostics, and the bag's report names it as the in-process run does (the same
    error to the printed 0.01 mm)."""
    from test_ros_live import Launch, dualarm

    from dualarm_control.app.record.bag import read_bag

    inproc = tmp_path / "inproc"
    assert main_cli(["experiment", BEHIND, "--solver", "sparse_qp", "--output", str(inproc)]) == 0
    record = json.loads((inproc / "metrics.json").read_text())["sparse_qp"]
    assert (record["segments_reached"], record["segments_stalled"]) == (0, 1)
    stall = str(record["segment_outcomes"])
    assert ": stalled: collision constraint: " in stall and "remaining error " in stall, stall
    bag = tmp_path / "bag"
    launch = Launch(BEHIND, "--lockstep", "--solver", "sparse_qp", "--record", str(bag))
    try:
        assert launch.finish(timeout=300) == 0, "\n".join(launch.lines[-30:])
    finally:
        launch.kill()
    said = [line for line in launch.lines if "[trajectory_node] [WARN]" in line and "segment 1 'through'" in line]
    assert said and ": stalled: collision constraint: " in said[0], "\n".join(launch.lines[-30:])
    statuses = [s for s in read_bag(bag).statuses if s.name == "trajectory_node" and "(t = " in s.message]
    assert [s.level for s in statuses] == [1] and ": stalled: collision constraint: " in statuses[0].message
    report = dualarm("report", str(bag), "--output", str(tmp_path / "report"), timeout=300)
    assert report.returncode == 0, report.stderr[-2000:]
    from_bag = json.loads((tmp_path / "report" / "metrics.json").read_text())["sparse_qp"]
    assert from_bag["segments_stalled"] == 1
    left = [str(r["segment_outcomes"]).split("remaining error ")[1].split(" mm")[0] for r in (record, from_bag)]
    assert left[0] == left[1], left


def test_a_record_with_a_state_fewer_than_its_commands_still_gets_its_verdicts() -> None:
    """A bag's record may hold one state fewer (or more) than commands on a loaded machine (Baxter under
    stress-ng: the report crashed on the lengths); the verdicts are then judged on the paired cycles."""
    from dataclasses import replace

    from dualarm_control.app.record.report import summarize_run
    from dualarm_control.app.run.experiment import run_scenario
    from dualarm_control.controller_params import controller_params

    scenario = load_scenario(str(Path(__file__).parent / "data" / "short.yaml"))
    model = DualArmModel(scenario.robot)
    record = run_scenario(scenario, controller_params({"solver": "sparse_qp"}), model)
    full = summarize_run(record, scenario, model)
    short = summarize_run(replace(record, positions=record.positions[:-3]), scenario, model)
    assert full["segment_outcomes"] == short["segment_outcomes"] and full["segments_reached"] == 1
