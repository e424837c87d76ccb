"""controller_node's parameters and what they set (ROS-free).

:data:`NODE_PARAMETERS` are the node's own (watchdogs, mode, scenario, plan, task options, hardware
profile), :data:`ALL_PARAMETERS` those and the core's (:data:`~dualarm_control.controller_params.CONTROLLER_PARAMETERS`).
:func:`controller_params` maps the values to the controller's settings (with the scenario's allowed
contacts), :func:`run_options` to a tracker's run options; :func:`start_text` is the start log line
of what the node runs with.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from dualarm_control import controller as core
from dualarm_control import controller_params as schema
from dualarm_control.hardware import HARDWARE_PARAMETERS
from dualarm_control.kinematics import DualArmModel
from dualarm_control.params import ParamSpec, non_negative, positive
from dualarm_control.references.base import RunOptions, Tracker
from dualarm_control.ros.obstacle_io import OBSTACLE_PARAMETERS
from dualarm_control.ros.priority import thread_priority_spec
from dualarm_control.ros.qos import QOS_PARAMETER
from dualarm_control.scenario import ROBOT_PARAMETER, Scenario

DEFAULT_PRIORITY = 50
"""SCHED_FIFO priority of the control loop (``thread_priority``'s default)."""

NODE_PARAMETERS = (
    ParamSpec("lockstep", False, "compute one command per joint-state stamp (deterministic runs)", read_only=True),
    ParamSpec("stale_timeout", 0.015, "joint states older than this give a zero command [s] (3 periods)",
              check=positive),
    ParamSpec("target_timeout", 0.05, "no target for longer than this while the last one was moving gives a "
              "zero command [s] (10 periods, the simulator's command timeout)", check=positive),
    QOS_PARAMETER,
    thread_priority_spec(DEFAULT_PRIORITY, "the control loop"),
    ParamSpec("scenario", "assembly", "scenario (name or YAML path): its robot and what a cycle tracks, as the "
              "in-process runner (relative targets on /relative_target; a task scenario such as pan_cleaning: "
              "its tasks)", read_only=True),
    ParamSpec("plan", "", "plan.json of `dualarm plan`: track its joint trajectory on /joint_reference "
              "(qd_ref + K (q_ref - q), K = the plan's execution.gain, eq 23 bounds)", read_only=True),
    ParamSpec("task_gain", 0.0, "task mode: gain k of every task [1/s] (0: the scenario's first gain, or "
              "force.gain with force)", check=non_negative, read_only=True),
    ParamSpec("force", False, "task mode: force feedback on /wrench (eq 9)", read_only=True),
    ParamSpec("duration", 0.0, "task mode: run length [s] of task time, then exit (0: the scenario's)",
              check=non_negative, read_only=True),
    ParamSpec("task_start_readers", 0, "task mode, real time: zero commands until /diagnostics has this many "
              "readers (the launcher sets 1 when recording: the bag then holds the run from t = 0)",
              check=non_negative, read_only=True),
    ParamSpec("internal_force.force_gain", -1.0, "held object: k_f of the internal-force admittance [m/(N s)] "
              "(< 0: the scenario's; live)"),
    ParamSpec("internal_force.torque_gain", -1.0, "held object: k_m of the internal-force admittance "
              "[rad/(N m s)] (< 0: the scenario's; live)"),
    ParamSpec("internal_force.setpoint", [0.0], "held object: the internal wrench's setpoint in F1, 6 values "
              "[N, N m] (one value: the scenario's; live)"),
    ROBOT_PARAMETER,
    *HARDWARE_PARAMETERS,
    *OBSTACLE_PARAMETERS,
)
"""controller_node's own parameters (the hardware profile's outputs' keys are added when declared)."""

ALL_PARAMETERS = schema.CONTROLLER_PARAMETERS + NODE_PARAMETERS
"""Every parameter controller_node declares: the core's, then its own."""


def with_cell_defaults(node: Any, scenario: Scenario, values: Mapping[str, Any]) -> dict[str, Any]:
    """``values`` with the cell's defaults (:meth:`~dualarm_control.scenario.Scenario.controller_defaults`: the
    robot's or the scenario's joint acceleration bound) in place of the parameters the node was not given (in a
    file or on the command line: its overrides), and set on the node: ``dualarm param get`` shows the value in
    use, a live change starts from it."""
    from rclpy.parameter import Parameter

    given = getattr(node, "_parameter_overrides", {})
    cell = {key: value for key, value in scenario.controller_defaults().items() if key not in given}
    refused = [f"{key}: {result.reason}" for key, result in zip(cell, node.set_parameters(
        [Parameter(key, value=value) for key, value in cell.items()]), strict=True) if not result.successful]
    if refused:
        raise ValueError(f"{node.get_name()}: the cell's default parameters were refused ({'; '.join(refused)})")
    return {**values, **cell}


def controller_params(scenario: Scenario, values: Mapping[str, Any], node: str) -> core.ControllerParams:
    """The controller's settings from the parameter ``values`` of ``node`` (ParameterError naming a bad
    one), with the scenario's allowed contacts (the assembly's tools) in the collision limit."""
    return scenario.controller_params(schema.controller_params(values, node))


def run_options(scenario: Scenario, values: Mapping[str, Any]) -> RunOptions:
    """The run options of the scenario and the task parameters (``task_gain`` [1/s], ``force``,
    ``duration`` [s]; 0: the scenario's)."""
    return RunOptions(scenario.limits, scenario.settle_time, float(values["task_gain"]) or None,
                      bool(values["force"]), float(values["duration"]) or None)


def acceleration_text(limit: tuple[float, ...]) -> str:
    """The start log's words for the joint acceleration bound (``acceleration_limit`` [rad/s^2]) the run uses."""
    if not limit:
        return "no joint acceleration bound (acceleration_limit: [0.0])"
    values = "/".join(f"{a:g}" for a in limit)
    return f"joint acceleration bound {values} rad/s^2" + (" on every joint" if len(limit) == 1 else " per joint")


def start_text(tracker: Tracker, scenario: str, source: str, model: DualArmModel, params: core.ControllerParams,
               lockstep: bool) -> str:
    """The start log line: what ``tracker`` follows (``source``: its description) on which robot, with which
    solver, gain [1/s], period [s], mode and joint acceleration bound."""
    steps = f", {tracker.steps} cycles" if tracker.steps is not None else ""
    return (f"{tracker.label} on scenario '{scenario}' ({source}{steps}), robot '{model.description.name}'"
            f" ({model.nq} joints), solver '{params.solver}' (K={params.gain}, T={params.period} s, "
            f"{'lockstep' if lockstep else 'real-time, event-driven'}), {acceleration_text(params.acceleration_limit)}")
