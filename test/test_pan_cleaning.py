"""Pan-cleaning task of paper 001: scenario, force feedback parts, short closed-loop runs, the CLI."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from dualarm_control.app.cli import main
from dualarm_control.app.record.report import summarize_run
from dualarm_control.app.run.experiment import run_scenario
from dualarm_control.controller_params import controller_params
from dualarm_control.errors import ScenarioError
from dualarm_control.force import (
    ForceParams,
    ForcePI,
    ForceSensorModel,
    contact_normal_force,
)
from dualarm_control.params import read_params_file
from dualarm_control.paths import config_path
from dualarm_control.scenario import load_scenario, scenario_from_parameters

# no ROS node, no wall-clock verdict: make test runs it at idle CPU priority beside the parallel tests (docs/testing.md)
pytestmark = pytest.mark.background


@pytest.fixture(scope="module")
def scenario():
    return load_scenario("pan_cleaning")


@pytest.fixture(scope="module")
def params():
    return controller_params({"solver": "constraint_based"})


def test_scenario_has_the_papers_tasks_and_cell(scenario) -> None:
    spec = scenario.tasks
    assert spec is not None and scenario.robot.name == "lwr4_pan_cell" and scenario.reference.kind == "tasks"
    assert scenario.urdf_path.name == "dualarm_cell_pan.urdf"
    assert [t.type for t in spec.tasks] == ["circle", "cone", "singularity", "singularity", "table", "table"]
    assert spec.gains == (1.0, 0.5, 0.2) and spec.table_height == pytest.approx(0.4)
    assert [t.gain for t in spec.build(0.5)] == [0.5] * 6


def test_bad_task_parameters_name_the_key() -> None:
    path = config_path("scenarios", "pan_cleaning.yaml")
    flat = read_params_file(path, "trajectory_node")
    with pytest.raises(ScenarioError, match="scenario.cone.type"):
        scenario_from_parameters({**flat, "scenario.cone.type": "spiral"}, path)
    with pytest.raises(ScenarioError, match="singularity_left.*b_5"):
        scenario_from_parameters({**flat, "scenario.singularity_left.bound": 0.1}, path)
    with pytest.raises(ScenarioError, match="force parameters: unknown"):
        scenario_from_parameters({**flat, "scenario.force.stiffness": 1.0}, path)
    typo = scenario_from_parameters({**flat, "scenario.cone.pan_frame": "left_tol"}, path)
    with pytest.raises(ScenarioError, match="cone.*unknown frame 'left_tol'"):
        run_scenario(typo, controller_params({"solver": "constraint_based"}), gain=1.0, duration=0.1)


def test_force_pi_integrates_and_saturates() -> None:
    pi = ForcePI(ForceParams(kp=0.001, ki=0.01, max_offset=0.02))
    assert pi.step(0.0, 0.1) == pytest.approx(0.001 * 5 + 0.01 * 5 * 0.1)
    for _ in range(1000):
        out = pi.step(0.0, 0.1)
    assert out == pytest.approx(0.02) and pi.integral == pytest.approx(0.02)
    assert pi.step(5.0, 0.1) == pytest.approx(0.02)  # at the set point: integral held


def test_sensor_model_is_seeded_and_low_pass() -> None:
    fp = ForceParams(noise_std=0.3, cutoff_hz=15.0, seed=3)
    a, b = ForceSensorModel(fp, 0.005), ForceSensorModel(fp, 0.005)
    xs = np.array([a.filter(np.zeros(6)) for _ in range(4000)])
    ys = np.array([b.filter(np.zeros(6)) for _ in range(4000)])
    np.testing.assert_array_equal(xs, ys)
    alpha = 1 - math.exp(-2 * math.pi * 15.0 * 0.005)
    expected = 0.3 * math.sqrt(alpha / (2 - alpha))  # stationary std of the first-order filter
    assert np.std(xs[100:, :3]) == pytest.approx(expected, rel=0.1)


def test_contact_normal_force_removes_the_tool_weight() -> None:
    """Tool pointing down (R_2 = diag(1, -1, -1)), pan normal up, 5 N contact, 0.1 kg brush."""
    r2 = np.diag([1.0, -1.0, -1.0])
    contact, weight = np.array([0, 0, 5.0]), np.array([0, 0, -0.981])
    reading = np.concatenate((r2.T @ -(contact + weight), np.zeros(3)))  # flange on tool, tool frame
    assert contact_normal_force(reading, r2, np.array([0, 0, 1.0]), 0.1) == pytest.approx(5.0)


def test_circle_converges_below_1_mm_and_no_inequality_is_violated(scenario, params) -> None:
    """k = 1, 8 s: RMS circle error after 5 s < 0.25 mm (measured 0.145 mm, 0.250 mm before the simulator held its
    integrated command; docs/constraint_based.md: 0.072 mm over the 25 s run; the done-when bound was 1 mm);
    f_i <= b_i every cycle; the table is never touched."""
    log = run_scenario(scenario, params, gain=1.0, duration=8.0)
    metrics = summarize_run(log, scenario)
    assert metrics["circle_rms_error_m"] < 0.25e-3
    assert metrics["max_inequality_violation"] <= 1e-4
    assert metrics["table_contacts"] == 0 and metrics["min_table_distance_m"] > 0.05
    assert metrics["solver_failures"] == 0


def test_larger_gain_converges_faster(scenario, params) -> None:
    """The paper's ordering (Fig. 4-5): ||f_1-3|| at 2.5 s is smaller for larger k."""
    errors = []
    for gain in (1.0, 0.5, 0.2):
        log = run_scenario(scenario, params, gain=gain, duration=2.5)
        errors.append(float(np.linalg.norm(log.tasks.values["circle"][-1])))
    assert errors[0] < errors[1] < errors[2]
    for gain, error in zip((1.0, 0.5, 0.2), errors, strict=True):  # close to exp(-k t) of the 5 cm start error
        assert error == pytest.approx(0.05 * math.exp(-gain * 2.5), rel=0.15)


def test_force_feedback_keeps_contact_at_the_set_point(scenario, params) -> None:
    """eq (9) with a 1 cm pan modelling error, 8 s: first touch before 3 s (measured 1.625 s), contact kept
    after it, force RMS error after 5 s < 0.09 N (measured 0.0734 N; docs/constraint_based.md: 0.048 N over
    the 25 s run)."""
    log = run_scenario(scenario, params, gain=scenario.tasks.force.gain, force=True, duration=8.0)
    metrics = summarize_run(log, scenario)
    assert metrics["first_contact_s"] < 3.0
    assert metrics["contact_lost_cycles"] == 0
    assert metrics["force_rms_error_n"] < 0.09
    assert metrics["max_inequality_violation"] <= 1e-4


def test_without_feedback_the_modelling_error_leaves_the_brush_above_the_pan(params) -> None:
    """The control case of the force test: ki = 0, the brush circles 1 cm above the real pan."""
    scenario = variant(**{"force.ki": 0.0})
    log = run_scenario(scenario, params, gain=scenario.tasks.force.gain, force=True, duration=4.0)
    assert log.contact_force.max() == 0.0
    assert log.tasks.tip_in_pan[-1, 2] == pytest.approx(scenario.tasks.force.model_error, abs=1e-3)


def test_cli_writes_metrics_and_figures(tmp_path: Path) -> None:
    out = tmp_path / "pan"
    assert main(["experiment", "pan_cleaning", "--gains", "1", "--duration", "6", "--output", str(out)]) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    for key in ("circle_rms_error_m", "max_inequality_violation", "min_table_distance_m", "min_singularity_margin",
                "cycle_time_p50_s", "cycle_time_p99_s"):
        assert key in metrics["k=1"]
    for name in ("tool_path.png", "task_values.png", "joint_velocities.png"):
        assert (out / name).stat().st_size > 1000
    assert main(["experiment", "assembly", "--force", "--output", str(out)]) == 2  # task options only
    assert main(["experiment", "pan_cleaning", "--solver", "standard_qp", "--output", str(out)]) == 2


def test_a_tasks_source_has_no_relative_trajectory(scenario) -> None:
    with pytest.raises(ScenarioError, match="task scenario"):
        scenario.trajectory(np.zeros(3), np.eye(3))


def variant(**changes: float):
    """pan_cleaning with some scenario keys changed (flattened names without 'scenario.')."""
    path = config_path("scenarios", "pan_cleaning.yaml")
    flat = read_params_file(path, "trajectory_node")
    return scenario_from_parameters({**flat, **{f"scenario.{k}": v for k, v in changes.items()}}, path)


def test_an_active_inequality_is_kept_while_the_circle_is_tracked(params) -> None:
    """A 5 deg cone: the brush tilts more than that on the plain run, so f_4 reaches its bound and
    stays on it (bound margin, eq 5) while the circle is still tracked: 8 s, on the bound in 30.7 % of
    the cycles (asserted > 16 %), circle RMS after 5 s 0.146 mm (asserted < 0.25 mm)."""
    scenario = variant(**{"cone.max_angle_deg": 5.0})
    log = run_scenario(scenario, params, gain=1.0, duration=8.0)
    margin = log.tasks.values["cone"][:, 0] - log.tasks.bounds["cone"][0]
    assert np.mean(margin > -1e-4) > 0.16  # active for a part of the run
    assert margin.max() <= 1e-4
    assert summarize_run(log, scenario)["circle_rms_error_m"] < 0.25e-3


def test_a_violated_inequality_decays_at_least_exponentially(params) -> None:
    """Table clearance 0.15 m demanded of the left arm, 0.148 m at the start: f_6 - b_6 > 0 decays no
    slower than exp(-k t), and is satisfied from 0.6 s on (measured: from 0.33 s)."""
    scenario = variant(**{"table_left.bound": -0.15})
    log = run_scenario(scenario, params, gain=1.0, duration=4.0)
    excess = (log.tasks.values["table_left"] - log.tasks.bounds["table_left"]).max(axis=1)
    assert excess[0] > 1e-3
    assert np.all(excess <= excess[0] * np.exp(-1.0 * log.time) + 1e-4)
    assert excess[int(0.6 / log.period):].max() <= 0.0


def test_task_controller_holds_the_force_loop_on_a_bad_reading(scenario, params) -> None:
    """The per-cycle object a node would use: a NaN wrench keeps the previous offset, no wrench is refused."""
    from dualarm_control.kinematics import DualArmModel
    from dualarm_control.references.tasks import TasksController

    model = DualArmModel(scenario.robot)
    control = TasksController(model, params, scenario.tasks, 2.0, force=True)
    q = scenario.initial_positions
    tool = model.frame_poses(q, ("right_tool",))[0]
    at_rest = np.concatenate((tool.rotation.T @ np.array([0.0, 0.0, 0.1 * 9.81]), np.zeros(3)))  # holds the weight
    first = control.step(q, 0.0, at_rest)
    assert abs(first.measured_force) < 1.0  # weight removed; noise 0.3 N
    assert first.normal_offset > 0  # below the set point: move toward the pan
    held = control.step(q, 0.005, np.full(6, np.nan))
    assert math.isnan(held.measured_force) and held.normal_offset == first.normal_offset
    assert held.result.status == "solved"
    with pytest.raises(ValueError, match="F/T reading"):
        control.step(q, 0.01)
