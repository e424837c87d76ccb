"""The scenario `carry` over ROS (issue 41, item 5; docs/cooperative.md "The scenario `carry`"): sim_node's box on
its support, grasped and released on the simulator's clock, controller_node's internal-force control, recorded.

Lockstep: `dualarm launch carry --lockstep --force --record BAG` then `dualarm report BAG` give the in-process
experiment's metrics (the issue asks 1e-6; measured: equal to the last bit, the wall-clock cycle times aside). The
default run compares the short variant (test_carry.short_carry, 1280 cycles); the full carry is ``slow``, and so is
the real-time run, which is judged on completing only (a real-time force bound flaked under load before).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from launching import meanwhile
from metrics_match import assert_same_metrics
from test_carry import PARAMS, _params, short_carry

from dualarm_control.app.record.bag_runs import read_run
from dualarm_control.app.record.report import summarize_run
from dualarm_control.app.run.experiment import run_scenario
from dualarm_control.app.run.launcher import launch_scenario
from dualarm_control.scenario import load_scenario


def _same_metrics(scenario_name: str, tmp_path: Path) -> dict[str, Any]:
    """Launch ``scenario_name`` in lockstep with the control on, recorded, while the same runs in one process;
    assert every metric of the bag's report equals the in-process one to 1e-6 (relative; NaN as NaN)."""
    bag = tmp_path / "bag"

    def in_process() -> dict[str, Any]:
        scenario = load_scenario(scenario_name)
        return summarize_run(run_scenario(scenario, _params(), force=True), scenario)

    code, expected = meanwhile(
        lambda: launch_scenario(scenario_name, [PARAMS], [], True, bag, timeout=300.0, force=True), in_process)
    assert code == 0
    (log,), scenario = read_run(bag)
    assert scenario is not None and log.internal_wrench is not None
    from_bag = summarize_run(log, scenario)
    assert_same_metrics(from_bag, expected, rel_tol=1e-6)
    return from_bag


def test_lockstep_short_carry_bag_metrics_equal_in_process(tmp_path: Path) -> None:
    """The short carry over ROS in lockstep: the bag's report equals the experiment's (path error, internal
    wrench, slip-free grasp, payload, closest pair, verdicts)."""
    metrics = _same_metrics(str(short_carry(tmp_path)), tmp_path)
    assert float(metrics["internal_force_settled_max_n"]) < 5.0 and float(metrics["path_error_max_m"]) < 5e-3
    assert math.isfinite(float(metrics["slip_left_max_m"])), "the bag's /held_object/pose gives the slip"
    # what `dualarm view BAG` draws: the box where the simulator had it (off the hands before the grasp, at the
    # grasp while held), the wrist forces as arrows; the video's box where the simulator had it
    from dualarm_control.app.view.from_bag import bag_run_arrays

    bag = tmp_path / "bag"
    arrays = bag_run_arrays(bag)
    box = arrays.frames["held_object"]
    held = round(3.0 / 0.005)  # t = 3 s: held, still
    assert np.linalg.norm(box[0, :3] - (0.0, 0.0, 0.15)) > 0.03, box[0]  # the hands start away from it
    np.testing.assert_allclose(box[held, :3], (0.0, 0.0, 0.15), atol=1e-3)
    assert arrays.held is not None and np.isfinite(arrays.held.forces["left_tool"][held]).all()
    from dualarm_control.app.view.video import box_poses, render_video

    poses = box_poses(bag)
    info = render_video(bag, tmp_path / "carry.mp4", fps=2.0, size=(160, 120), log=None)
    assert info.frames >= 10 and (tmp_path / "carry.mp4").stat().st_size > 1000
    start = poses[min(poses)]
    np.testing.assert_allclose(start[:3], (0.675, 0.0, 0.145), atol=2e-3)  # on its support
    import pybullet as p

    from dualarm_control.app.view.recording import read_joint_recording
    from dualarm_control.app.view.video import CellCamera, held_box

    recording = read_joint_recording(bag)
    camera = CellCamera(recording.urdf_text, (160, 120), recording.joint_names, None, held_box(bag), poses)
    try:  # the video's box at the first frame: on its support, where the simulator had it
        camera.render(recording.positions[0], int(recording.stamps_ns[0]))
        drawn = p.getBasePositionAndOrientation(camera._box, physicsClientId=camera.cell.client_id)
    finally:
        camera.close()
    np.testing.assert_allclose(drawn[0], start[:3], atol=1e-9)


@pytest.mark.slow
def test_lockstep_carry_bag_metrics_equal_in_process(tmp_path: Path) -> None:
    """The full carry (2960 cycles) over ROS in lockstep: the same metrics as in one process."""
    metrics = _same_metrics("carry", tmp_path)
    assert metrics["tasks_reached"] == 2, metrics["task_outcomes"]


@pytest.mark.slow
@pytest.mark.realtime
def test_realtime_carry_runs_to_completion(tmp_path: Path) -> None:
    """`dualarm launch carry --force --record BAG` in real time at 200 Hz: it runs to completion, recorded, and the
    report reads it (no force bound on the wall-clock run: its squeeze depends on the machine's timing)."""
    bag = tmp_path / "bag"
    assert launch_scenario("carry", [PARAMS], [], False, bag, timeout=120.0, force=True) == 0
    (log,), scenario = read_run(bag)
    assert scenario is not None and log.internal_wrench is not None
    metrics = summarize_run(log, scenario)
    assert scenario.tasks is not None
    assert len(log.time) >= round(scenario.tasks.duration / log.period) - 20, len(log.time)  # recorder's start
    assert math.isfinite(float(metrics["path_error_max_m"])), metrics
