"""A held box over ROS (issue 41, items 2-3): sim_node's wrist sensors on /left/wrench and /right/wrench,
controller_node's internal-force control on them (docs/cooperative.md).

Lockstep: the bag's metrics equal the in-process experiment's exactly (the same physics, the same sensor noise
drawn once per step, the same solver path; the internal wrench comes back from /diagnostics at full precision).
A wrist stream that stops trips the stale-wrench watchdog as stale joint states do.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from launching import meanwhile
from metrics_match import assert_same_metrics

from dualarm_control.app.record.bag_runs import read_run
from dualarm_control.app.record.report import summarize_run
from dualarm_control.app.run.experiment import run_scenario
from dualarm_control.app.run.launcher import launch_scenario
from dualarm_control.controller_params import controller_params
from dualarm_control.nodes.controller_inputs import ControllerInputs, cycle_wrench
from dualarm_control.params import read_params_files
from dualarm_control.references.base import LEFT_WRENCH, RIGHT_WRENCH, WRENCH
from dualarm_control.scenario import load_scenario

PARAMS = str(Path(__file__).parents[1] / "config" / "solvers" / "constraint_based.yaml")


def _in_process() -> dict[str, float | int | str]:
    scenario = load_scenario("hold_box")
    params = controller_params({**read_params_files([PARAMS], "controller_node"), "solver": "constraint_based"})
    return summarize_run(run_scenario(scenario, params, force=True), scenario)


def test_lockstep_hold_box_bag_metrics_equal_in_process(tmp_path: Path) -> None:
    """`dualarm launch hold_box --lockstep --force --record BAG` then `dualarm report BAG`: every metric
    (internal force and torque, drift, absolute error) equals the in-process run's, exactly (measured: equal to
    the last bit; the issue asks 1e-6)."""
    bag = tmp_path / "bag"
    code, expected = meanwhile(
        lambda: launch_scenario("hold_box", [PARAMS], [], True, bag, timeout=120.0, force=True),
        _in_process)
    assert code == 0
    (log,), scenario = read_run(bag)
    assert scenario is not None and log.internal_wrench is not None
    from_bag = summarize_run(log, scenario)
    assert_same_metrics(from_bag, expected, ignore=("label",))
    assert float(from_bag["internal_force_max_n"]) < 5.0
    # the viewer's arrays of the bag: the held object's frame, and the box among the closest pairs' links
    from dualarm_control.app.view.from_bag import bag_run_arrays

    arrays = bag_run_arrays(bag)
    # where the simulator had the box (/held_object/pose), in the left tool frame: at its grasp to 1e-6 m
    np.testing.assert_allclose(arrays.frames["held_object"][0, :3], (0.0, 0.0, 0.15), atol=1e-6)
    assert arrays.closest is not None and arrays.held is not None
    forces = arrays.held.forces  # the wrist readings of each cycle's stamp: the hands carry the 2 kg box
    assert np.isfinite(forces["left_tool"]).all() and np.isfinite(forces["right_tool"]).all()
    assert 5.0 < np.linalg.norm(forces["left_tool"][-1]) < 30.0, forces["left_tool"][-1]
    import rerun as rr

    recording = rr.RecordingStream("dualarm_test_held")
    recording.save(str(tmp_path / "held.rrd"))
    arrays.log(recording)
    recording.flush()
    assert (tmp_path / "held.rrd").stat().st_size > 0


class _Out:
    def __init__(self) -> None:
        self.safe_states: list[str] = []

    def enter_safe_state(self, stamp: int, reason: str) -> None:
        self.safe_states.append(reason)

    def safe(self, stamp: int, reason: str) -> None:
        self.safe_states.append(reason)


def test_a_stopped_wrist_stream_trips_the_watchdog() -> None:
    """Real time: a wrist sensor's last sample older than stale_timeout gives the safe state, naming the stream;
    fresh ones give the cycle both readings (12,), left then right."""
    out = _Out()
    values = {"stale_timeout": 0.05, "target_timeout": 0.1}
    inputs = ControllerInputs((LEFT_WRENCH, RIGHT_WRENCH), False, out, None, lambda: values, Any, lambda: None)
    left, right = np.arange(6.0), np.arange(6.0, 12.0)
    inputs.samples.put(LEFT_WRENCH, 1, left)
    inputs.samples.put(RIGHT_WRENCH, 1, right)
    sample = inputs.fresh(1)
    assert sample is not None and out.safe_states == []
    np.testing.assert_array_equal(cycle_wrench(sample), np.arange(12.0))
    value, received = inputs.samples.latest[LEFT_WRENCH]
    inputs.samples.latest[LEFT_WRENCH] = (value, received - 80_000_000)  # its last sample 80 ms ago
    assert inputs.fresh(2) is None
    assert out.safe_states and out.safe_states[-1].startswith("left/wrench stale by"), out.safe_states
    assert cycle_wrench({WRENCH: left}) is left and cycle_wrench({}) is None


def test_a_realtime_cycle_waits_for_the_wrist_readings_of_its_stamp() -> None:
    """Real time: the wrist readings are synced to the joint state's stamp (a one-period-old reading made the
    stiff internal-force loop unstable: 980 N in process): an older one makes the cycle wait, without a safe
    command, and its arrival runs the cycle."""
    out, cycles = _Out(), []
    values = {"stale_timeout": 0.05, "target_timeout": 0.1}
    inputs = ControllerInputs((LEFT_WRENCH, RIGHT_WRENCH), False, out, None, lambda: values, Any,
                              lambda: cycles.append(inputs.fresh(10)))
    inputs.put(LEFT_WRENCH, 5, np.zeros(6))
    inputs.put(RIGHT_WRENCH, 5, np.ones(6))
    assert inputs.fresh(10) is None and out.safe_states == []  # readings of stamp 5 for the state of stamp 10
    inputs.put(LEFT_WRENCH, 10, np.zeros(6))
    assert cycles[-1] is None  # the right one of stamp 10 is still on the way
    inputs.put(RIGHT_WRENCH, 10, np.ones(6))
    assert cycles[-1] is not None and out.safe_states == []


@pytest.mark.slow
@pytest.mark.realtime
def test_realtime_hold_box_keeps_the_squeeze_small(tmp_path: Path) -> None:
    """`dualarm launch hold_box --force --record BAG` in real time at 200 Hz: internal force within 5 N and torque
    within 0.5 N m (measured 1.67 N, 0.062 N m; before the wrist readings were synced to the joint state's stamp,
    the loop ran away and the wrench limit stopped the motion). ``slow``: the stiff grasp's force in real time
    depends on the machine's timing (10.1 N once in a fresh clone's CI run on 2 cores); the default run judges the
    control law in lockstep over ROS (test_lockstep_hold_box_bag_metrics_equal_in_process) and in one process."""
    bag = tmp_path / "bag"
    assert launch_scenario("hold_box", [PARAMS], [], False, bag, timeout=120.0, force=True) == 0
    (log,), scenario = read_run(bag)
    assert scenario is not None
    metrics = summarize_run(log, scenario)
    assert metrics["solver_failures"] == 0, metrics
    assert float(metrics["internal_force_max_n"]) < 5.0 and float(metrics["internal_torque_max_nm"]) < 0.5, metrics


def test_viewer_series_carry_the_internal_wrench() -> None:
    """`dualarm view` of a held-object run plots its internal wrench, six components in F1."""
    from dualarm_control.app.view.from_bag import record_arrays
    from dualarm_control.kinematics import DualArmModel

    scenario = load_scenario("hold_box")
    params = controller_params({**read_params_files([PARAMS], "controller_node"), "solver": "constraint_based"})
    record = run_scenario(scenario, params, force=True, duration=0.5)
    arrays = record_arrays(record, DualArmModel(scenario.robot))
    assert record.internal_wrench is not None
    np.testing.assert_array_equal(arrays.series["internal/fz_n"], record.internal_wrench[:, 2])
    assert {f"internal/{a}" for a in ("fx_n", "fy_n", "fz_n", "mx_nm", "my_nm", "mz_nm")} <= set(arrays.series)


class _Node:
    def add_on_set_parameters_callback(self, callback: Any) -> None:
        self.callback = callback

    def get_name(self) -> str:
        return "controller_node"

    def get_logger(self) -> Any:
        class _Log:
            def warning(self, text: str) -> None:
                pass

            def info(self, text: str) -> None:
                pass
        return _Log()


class _Parameter:
    def __init__(self, name: str, value: Any) -> None:
        self.name, self.value = name, value


def test_a_live_setpoint_arrives_as_an_array_and_is_taken() -> None:
    """rclpy gives a double-array parameter as array.array('d'): the live setpoint is accepted (it was refused as
    "expected a double array", tried with `dualarm param set`), a non-finite one refused naming it."""
    import array

    from dualarm_control.nodes.controller_setup import ALL_PARAMETERS
    from dualarm_control.references.held import tuned
    from dualarm_control.ros.node import LiveParameters

    specs = {s.name: s for s in ALL_PARAMETERS}
    values = {name: spec.default for name, spec in specs.items()}
    scenario = load_scenario("hold_box")
    assert scenario.tasks is not None and scenario.tasks.held is not None
    live = LiveParameters(_Node(), specs, values, lambda merged: tuned(scenario.tasks.held.control, merged))
    setpoint = array.array("d", [0.0, 0.0, 2.0, 0.0, 0.0, 0.1])
    assert live.on_set([_Parameter("internal_force.setpoint", setpoint)]).successful
    change = live.take()
    assert change is not None and change[1].setpoint == (0.0, 0.0, 2.0, 0.0, 0.0, 0.1)
    bad = live.on_set([_Parameter("internal_force.setpoint", array.array("d", [0.0, 0.0, math.nan, 0, 0, 0]))])
    assert not bad.successful and "setpoint[2]" in bad.reason


def test_a_live_array_is_recorded_as_a_list() -> None:
    """After a live array change rclpy keeps the value as array.array: /dualarm/cell records it as a list (a YAML
    dump of the array crashed controller_node, tried)."""
    import array

    from dualarm_control.ros.cell_topic import node_parameters

    class _ParamNode:
        def get_parameters_by_prefix(self, prefix: str) -> dict[str, Any]:
            return {"internal_force.setpoint": _Parameter("internal_force.setpoint", array.array("d", [0.0, 1.0])),
                    "task_gain": _Parameter("task_gain", 2.0)}

    assert node_parameters(_ParamNode()) == {"internal_force.setpoint": [0.0, 1.0], "task_gain": 2.0}
