"""Internal-force control of a held box (issue 41, item 3): the relative-frame admittance, the identification,
the closed loop in the simulator with the control on and off, and its safety (dualarm_control/internal_force.py,
dualarm_control/references/held.py; docs/cooperative.md)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pinocchio as pin
import pytest

from dualarm_control.app.record.report import task_metrics
from dualarm_control.app.run.experiment import run_scenario
from dualarm_control.controller import ControllerParams
from dualarm_control.errors import ScenarioError
from dualarm_control.internal_force import (
    InternalForceParams,
    RelativeAdmittance,
    offset_target,
)
from dualarm_control.kinematics import DualArmModel
from dualarm_control.params import read_params_file
from dualarm_control.references.base import RunOptions
from dualarm_control.references.held import HoldController, tuned
from dualarm_control.scenario import (
    Scenario,
    load_scenario,
    scenario_file,
    scenario_from_parameters,
)
from dualarm_control.status import Status
from dualarm_sim.cell import DualArmCell
from dualarm_sim.cell_config import CellConfig

# no ROS node, no wall-clock verdict: make test runs it at idle CPU priority beside the parallel tests (docs/testing.md)
pytestmark = pytest.mark.background

PARAMS = ControllerParams(solver="constraint_based")


def test_admittance_step_by_hand() -> None:
    """delta = clip(delta + T K (h_I - h_I*)): a 10 N squeeze along z over 5 ms at k_f = 0.01 m/(N s) moves the
    target 0.5 mm apart along z; a 1 N m twist at k_m = 0.25 rad/(N m s) turns it 1.25 mrad; the bounds clip."""
    params = InternalForceParams(setpoint=(0.0, 0.0, 2.0, 0.0, 0.0, 0.0), force_gain=0.01, torque_gain=0.25,
                                 max_offset=0.02, max_rotation=0.1)
    admittance = RelativeAdmittance(params)
    offset = admittance.step(np.array((0.0, 0.0, 12.0, 0.0, 0.0, 1.0)), 0.005)
    np.testing.assert_allclose(offset, (0.0, 0.0, 5e-4, 0.0, 0.0, 1.25e-3), atol=1e-15)
    for _ in range(10000):
        admittance.step(np.array((-1e3, 0.0, 12.0, 0.0, 0.0, 1e3)), 0.005)
    np.testing.assert_allclose(admittance.offset, (-0.02, 0.0, 0.02, 0.0, 0.0, 0.1))
    pi = RelativeAdmittance(dataclasses.replace(params, force_p_gain=1e-4))
    np.testing.assert_allclose(pi.step(np.array((0.0, 0.0, 12.0, 0.0, 0.0, 0.0)), 0.005)[2], 1e-3 + 5e-4)
    np.testing.assert_allclose(pi.step(np.array((0.0, 0.0, 2.0, 0.0, 0.0, 0.0)), 0.005)[2], 5e-4)  # P part gone
    position, rotation = offset_target(np.array((0.0, 0.0, 0.3)), np.eye(3), np.array((0.0, 0.0, 0.01, 0.0, 0.0,
                                                                                        0.1)))
    np.testing.assert_allclose(position, (0.0, 0.0, 0.31))
    np.testing.assert_allclose(rotation, pin.exp3(np.array((0.0, 0.0, 0.1))))


def _hold_box(**control: object) -> Scenario:
    scenario = load_scenario("hold_box")
    spec = scenario.tasks
    assert spec is not None and spec.held is not None
    held = dataclasses.replace(spec.held, control=dataclasses.replace(spec.held.control, **control))
    return dataclasses.replace(scenario, reference=dataclasses.replace(spec, held=held))


def _metrics(scenario: Scenario, on: bool) -> dict[str, float | int | str]:
    record = run_scenario(scenario, PARAMS, force=on)
    assert record.tasks is not None
    return task_metrics(record, record.tasks, scenario)


@pytest.mark.parametrize("name", ["hold_box", "hold_box_lwr4"])
def test_internal_force_control_keeps_the_squeeze_small(name: str) -> None:
    """A 2 kg box, biased noisy sensors, lifted 5 cm and turned 10 deg: with the control the internal force stays
    within 5 N and the torque within 0.5 N m over the whole carry (measured: Baxter 1.63 N, 0.061 N m; LWR4 1.39 N,
    0.139 N m); without it the squeeze grows past 10 N (Baxter 24.3 N, LWR4 17.3 N); the box reaches its target
    either way. With the admittance's sign flipped the squeeze ran away (153 N, tried)."""
    scenario = load_scenario(name)
    on, off = _metrics(scenario, True), _metrics(scenario, False)
    assert on["internal_force_max_n"] < 5.0 and on["internal_torque_max_nm"] < 0.5, on
    assert off["internal_force_max_n"] > 10.0, off
    for run in (on, off):
        assert run["absolute_error_final_m"] < 1e-3 and run["solver_failures"] == 0, run
        assert abs(float(run["identified_mass_kg"]) - 2.0) < 0.01, run  # measured 2.001 (Baxter), 2.002 (LWR4)


def test_identified_payload_and_bias() -> None:
    """The still steps identify the sensors' bias (within 0.1 N, N m: 0.3 N noise) and the 2 kg box within
    0.01 kg (measured 2.001 kg)."""
    scenario = load_scenario("hold_box")
    spec = scenario.tasks
    assert spec is not None and spec.held is not None
    tracker = spec.tracker(DualArmModel(scenario.robot), PARAMS, _options(scenario))
    assert isinstance(tracker, HoldController)
    config = CellConfig.for_robot(scenario.robot, **spec.cell(_options(scenario)))
    with DualArmCell(config, initial_positions=scenario.initial_positions) as cell:
        q = cell.state().positions
        for k in range(round(tracker.params.motion_start / PARAMS.period) + 2):
            out = tracker.track(q, None, k * PARAMS.period, cell.wrist_wrenches().ravel())
            cell.apply_command(out.velocities)
            q = cell.step().positions
    bias = np.array((spec.held.wrist_sensors["left_bias"], spec.held.wrist_sensors["right_bias"]))
    assert np.abs(tracker.identification.bias - bias).max() < 0.1, tracker.identification.bias
    assert abs(tracker.identification.mass - 2.0) < 0.01, tracker.identification.mass


def _options(scenario: Scenario) -> RunOptions:
    return RunOptions(scenario.limits, scenario.settle_time, force=True)


def test_wrench_limit_stops_the_motion_and_says_so() -> None:
    """A 12 N wrench limit (each hand carries 9.8 N of the 2 kg box, and the squeeze adds to it without the
    control): the motion stops with the safe command, the reason names the hand, the force and the limit."""
    record = run_scenario(_hold_box(wrench_limit=12.0), PARAMS, force=False)
    stopped = [k for k, s in enumerate(record.status) if s == Status.INVALID_INPUT]
    assert stopped, "the wrench limit never tripped"
    first = stopped[0]
    assert stopped == list(range(first, len(record.status))), "the stop is latched"
    assert np.abs(record.commands[first + 1:]).max() < 1e-9


def test_missing_wrench_gives_the_safe_command() -> None:
    scenario = load_scenario("hold_box")
    spec = scenario.tasks
    assert spec is not None
    tracker = spec.tracker(DualArmModel(scenario.robot), PARAMS, _options(scenario))
    out = tracker.track(scenario.initial_positions, None, 0.0, np.full(12, math.nan))
    assert out.result.status == Status.INVALID_INPUT and "wrist wrenches" in out.result.detail
    assert np.abs(out.velocities).max() == 0.0


@pytest.mark.parametrize(("key", "value", "message"), [
    ("internal_force.task", "carry", "expected the name of a relative_pose task"),
    ("internal_force.gain", 1.0, "unknown gain"),
    ("internal_force.force_gain", -1.0, "force_gain must be >= 0"),
    ("held_object.mass", 0.0, "mass must be > 0"),
    ("held_object.grasp_time", 0.1, "grasp_time"),
])
def test_bad_held_scenario_values_are_named(key: str, value: object, message: str) -> None:
    path = scenario_file("hold_box")
    flat = dict(read_params_file(path, "trajectory_node"))
    flat["scenario." + key] = value
    with pytest.raises(ScenarioError, match=message):
        scenario = scenario_from_parameters(flat, path)
        assert scenario.tasks is not None
        scenario.tasks.tracker(DualArmModel(scenario.robot), PARAMS, _options(scenario))


def test_live_gains_and_setpoint_retune_the_admittance() -> None:
    """controller_node's live parameters internal_force.force_gain / .torque_gain / .setpoint (docs/cooperative.md):
    < 0 and a one-value setpoint keep the scenario's; a change keeps the admittance's offset; a non-finite
    setpoint is refused naming it."""
    scenario = load_scenario("hold_box")
    assert scenario.tasks is not None
    tracker = scenario.tasks.tracker(DualArmModel(scenario.robot), PARAMS, _options(scenario))
    assert isinstance(tracker, HoldController)
    defaults = {"internal_force.force_gain": -1.0, "internal_force.torque_gain": -1.0, "internal_force.setpoint": [0.0]}
    tracker.retune(defaults)
    assert tracker.params == tracker.scenario_params
    tracker.admittance.step(np.array((0.0, 0.0, 10.0, 0.0, 0.0, 0.0)), 0.005)
    offset = tracker.admittance.offset.copy()
    tracker.retune({**defaults, "internal_force.force_gain": 0.002, "internal_force.setpoint": [0.0, 0.0, 5.0, 0, 0, 0]})
    assert tracker.params.force_gain == 0.002 and tracker.params.setpoint == (0.0, 0.0, 5.0, 0.0, 0.0, 0.0)
    np.testing.assert_array_equal(tracker.admittance.offset, offset)
    after = tracker.admittance.step(np.array((0.0, 0.0, 10.0, 0.0, 0.0, 0.0)), 0.005)
    np.testing.assert_allclose(after[2] - offset[2], 0.002 * 5.0 * 0.005)
    with pytest.raises(ValueError, match=r"setpoint\[2\] must be a finite number"):
        tuned(tracker.scenario_params, {**defaults, "internal_force.setpoint": [0.0, 0.0, math.nan, 0, 0, 0]})


def test_internal_force_keys_need_a_held_object() -> None:
    path = scenario_file("hold_box")
    flat = {k: v for k, v in read_params_file(path, "trajectory_node").items() if ".held_object." not in k}
    with pytest.raises(ScenarioError, match="need the object"):
        scenario_from_parameters(flat, path)
