"""A user's own limit and task, from a file outside the package (test/data/plugins/keep_above.py), bind in
every solver and every tracker: the relative pose step, a task set, a plan's joint tracking (issue 39;
docs/limits.md). Each check runs once without the limit, to show that the motion would break it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from test_properties import Target

from dualarm_control.controller import ControllerParams, RelativeController
from dualarm_control.controller_params import controller_params
from dualarm_control.errors import ParameterError, ScenarioError
from dualarm_control.kinematics import Configuration, DualArmModel
from dualarm_control.scenario import load_scenario
from dualarm_control.solvers import solver_names
from dualarm_control.tasks import task_types

# no ROS node, no wall-clock verdict: make test runs it at idle CPU priority beside the parallel tests (docs/testing.md)
pytestmark = pytest.mark.background

DATA = Path(__file__).parent / "data"
PLUGIN = DATA / "plugins" / "keep_above.py"
PERIOD = 0.005



@pytest.fixture(scope="module")
def model() -> DualArmModel:
    return DualArmModel("lwr4_cell")


def controller(model: DualArmModel, solver: str, limits: tuple[str, ...]) -> RelativeController:
    return RelativeController(model, ControllerParams(solver=solver, limits=limits, plugins=(str(PLUGIN),)))


def floor_and_cap() -> tuple[float, float]:
    RelativeController(DualArmModel("lwr4_cell"), ControllerParams(plugins=(str(PLUGIN),)))  # registers
    from dualarm_control.plugins import load_plugin

    module = load_plugin(str(PLUGIN))
    return module.FLOOR, module.CAP


@pytest.mark.parametrize("solver", solver_names())
def test_a_user_limit_binds_in_the_relative_pose_step(model: DualArmModel, solver: str) -> None:
    """A relative target 0.2 m away asks for more than 0.3 rad/s of some joint (gain 10): the user's box caps
    every joint at 0.3 rad/s in every solver; without it the step goes faster."""
    _, cap = floor_and_cap()
    q0 = np.asarray(model.description.ready, dtype=float)
    state = Configuration(model, q0).relative()
    zero = np.zeros(3)
    target = Target(state.position + np.array([0.0, 0.2, 0.0]), state.rotation, zero, zero)
    peaks = {}
    for limits in ((), ("joint_speed_cap",)):
        ctrl, q, peak = controller(model, solver, limits), q0.copy(), 0.0
        for _ in range(100):
            cycle = ctrl.step(q, target)
            peak = max(peak, float(np.abs(cycle.velocities).max()))
            q = q + PERIOD * cycle.velocities
        peaks[limits] = peak
    assert peaks[()] > 1.5 * cap, peaks  # the motion would break the cap
    assert peaks[("joint_speed_cap",)] <= cap + 1e-9, peaks
    assert peaks[("joint_speed_cap",)] >= cap - 1e-6, peaks  # and it binds


@pytest.mark.parametrize("solver", solver_names())
def test_a_user_task_and_limit_bind_in_a_task_set(model: DualArmModel, solver: str) -> None:
    """The scenario test/data/tool_height.yaml names the user's task type (its plugins key): the left tool goes
    down to 1.05 m; with the user's row limit keep_above it stops at 1.25 m (within 1 mm)."""
    floor, _ = floor_and_cap()
    scenario = load_scenario(str(DATA / "tool_height.yaml"))
    lowest = {}
    for limits in ((), ("keep_above",)):
        ctrl = controller(model, solver, limits)
        tasks = scenario.reference.build(2.0)
        q = scenario.initial_positions.copy()
        low = np.inf
        for k in range(600):
            cycle = ctrl.solve_tasks(q, tasks, k * PERIOD)
            q = q + PERIOD * cycle.velocities
            low = min(low, float(Configuration(model, q).frame("left_tool").position[2]))
        lowest[limits] = low
    assert lowest[()] < floor - 0.1, lowest
    assert floor - 1e-3 <= lowest[("keep_above",)] <= floor + 0.01, lowest


@pytest.mark.parametrize("limits", [("keep_above",), ("joint_speed_cap",), ("joint_speed_cap", "keep_above")])
def test_user_limits_bind_in_a_plans_joint_tracking(model: DualArmModel, limits: tuple[str, ...]) -> None:
    """A joint reference that lowers the left tool at 0.5 m/s: the plan's tracker keeps the user's floor and
    speed cap (each, and both listed in either order of priority)."""
    floor, cap = floor_and_cap()
    q0 = np.asarray(model.description.ready, dtype=float)
    jz = Configuration(model, q0).frame("left_tool").jacobian[2]
    down = -0.5 * jz / (jz @ jz)  # rad/s: d z / dt = -0.5 m/s at q0
    target = Target(np.zeros(3), np.eye(3), np.zeros(3), np.zeros(3))
    runs = {}
    for chosen in ((), limits):
        ctrl, q = controller(model, "hierarchical_sparse_qp", chosen), q0.copy()
        low, peak = np.inf, 0.0
        for k in range(400):
            cycle = ctrl.track_joints(q, q0 + down * (k * PERIOD), down, target, 10.0)
            q = q + PERIOD * cycle.velocities
            low = min(low, float(Configuration(model, q).frame("left_tool").position[2]))
            peak = max(peak, float(np.abs(cycle.velocities).max()))
        runs[chosen] = (low, peak)
    free_low, free_peak = runs[()]
    low, peak = runs[limits]
    if "keep_above" in limits:
        assert free_low < floor - 0.05 and low >= floor - 1e-3, runs
    if "joint_speed_cap" in limits:
        assert free_peak > 1.2 * cap and peak <= cap + 1e-9, runs


def test_the_limits_parameter_names_user_limits_and_refuses_unknown_ones(model: DualArmModel) -> None:
    params = controller_params({"limits": ["keep_above", ""], "plugins": [str(PLUGIN)]})
    assert params.limits == ("keep_above",)
    names = [limit.name for limit in RelativeController(model, params).constraints]
    assert names == ["joint_velocity", "collision", "keep_above"]
    with pytest.raises(ParameterError, match=r"'limits': got 'keep_below'.*registered limit: .*keep_above"):
        RelativeController(model, ControllerParams(limits=("keep_below",), plugins=(str(PLUGIN),)))
    with pytest.raises(ParameterError, match=r"'plugins': got '/nowhere/mine.py'"):
        RelativeController(model, ControllerParams(plugins=("/nowhere/mine.py",)))


def test_an_unknown_task_type_is_refused_naming_the_registered_ones(tmp_path: Path) -> None:
    text = (DATA / "tool_height.yaml").read_text().replace("type: tool_height", "type: tool_hight")
    text = text.replace("plugins/keep_above.py", str(PLUGIN))
    path = tmp_path / "typo.yaml"
    path.write_text(text)
    with pytest.raises(ScenarioError, match=r"scenario\.lower\.type.*'tool_hight'.*circle, cone, .*tool_height"):
        load_scenario(str(path))
    assert {"circle", "cone", "singularity", "table", "tool_height"} <= set(task_types())


def test_a_broken_plugin_is_named_with_its_error(tmp_path: Path, model: DualArmModel) -> None:
    bad = tmp_path / "broken.py"
    bad.write_text("raise RuntimeError('no licence')\n")
    with pytest.raises(ParameterError, match=r"broken\.py.*RuntimeError: no licence"):
        RelativeController(model, ControllerParams(plugins=(str(bad),)))


def test_a_task_held_by_a_limit_is_reported_stalled(model: DualArmModel) -> None:
    """Issue 40: a task's stall said out loud. The tool_height scenario in the simulated cell (the one runner of
    `dualarm experiment`): reached without the user's floor; with it, stalled 0.200 m short."""
    from dualarm_control.app.record.report import summarize_run
    from dualarm_control.app.run.experiment import run_scenario

    scenario = load_scenario(str(DATA / "tool_height.yaml"))
    free = summarize_run(run_scenario(scenario, ControllerParams(solver="constraint_based"), model), scenario, model)
    assert (free["tasks_reached"], free["tasks_stalled"]) == (1, 0), free["task_outcomes"]
    params = ControllerParams(solver="constraint_based", limits=("keep_above",), plugins=(str(PLUGIN),))
    held = summarize_run(run_scenario(scenario, params, model), scenario, model)
    assert (held["tasks_reached"], held["tasks_stalled"]) == (0, 1), held["task_outcomes"]
    assert "task 'lower' (t = 4 s): stalled: |f - b| = 0.2 (tolerance 0.001)" in str(held["task_outcomes"])
