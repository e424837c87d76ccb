"""The scenario `carry` in one process (issue 41, item 5; docs/cooperative.md "The scenario `carry`"): Baxter's hands
close on a box resting on a support, lift it, carry it along a path of the absolute frame turning it, set it down,
let go and retreat; internal-force control on (``--force``) or off.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from dualarm_control.app.record.hold_metrics import plot_internal_wrench
from dualarm_control.app.record.report import summarize_run
from dualarm_control.app.record.run_record import RunRecord
from dualarm_control.app.run.experiment import run_scenario
from dualarm_control.controller_params import controller_params
from dualarm_control.errors import ScenarioError
from dualarm_control.params import read_params_files
from dualarm_control.references.base import RunOptions
from dualarm_control.scenario import Scenario, load_scenario, scenario_file
from dualarm_sim.cell import DualArmCell
from dualarm_sim.cell_config import CellConfig

# no ROS node, no wall-clock verdict: make test runs it at idle CPU priority beside the parallel tests (docs/testing.md)
pytestmark = pytest.mark.background

PARAMS = str(Path(__file__).parents[1] / "config" / "solvers" / "constraint_based.yaml")


def _params() -> Any:
    return controller_params({**read_params_files([PARAMS], "controller_node"), "solver": "constraint_based"})


def variant(tmp_path: Path, name: str = "carry", **changes: Any) -> Path:
    """The scenario file ``name`` with ``changes`` (dotted keys under ``scenario``; None deletes) at tmp_path."""
    data = yaml.safe_load(scenario_file(name).read_text())
    scenario = data["/**"]["ros__parameters"]["scenario"]
    for key, value in changes.items():
        *parents, leaf = key.split(".")
        node = scenario
        for part in parents:
            node = node[part]
        if value is None:
            node.pop(leaf)
        else:
            node[leaf] = value
    path = tmp_path / f"{name}_variant.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def short_carry(tmp_path: Path) -> Path:
    """``carry`` shortened for the default run: a 3 cm lift turning 10 deg and back down, released at 5.0 s
    (1280 cycles instead of 2960)."""
    return variant(tmp_path, absolute_segments=["lift", "set_down"],
                   **{"lift.position": [0.675, 0.0, 0.175], "lift.rpy_deg": [90.0, 0.0, 10.0],
                      "set_down.position": [0.675, 0.0, 0.146], "set_down.rpy_deg": [90.0, 0.0, 10.0],
                      "held_object.release_time": 5.0, "duration": 6.4})


_RUNS: dict[str, tuple[RunRecord, dict[str, Any], Scenario]] = {}


def _carried(name: str) -> tuple[RunRecord, dict[str, Any], Scenario]:
    """The full carry ``name`` with the control on, run once per module."""
    if name not in _RUNS:
        scenario = load_scenario(name)
        record = run_scenario(scenario, _params(), force=True)
        _RUNS[name] = (record, summarize_run(record, scenario), scenario)
    return _RUNS[name]


@pytest.fixture(scope="module")
def carried() -> tuple[RunRecord, dict[str, Any], Scenario]:
    return _carried("carry")


@pytest.mark.parametrize("name", ["carry", "carry_lwr4"])
def test_carry_with_internal_force_control(name: str) -> None:
    """The full carry with the control on, on Baxter and on the LWR4 cell: the internal force within 5 N and the
    torque within 0.5 N m of the setpoint once settled, the path error < 5 mm, no joint limit violated, the box
    clear of everything it is not put on, the payload identified while it hangs still above the support, both tasks
    at the plan's end, the box neither slipping in the hands nor moving once put down (measured on Baxter: 1.25 N,
    0.042 N m, 0.150 mm, 74.4 mm, 1.999 kg; on the LWR4 cell: 1.46 N, 0.058 N m, 0.136 mm, 56.5 mm, 1.998 kg)."""
    record, metrics, _ = _carried(name)
    assert metrics["solver_failures"] == 0, metrics
    assert float(metrics["internal_force_settled_max_n"]) < 5.0, metrics
    assert float(metrics["internal_torque_settled_max_nm"]) < 0.5, metrics
    assert float(metrics["path_error_max_m"]) < 5e-3 and float(metrics["path_error_max_rad"]) < 5e-3, metrics
    assert metrics["held_joint_limit_violations"] == 0
    assert float(metrics["held_collision_min_distance_m"]) > 0.03, metrics
    assert abs(float(metrics["identified_mass_kg"]) - 2.0) < 0.05, metrics
    assert metrics["tasks_reached"] == 2, metrics["task_outcomes"]
    assert record.internal_wrench is not None
    # the simulator's box in each hand: no slip (measured on Baxter 0.019 mm; LWR4 0.099 mm); after the release it
    # drops the 1 mm it was set down above the support and stays there (measured 1.002 mm)
    assert max(float(metrics["slip_left_max_m"]), float(metrics["slip_right_max_m"])) < 0.5e-3, metrics
    assert float(metrics["slip_max_rad"]) < 5e-3, metrics
    assert 0.5e-3 < float(metrics["placed_box_moved_m"]) < 2e-3, metrics


def test_the_path_turns_the_box_and_the_hands_let_go(carried: tuple[RunRecord, dict[str, Any], Scenario]) -> None:
    """What the arms did: the box's frame rose 10 cm, came 15 cm towards the torso turned 20 deg about the world
    z axis, went back down; after the release the tools are 6 cm further apart and the wrist sensors feel no box."""
    from dualarm_control.kinematics import Configuration, DualArmModel
    from dualarm_control.tasks import AbsolutePoseTask

    record, _, scenario = carried
    model = DualArmModel(scenario.robot)
    spec = scenario.tasks
    assert spec is not None and spec.held is not None
    task = next(t for t in spec.build(2.0) if isinstance(t, AbsolutePoseTask))

    def pose(t: float) -> tuple[np.ndarray, np.ndarray]:
        state = task.state(Configuration(model, record.positions[round(t / record.period)]))
        return state.position, state.rotation

    start, top, placed = pose(2.3), pose(4.3), pose(12.4)
    assert abs(top[0][2] - start[0][2] - 0.10) < 2e-3, top[0] - start[0]
    np.testing.assert_allclose(placed[0] - start[0], (-0.15, 0.0, 0.001), atol=2e-3)
    turn = np.degrees(np.arctan2(*(placed[1] @ start[1].T)[[1, 0], 0]))
    assert abs(turn - 20.0) < 0.5, turn
    gap = [float(np.linalg.norm(model.relative_pose(record.positions[k])[0])) for k in (2400, len(record.time) - 1)]
    assert abs(gap[0] - 0.30) < 1e-3 and abs(gap[1] - 0.36) < 2e-3, gap
    assert record.internal_wrench is not None and np.abs(record.internal_wrench[-1, :3]).max() < 2.0


@pytest.mark.slow
@pytest.mark.parametrize("name", ["carry", "carry_lwr4"])
def test_carry_without_control_squeezes_the_box(name: str) -> None:
    """The same carry with the control off (reported beside it in docs/cooperative.md): the rigid grasp squeezes
    the box (measured 145.2 N on Baxter)."""
    scenario = load_scenario(name)
    metrics = summarize_run(run_scenario(scenario, _params(), force=False), scenario)
    assert float(metrics["internal_force_max_n"]) > 50.0, metrics
    assert float(metrics["path_error_max_m"]) < 5e-3, metrics


@pytest.mark.slow
@pytest.mark.parametrize("name", ["carry", "carry_lwr4"])
def test_carry_of_a_5_kg_box(tmp_path: Path, name: str) -> None:
    """The same carries with a 5 kg box, control on: the same bounds (measured on Baxter 1.38 N, 0.067 N m; on the
    LWR4 cell 1.66 N, 0.090 N m); the payload identified as 5 kg. (With hold_box's force_gain 1e-2 the squeeze ran
    away at the end of the lift, 6 -> 153 N in 0.3 s, and the wrench limit stopped Baxter's carry.)"""
    scenario = load_scenario(str(variant(tmp_path, name, **{"held_object.mass": 5.0})))
    metrics = summarize_run(run_scenario(scenario, _params(), force=True), scenario)
    assert metrics["solver_failures"] == 0, metrics
    assert float(metrics["internal_force_settled_max_n"]) < 5.0, metrics
    assert float(metrics["internal_torque_settled_max_nm"]) < 0.5, metrics
    assert float(metrics["path_error_max_m"]) < 5e-3, metrics
    assert abs(float(metrics["identified_mass_kg"]) - 5.0) < 0.05, metrics


def test_box_rests_is_grasped_then_released_where_it_is() -> None:
    """The simulator's side: the box rests on the support (no fixture), the hands close at grasp_time, open at
    release_time, and the box stays where it was (arms still)."""
    scenario = load_scenario("carry")
    source = scenario.reference
    cell_options = source.cell(RunOptions(scenario.limits, 1.0, None, True))
    held = cell_options["held_object"]
    import dataclasses

    cell_options["held_object"] = dataclasses.replace(held, grasp_time=0.1, release_time=0.3)
    config = CellConfig.for_robot(scenario.robot, allowed=scenario.robot_pairs_allowed, control_period=0.005,
                                  obstacles=scenario.obstacles, **cell_options)
    with DualArmCell(config, initial_positions=scenario.initial_positions) as cell:
        box = cell.held_object
        assert box is not None and box.waiting and not box.grasped
        start = box.object_matrix()
        seen = []
        for _ in range(100):
            cell.apply_command(np.zeros(14))
            cell.step()
            seen.append((box.grasped, box.released))
        assert (True, False) in seen and seen[-1] == (False, True), seen[::10]
        end = box.object_matrix()
    np.testing.assert_allclose(end[:3, 3], start[:3, 3], atol=1e-3)
    np.testing.assert_allclose(end[:3, :3], start[:3, :3], atol=1e-3)


@pytest.mark.parametrize(("changes", "expected"), [
    ({"phases.close_time": 1.9}, "phases.close_time': got 1.9"),
    ({"held_object.release_time": 6.0}, "held_object.release_time': got 6.0 s, but the path ends"),
    ({"held_object.release_time": None}, "a carry sets the box down and releases it"),
    ({"phases.retract": 0.1}, "scenario.phases.retract': unknown"),
    ({"absolute_segments": None}, "need the path, 'scenario.absolute_segments'"),
])
def test_bad_carry_values_are_named(tmp_path: Path, changes: dict[str, Any], expected: str) -> None:
    """A close that runs into the bias's still step, a release before the path's end (or none), an unknown phase
    key, phases without a path: refused when the run starts, naming the key and the value."""
    with pytest.raises(ScenarioError, match=expected.replace("(", r"\(").replace(".", r"\.")):
        scenario = load_scenario(str(variant(tmp_path, **changes)))
        scenario.reference.tracker(*_model_params(scenario), RunOptions(scenario.limits, 1.0, None, True))


def _model_params(scenario: Scenario) -> tuple[Any, Any]:
    from dualarm_control.kinematics import DualArmModel

    return DualArmModel(scenario.robot), scenario.controller_params(_params())


def test_short_carry_draws_the_internal_force_over_time(tmp_path: Path) -> None:
    """The short variant (the default run's ROS comparison uses it too) runs to completion with the control on,
    and the report's internal_wrench.png plots its internal force and torque over time: the figure's lines hold
    the record's series."""
    scenario = load_scenario(str(short_carry(tmp_path)))
    record = run_scenario(scenario, _params(), force=True)
    metrics = summarize_run(record, scenario)
    assert metrics["solver_failures"] == 0 and float(metrics["internal_force_settled_max_n"]) < 5.0, metrics
    assert float(metrics["path_error_max_m"]) < 5e-3, metrics
    import matplotlib.pyplot as plt

    drawn: list[Any] = []
    real_savefig = plt.Figure.savefig

    def keep(fig: Any, *args: Any, **kwargs: Any) -> None:
        drawn.append(fig)
        real_savefig(fig, *args, **kwargs)

    path = tmp_path / "internal_wrench.png"
    plt.Figure.savefig = keep  # type: ignore[method-assign]
    try:
        plot_internal_wrench([record], path)
    finally:
        plt.Figure.savefig = real_savefig  # type: ignore[method-assign]
    assert path.stat().st_size > 10_000
    force_line = drawn[0].axes[0].lines[0]
    assert record.internal_wrench is not None
    np.testing.assert_allclose(force_line.get_ydata(), np.linalg.norm(record.internal_wrench[:, :3], axis=1))
    assert math.isclose(float(force_line.get_xdata()[-1]), float(record.time[-1]))
