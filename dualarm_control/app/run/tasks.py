"""In-process lockstep run of a task scenario (paper 001's pan cleaning): pybullet cell + tasks.

One control period per step: read the joint state (and, in the force variant, the F/T
sensor) from the physics, evaluate the tasks at the step's time, solve the constraint-based
QP, command, step the physics. Deterministic for a given scenario, gain and seed.

Without force feedback the brush and the pan do not collide (the paper's simulation, eq 8);
with it (eq 9) they make real pybullet contact, the sensor reading is noisy and filtered
(:class:`~dualarm_control.force.ForceSensorModel`), the pan's modelled surface is
``force.model_error`` above the real one, and a PI controller sets the circle task's normal
offset. The table is in the cell in both variants.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from dualarm_control.controller import ControllerParams
from dualarm_control.kinematics import Configuration, DualArmModel, FloatArray
from dualarm_control.metrics import percentiles
from dualarm_control.references.tasks import TasksSource
from dualarm_control.scenario import Scenario
from dualarm_control.task_control import TasksController
from dualarm_control.tasks import (
    INEQUALITY,
    CircleTask,
    ManipulabilityTask,
    TablePlaneTask,
    evaluate_tasks,
)
from dualarm_sim.cell import CellConfig, DualArmCell


@dataclass(frozen=True)
class TaskRunLog:
    """Per-cycle record of a task run; arrays have N rows (one per control period).

    Attributes:
        label: run name (gain, force). gain: k [1/s]. force: force variant or not.
        period: control period [s]. time: cycle times [s], (N,).
        positions, commands: measured joints [rad] and commands [rad/s], (N, 14).
        status: solver status per cycle. cycle_time: controller wall time [s], (N,).
        values, bounds: per task name, f (N, m) and b (m,). kinds: per task, its kind.
        tip_in_pan: brush tip in the model's pan frame [m], (N, 3).
        contact_force: pybullet normal force brush-pan [N], (N,) (0 without contact).
        measured_force: filtered sensor f_c [N], (N,) (NaN without force feedback).
        normal_offset: f_F of eq (9) [m], (N,).
        table_contacts: contact points with the table, (N,).
        set_point: f_c^0 [N] (NaN without force feedback).
    """

    label: str
    gain: float
    force: bool
    period: float
    time: FloatArray
    positions: FloatArray
    commands: FloatArray
    status: list[str]
    cycle_time: FloatArray
    values: dict[str, FloatArray]
    bounds: dict[str, FloatArray]
    kinds: dict[str, str]
    tip_in_pan: FloatArray
    contact_force: FloatArray
    measured_force: FloatArray
    normal_offset: FloatArray
    table_contacts: FloatArray
    set_point: float


def _tasks_source(scenario: Scenario) -> TasksSource:
    if scenario.tasks is None:
        raise ValueError(f"scenario {scenario.name!r} has no tasks (a segment scenario: use 'dualarm experiment')")
    return scenario.tasks


def run_tasks(
    scenario: Scenario,
    params: ControllerParams,
    gain: float,
    force: bool = False,
    duration: float | None = None,
    progress: Callable[[float, str], None] | None = None,
) -> TaskRunLog:
    """Run the task scenario with all task gains k = ``gain`` (force variant if ``force``)."""
    spec = _tasks_source(scenario)
    model = DualArmModel(scenario.urdf_path)
    control = TasksController(model, params, spec, gain, force)
    if control.circle is None:
        raise ValueError(f"scenario {scenario.name!r} has no circle task")
    period = params.period
    steps = math.ceil((duration if duration is not None else spec.duration) / period)
    pairs: tuple[tuple[str, str], ...] = (spec.contact_links,) if force else ()
    config = CellConfig(urdf=scenario.urdf_path, control_period=period, table_height=spec.table_height,
                        contact_pairs=pairs)
    n = model.nq
    rec = {k: np.zeros((steps, n)) for k in ("positions", "commands")}
    scal = {k: np.zeros(steps) for k in ("time", "cycle_time", "contact_force", "normal_offset", "table_contacts",
                                         "measured_force")}
    status: list[str] = []
    every = max(steps // 100, 1)
    with DualArmCell(config, initial_positions=scenario.initial_positions) as cell:
        state = cell.state()
        for k in range(steps):
            t = k * period
            cycle = control.step(state.positions, t, cell.wrench() if force else None)
            out = cycle.output
            cell.apply_command(out.velocities)
            rec["positions"][k], rec["commands"][k] = state.positions, out.velocities
            status.append(out.result.status)
            for key, value in (("time", t), ("cycle_time", out.cycle_time), ("normal_offset", cycle.normal_offset),
                               ("measured_force", cycle.measured_force)):
                scal[key][k] = value
            state = cell.step()
            scal["contact_force"][k] = cell.contact_force(*pairs[0]) if force else 0.0
            scal["table_contacts"][k] = cell.table_contacts()
            if progress is not None and (k % every == 0 or k == steps - 1):
                progress((k + 1) / steps, "circle")
    return task_run_log(scenario, model, gain, force, period, status=status, **rec, **scal)


def task_run_log(
    scenario: Scenario,
    model: DualArmModel,
    gain: float,
    force: bool,
    period: float,
    *,
    time: FloatArray,
    positions: FloatArray,
    commands: FloatArray,
    status: list[str],
    cycle_time: FloatArray,
    normal_offset: FloatArray,
    measured_force: FloatArray,
    contact_force: FloatArray,
    table_contacts: FloatArray,
) -> TaskRunLog:
    """The :class:`TaskRunLog` of a run from its per-cycle record (N rows each, fields as there).

    The task values f_i and bounds b_i and the tool path in the pan frame are evaluated here,
    from the measured joint positions and the cycle times (the circle at the cycle's normal
    offset f_F in the force variant): the same values the controller solved with, computed by
    the one piece of code that serves the in-process runner and a recorded bag
    (:mod:`dualarm_control.app.record.tasks`).
    """
    spec = _tasks_source(scenario)
    tasks = spec.build_variant(gain, force)
    circles = [(i, t) for i, t in enumerate(tasks) if isinstance(t, CircleTask)]
    if not circles:
        raise ValueError(f"scenario {scenario.name!r} has no circle task")
    circle_index, circle = circles[0]
    values: dict[str, list[FloatArray]] = {t.name: [] for t in tasks}
    bounds: dict[str, FloatArray] = {}
    tip = np.zeros((len(time), 3))
    for k, (q, t) in enumerate(zip(positions, time, strict=True)):
        cycle_tasks = tasks
        if force:
            cycle_tasks = list(tasks)
            cycle_tasks[circle_index] = dataclasses.replace(circle, normal_offset=float(normal_offset[k]))
        for rows in evaluate_tasks(cycle_tasks, Configuration(model, model.check_q(q)), float(t)):
            values[rows.name].append(rows.value)
            bounds.setdefault(rows.name, rows.bound)
        o1, o2 = model.frame_poses(q, (circle.pan_frame, circle.tool_frame))
        tip[k] = o1.rotation.T @ (o2.translation - o1.translation)
    label = f"k={gain:g}" + (" force" if force else "")
    return TaskRunLog(label=label, gain=gain, force=force, period=period, time=np.asarray(time, dtype=float),
                      positions=np.asarray(positions, dtype=float), commands=np.asarray(commands, dtype=float),
                      status=list(status), cycle_time=np.asarray(cycle_time, dtype=float),
                      values={name: np.array(v) for name, v in values.items()}, bounds=bounds,
                      kinds={t.name: t.kind for t in tasks}, tip_in_pan=tip,
                      contact_force=np.asarray(contact_force, dtype=float),
                      measured_force=np.asarray(measured_force, dtype=float),
                      normal_offset=np.asarray(normal_offset, dtype=float),
                      table_contacts=np.asarray(table_contacts, dtype=float),
                      set_point=spec.force.set_point if force else float("nan"))


def convergence_time(time: FloatArray, error: FloatArray, threshold: float) -> float:
    """First time [s] after which ``error`` stays below ``threshold`` (NaN if it never does)."""
    above = np.nonzero(error >= threshold)[0]
    if above.size == 0:
        return float(time[0])
    last = int(above[-1])
    return float(time[last + 1]) if last + 1 < time.size else float("nan")


def summarize_task_run(log: TaskRunLog, scenario: Scenario) -> dict[str, float | int | str]:
    """The metrics.json record of one task run (keys in docs/constraint_based.md)."""
    spec = _tasks_source(scenario)
    after = log.time >= spec.convergence_time
    circle_name = next(s.name for s in spec.tasks if s.type == "circle")
    circle_error = np.linalg.norm(log.values[circle_name], axis=1)
    violations = [log.values[name] - log.bounds[name] for name, kind in log.kinds.items() if kind == INEQUALITY]
    worst = max(float(v.max()) for v in violations) if violations else float("nan")
    tasks = spec.build(log.gain)
    table = [t for t in tasks if isinstance(t, TablePlaneTask)]
    singular = [t for t in tasks if isinstance(t, ManipulabilityTask)]
    min_table = min(float(-log.values[t.name].max()) for t in table) if table else float("nan")
    margin = min(float((log.bounds[t.name] - log.values[t.name]).min()) for t in singular) if singular \
        else float("nan")
    manip = min(float((-2.0 * log.values[t.name]).min()) for t in singular) if singular else float("nan")
    p50, p99 = percentiles(log.cycle_time)
    record: dict[str, float | int | str] = {
        "label": log.label,
        "gain": log.gain,
        "force": int(log.force),
        "duration_s": float(log.time[-1] + log.period),
        "circle_rms_error_m": float(np.sqrt(np.mean(circle_error[after] ** 2))),
        "circle_max_error_after_convergence_m": float(circle_error[after].max()),
        "convergence_time_1mm_s": convergence_time(log.time, circle_error, 1e-3),
        "max_inequality_violation": worst,
        "min_table_distance_m": min_table,
        "table_contacts": int(log.table_contacts.sum()),
        "min_singularity_margin": margin,
        "min_manipulability_det": manip,
        "solver_failures": int(sum(s in ("infeasible", "failed", "invalid_input") for s in log.status)),
        "cycle_time_p50_s": p50,
        "cycle_time_p99_s": p99,
    }
    if log.force:
        record.update(force_metrics(log, spec.convergence_time, spec.force.contact_threshold))
    return record


def force_metrics(log: TaskRunLog, settle: float, threshold: float) -> dict[str, float | int]:
    """Contact metrics of a force run: first touch, contact kept, force RMS error around the set point.

    ``force_rms_error_n`` is the RMS of (pybullet contact force - set point) from
    max(first touch, ``settle``) to the end; ``measured_force_rms_error_n`` the same for the
    filtered sensor value the controller used; ``contact_lost_cycles`` counts cycles after the
    first touch with a contact force below ``threshold``; ``contact_force_mean/min/max_n`` are
    taken over the same window as ``force_rms_error_n``, ``contact_force_peak_n`` over the run.
    """
    touching = log.contact_force > threshold
    if not touching.any():
        return {"first_contact_s": float("nan"), "contact_lost_cycles": -1, "force_rms_error_n": float("nan"),
                "contact_force_peak_n": float(log.contact_force.max()),
                "measured_force_rms_error_n": float("nan"), "contact_force_mean_n": float("nan"),
                "force_rms_error_from_first_touch_n": float("nan")}
    first = int(np.argmax(touching))
    window = log.time >= max(float(log.time[first]), settle)
    error = log.contact_force - log.set_point
    return {
        "first_contact_s": float(log.time[first]),
        "contact_lost_cycles": int(np.count_nonzero(~touching[first:])),
        "force_rms_error_n": float(np.sqrt(np.mean(error[window] ** 2))),
        "force_rms_error_from_first_touch_n": float(np.sqrt(np.mean(error[first:] ** 2))),
        "measured_force_rms_error_n": float(np.sqrt(np.mean((log.measured_force[window] - log.set_point) ** 2))),
        "contact_force_mean_n": float(log.contact_force[window].mean()),
        "contact_force_min_n": float(log.contact_force[window].min()),
        "contact_force_max_n": float(log.contact_force[window].max()),
        "contact_force_peak_n": float(log.contact_force.max()),
        "normal_offset_final_m": float(log.normal_offset[-1]),
    }
