"""The run record: what one run of any scenario gives, per control cycle, whoever produced it.

The in-process runner (:func:`dualarm_control.app.run.experiment.run_scenario`) and the bag reader
(:func:`dualarm_control.app.record.bag_runs.read_run`) both give :class:`RunRecord`; the report
(:mod:`dualarm_control.app.record.report`) and the viewer (:mod:`dualarm_control.app.view.from_bag`)
read it. Its task part (:class:`TaskValues`) is computed from the recorded joint positions by
:func:`with_task_values`, the one piece of code for both producers.

Core imports only (kinematics, tasks, scenario): no simulator, no ROS, no report.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from dualarm_control.kinematics import Configuration, DualArmModel, FloatArray
from dualarm_control.references.base import RunOptions
from dualarm_control.scenario import Scenario
from dualarm_control.tasks import CircleTask, evaluate_tasks


@dataclass(frozen=True)
class TaskValues:
    """The task part of a run record (scenarios with tasks).

    Attributes:
        gain: task gain k [1/s]. force: force variant or not.
        values, bounds: per task name, f (N, m) and b (m,). kinds: per task, its kind.
        tip_in_pan: brush tip in the model's pan frame [m], (N, 3).
        set_point: f_c^0 [N] (NaN without force feedback).
    """

    gain: float
    force: bool
    values: dict[str, FloatArray]
    bounds: dict[str, FloatArray]
    kinds: dict[str, str]
    tip_in_pan: FloatArray
    set_point: float


@dataclass(frozen=True)
class RunRecord:
    """Per-cycle record of one run, in-process or from a bag; arrays have N rows (one per control period).

    Plain arrays per field, so that any reader (report, viewer) takes what it needs. Fields a
    source does not produce hold NaN (relative errors of a task run, forces without force
    feedback, measured velocities and solve times a bag does not carry).

    Attributes:
        label: run name (the solver for relative motion, "k=1 force" for tasks).
        kind: the reference source's kind ("segments", "tasks", "plan").
        period: control period [s].
        time: cycle times since the start [s], (N,).
        positions, velocities: measured joint state at each cycle [rad, rad/s], (N, 14).
        commands: commanded joint velocities [rad/s], (N, 14).
        status: solver status per cycle.
        solve_time, cycle_time: wall times [s], (N,).
        position_error, orientation_error: relative tracking errors vs the cycle's target [m, rad], (N,).
        final_positions: joint positions after the last step [rad], (14,) (NaN when unknown).
        contact_force: pybullet normal force of the contact pair [N], (N,) (0 without contact pair).
        measured_force: filtered sensor f_c [N], (N,) (NaN without force feedback).
        normal_offset: f_F of eq (9) [m], (N,).
        table_contacts: contact points with the table, (N,).
        tasks: task values and bounds where there are tasks, else None.
        final_errors: final relative (position [m], orientation [rad]) error where the recording
            gives it (a bag: its last /relative_pose against its last /relative_target); None:
            the report computes it from ``final_positions`` and the scenario.
        obstacle_events: each stretch of cycles the live obstacle limit held the command, as text with the
            obstacle's name (``t = 16.20-17.35 s: yielding to obstacle:hand (closest 0.034 m, left_flange)``).
        absolute_error: the absolute frame's tracking error (position [m], orientation [rad]) per cycle, (N, 2),
            in a run with an absolute target (issue 41; a bag: the controller's /diagnostics values), else None.
        internal_wrench: a held object's internal wrench h_I [N, N m] in F1, (N, 6)
            (:mod:`dualarm_control.references.held`); None without a held object.
        identified_mass: the held object's mass the still step identified [kg] (NaN: none).
        object_pose: the simulated held box's world pose at each cycle's state, (x, y, z [m], qx, qy, qz, qw),
            (N, 7) (a bag: /held_object/pose by the state's stamp, NaN where missing); None without one.
    """

    label: str
    kind: str
    period: float
    time: FloatArray
    positions: FloatArray
    velocities: FloatArray
    commands: FloatArray
    status: list[str]
    solve_time: FloatArray
    cycle_time: FloatArray
    position_error: FloatArray
    orientation_error: FloatArray
    final_positions: FloatArray
    contact_force: FloatArray
    measured_force: FloatArray
    normal_offset: FloatArray
    table_contacts: FloatArray
    tasks: TaskValues | None = field(default=None)
    final_errors: tuple[float, float] | None = None
    obstacle_events: tuple[str, ...] = ()
    absolute_error: FloatArray | None = None
    internal_wrench: FloatArray | None = None
    identified_mass: float = math.nan
    object_pose: FloatArray | None = None


def with_task_values(record: RunRecord, scenario: Scenario, model: DualArmModel, gain: float | None,
                     force: bool) -> RunRecord:
    """``record`` with its task values (a scenario with tasks; otherwise unchanged).

    The task values f_i and bounds b_i and the tool path in the pan frame (NaN without a circle task) are
    evaluated here,
    from the measured joint positions and the cycle times (the circle at the cycle's normal
    offset f_F in the force variant): the same values the controller solved with, computed by
    the one piece of code that serves the in-process runner and a recorded bag
    (:mod:`dualarm_control.app.record.bag`).
    """
    spec = scenario.tasks
    if spec is None:
        return record
    k_gain = spec.gain(RunOptions(scenario.limits, scenario.settle_time, gain, force))
    tasks = spec.build_variant(k_gain, force)
    circles = [(i, t) for i, t in enumerate(tasks) if isinstance(t, CircleTask)]
    circle_index, circle = circles[0] if circles else (-1, None)  # no circle: no tool path (NaN)
    values: dict[str, list[FloatArray]] = {t.name: [] for t in tasks}
    bounds: dict[str, FloatArray] = {}
    tip = np.zeros((len(record.time), 3))
    for k, (q, t) in enumerate(zip(record.positions, record.time, strict=True)):
        cycle_tasks = tasks
        if force and circle is not None:
            cycle_tasks = list(tasks)
            cycle_tasks[circle_index] = dataclasses.replace(circle, normal_offset=float(record.normal_offset[k]))
        for rows in evaluate_tasks(cycle_tasks, Configuration(model, model.check_q(q)), float(t)):
            values[rows.name].append(rows.value)
            bounds.setdefault(rows.name, rows.bound)
        if circle is None:
            tip[k] = np.nan
            continue
        o1, o2 = model.frame_poses(q, (circle.pan_frame, circle.tool_frame))
        tip[k] = o1.rotation.T @ (o2.translation - o1.translation)
    part = TaskValues(gain=k_gain, force=force, values={name: np.array(v) for name, v in values.items()},
                      bounds=bounds, kinds={t.name: t.kind for t in tasks}, tip_in_pan=tip,
                      set_point=spec.force.set_point if force else float("nan"))
    return dataclasses.replace(record, tasks=part)


def absolute_columns(position: FloatArray, orientation: FloatArray) -> FloatArray | None:
    """(N, 2) of the absolute frame's errors [m, rad] per cycle, None when no cycle had an absolute target."""
    if not np.isfinite(position).any():
        return None
    return np.column_stack((position, orientation))


def nan_column(n: int) -> FloatArray:
    """(n,) NaN: a field a source or a bag does not give."""
    return np.full(n, math.nan)
