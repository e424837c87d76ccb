"""The report of a run: summaries (metrics.json, plan.json), tables and the figures that fit its kind.

One module for the three papers' scenarios. Relative motion (paper 000): Table I and the
Fig. 5-style velocity norms. Tasks (paper 001): Fig. 4/6/10: tool path in the pan frame;
Fig. 5/7/11: f_i over time with their bounds; Fig. 8/12: the 14 joint velocities; Fig. 11
(last row): the contact force. Plans (paper 003): plan.json, Fig. 4 (the index along the path)
and Fig. 5 (the baseline from other initial configurations). The same functions summarise an
in-process experiment and a recorded bag (:class:`RunRecord`), so both give the same keys
computed the same way; :func:`write_figures` is the one place that picks the figures by kind.

plan.json is self-describing (``format``, ``units``, ``joint_names``, the sampled path and
the planner settings travel with the configurations), so a node can execute it without this
package's planner: ``configurations`` are the joint positions [rad] at the path samples
``path.positions_m`` (in the left tool frame F1, orientation ``path.rotation``), in the
order of ``joint_names``.
"""

from __future__ import annotations

import json
import math
import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import asdict
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from dualarm_control.app.record.allowances import allowance_lines, allowance_metrics
from dualarm_control.app.record.carry_metrics import (
    CARRY_ROWS,
    carry_metrics,
    final_task_errors,
)
from dualarm_control.app.record.hold_metrics import (
    HOLD_ROWS,
    hold_metrics,
    plot_internal_wrench,
)
from dualarm_control.app.record.run_record import RunRecord, TaskValues
from dualarm_control.collision import CollisionModel
from dualarm_control.drive_monitor import (
    SegmentJudge,
    closest_pair,
    held_by,
    judge_goals,
)
from dualarm_control.errors import DualArmError
from dualarm_control.kinematics import DualArmModel, FloatArray, rotation_angle
from dualarm_control.metrics import (
    ACTIVITY_THRESHOLD,
    active_set_switches_per_s,
    joint_limit_metrics,
    limit_violations,
    max_joint_acceleration,
    percentiles,
    velocity_norm_metrics,
)
from dualarm_control.planning.plan_file import PLAN_FORMAT
from dualarm_control.scenario import Scenario
from dualarm_control.status import FAILURE_STATUSES
from dualarm_control.tasks import (
    INEQUALITY,
    CircleTask,
    ManipulabilityTask,
    TablePlaneTask,
)

if TYPE_CHECKING:  # the planner and the simulator are only imported where a plan is made or executed
    from dualarm_control.app.plan.execute import ExecutionResult
    from dualarm_control.app.plan.optimise import PlanResult

POSITION_TOLERANCE = 1e-6
"""rad: a measured position beyond a limit by more than this counts as a violation."""
VELOCITY_TOLERANCE = 1e-6
"""rad/s: a commanded or measured velocity beyond its limit by more than this counts."""

METRIC_KEYS = (
    "l0_mean", "l1_mean", "l2_mean", "l0_integral", "l1_integral", "l2_integral", "duration_s",
    "final_position_error_m", "final_orientation_error_rad", "joint_position_limit_violations",
    "joint_velocity_limit_violations", "solver_failures", "cycle_time_p50_s", "cycle_time_p99_s",
    "max_joint_acceleration", "active_set_switches_per_s",
)
JOINT_LIMIT_KEYS = ("joint_limit_min_margin", "joint_limit_final_margin", "repulsive_zone_joint_s",
                    "repulsive_zone_joints", "repulsive_zone_depth_s", "repulsive_zone_alpha")
"""How close a relative-motion run came to the joint limits (issue 43, :class:`~dualarm_control.metrics.JointLimitMetrics`)."""
DEFAULT_ALPHA = 0.1
"""eq (24)'s share alpha the joint-limit metrics use when the run's is not known (the controller's default)."""
TRACKING_KEYS = ("max_tracking_error_m", "rms_tracking_error_m", "max_tracking_error_rad")
"""Added when per-cycle tracking errors are known (in-process runs, bags with controller diagnostics)."""


def summarize_run(record: RunRecord, scenario: Scenario | None, model: DualArmModel | None = None,
                  alpha: float = DEFAULT_ALPHA) -> dict[str, float | int | str]:
    """The metrics.json record of a run, in-process or from a bag: paper 001's keys for tasks
    (:func:`task_metrics`), else Table I's (``METRIC_KEYS``; ``TRACKING_KEYS`` too where the
    record has per-cycle tracking errors), then the joint-limit keys (``JOINT_LIMIT_KEYS``, with eq (24)'s
    share ``alpha`` of the run). The velocity norms are those of the commanded
    velocities (Table I uses these); the velocity limits are checked on the commanded and the
    measured velocities, the position limits on the measured positions. The scenario may be
    None for a relative-motion record that holds its ``final_errors`` (a bag's)."""
    if record.tasks is not None:
        assert scenario is not None
        model = model or DualArmModel(scenario.robot)
        return {**task_metrics(record, record.tasks, scenario, model),
                **task_verdicts(record, record.tasks, scenario, model)}
    model = model or (DualArmModel(scenario.robot) if scenario is not None else DualArmModel())
    errors = record.final_errors
    if errors is None:
        assert scenario is not None, "a run without recorded final errors needs its scenario"
        errors = final_errors(record, scenario, model)
    commands, period = record.commands, record.period
    positions = np.vstack((record.positions, record.final_positions))
    velocities = np.vstack((commands, record.velocities))
    p50, p99 = percentiles(record.cycle_time[np.isfinite(record.cycle_time)])  # a bag's unparsable times are NaN
    out: dict[str, float | int | str] = dict(asdict(velocity_norm_metrics(commands, period)))
    out.update(
        final_position_error_m=float(errors[0]),
        final_orientation_error_rad=float(errors[1]),
        joint_position_limit_violations=limit_violations(positions, model.q_min, model.q_max, POSITION_TOLERANCE),
        joint_velocity_limit_violations=limit_violations(velocities, -model.qd_max, model.qd_max, VELOCITY_TOLERANCE),
        solver_failures=int(sum(s in FAILURE_STATUSES for s in record.status)),
        cycle_time_p50_s=p50,
        cycle_time_p99_s=p99,
        max_joint_acceleration=max_joint_acceleration(commands, period),
        active_set_switches_per_s=active_set_switches_per_s(commands, period),
    )
    out.update(joint_limit_keys(record, model, alpha))
    pos, rot = (e[np.isfinite(e)] for e in (record.position_error, record.orientation_error))
    if pos.size and rot.size:
        out.update(max_tracking_error_m=float(pos.max()), rms_tracking_error_m=float(np.sqrt(np.mean(pos**2))),
                   max_tracking_error_rad=float(rot.max()))
    if record.absolute_error is not None:  # an absolute target (issue 41): the absolute frame's tracking
        error = record.absolute_error[np.all(np.isfinite(record.absolute_error), axis=1)]
        out.update(absolute_max_error_m=float(error[:, 0].max()),
                   absolute_rms_error_m=float(np.sqrt(np.mean(error[:, 0] ** 2))),
                   absolute_max_error_rad=float(error[:, 1].max()))
    if scenario is not None:  # the verdicts of a run of goals or segments, on the controller's collision model
        commands_script = getattr(scenario.reference, "commands", None)
        if commands_script:
            frame = getattr(scenario.reference, "frame", None)  # absolute goals: judged on the absolute frame
            out.update(goal_metrics(record, commands_script, model, scenario.collision_model(model),
                                    frame.pose if frame is not None else None))
        judge = scenario.reference.judge(model, record.positions[0], scenario.limits, scenario.collision_model(model))
        if judge is not None:  # segments, a plan
            out.update(segment_metrics(record, judge))
        parts = [(f"{judge.kind} {k + 1} '{name}'", end) for k, (name, end) in enumerate(zip(judge.names, judge.ends,
                 strict=True))] if judge is not None else [("the run", math.inf)]
        out.update(allowance_metrics(scenario, model, *timed_positions(record), record.final_positions, parts))
    if record.obstacle_events:  # the live obstacles the arms yielded to (in one process: moving_feed.py)
        out["obstacle_events"] = " | ".join(record.obstacle_events)
    return out


def joint_limit_keys(record: RunRecord, model: DualArmModel, alpha: float) -> dict[str, float | int]:
    """The ``JOINT_LIMIT_KEYS`` of a run (its finite cycles' positions; the final positions, else the last cycle's)."""
    cycles = record.positions[np.all(np.isfinite(record.positions), axis=1)]
    final = record.final_positions if np.all(np.isfinite(record.final_positions)) else \
        (cycles[-1] if len(cycles) else np.full(model.nq, np.nan))
    m = joint_limit_metrics(cycles, final, model.q_min, model.q_max, alpha, record.period)
    return {"joint_limit_min_margin": m.min_margin, "joint_limit_final_margin": m.final_margin,
            "repulsive_zone_joint_s": m.zone_joint_seconds, "repulsive_zone_joints": m.zone_joints,
            "repulsive_zone_depth_s": m.zone_depth_seconds, "repulsive_zone_alpha": m.alpha}


SEGMENT_KEYS = ("segments_reached", "segments_stalled", "segment_outcomes")
"""The keys of a segments run (:func:`segment_metrics`)."""


def timed_positions(record: RunRecord) -> tuple[FloatArray, FloatArray]:
    """The cycles' times (N,) [s] and joint positions (N, n) [rad] of a run, paired: a bag's record may hold a
    state fewer or more than its commands (a state re-sent, or lost, on a loaded machine; seen on Baxter under
    ``stress-ng --cpu 1``, where the verdicts then failed on the lengths), so the longer is cut to the shorter."""
    n = min(len(record.time), len(record.positions))
    return record.time[:n], record.positions[:n]


def segment_metrics(record: RunRecord, judge: SegmentJudge) -> dict[str, float | int | str]:
    """How each part of a run ended (issue 40: each segment of a relative trajectory, a plan; the source's
    :meth:`~dualarm_control.references.base.ReferenceSource.judge` from the recorded start, as the trajectory
    node judges it live): reached, or stalled explained by the collision pair or the joint limit that held the arms."""
    outcomes = judge.run(*timed_positions(record), record.final_positions)
    return {"segments_reached": sum(o.state == "reached" for o in outcomes),
            "segments_stalled": sum(o.state == "stalled" for o in outcomes),
            "segment_outcomes": " | ".join(o.text() for o in outcomes)}


GOAL_KEYS = ("goals_reached", "goals_stalled", "goal_outcomes", "collision_min_distance_m", "collision_min_pair")
"""The keys of a scripted goals run (:func:`goal_metrics`)."""


def goal_lines(results: Mapping[str, Mapping[str, Any]]) -> str:
    """The goals' verdicts and the closest pair of every goals run, for the terminal ('' without goals)."""
    out = []
    for label, summary in results.items():
        if "task_outcomes" in summary:
            total = int(summary["tasks_reached"]) + int(summary["tasks_stalled"])
            out.append(f"\n{label}: {summary['tasks_reached']} of {total} equality tasks reached")
            out += [f"  {line}" for line in str(summary["task_outcomes"]).split(" | ") if ": stalled" in line]
        if "segment_outcomes" in summary:
            stalled = [line for line in str(summary["segment_outcomes"]).split(" | ") if ": stalled" in line]
            total = int(summary["segments_reached"]) + int(summary["segments_stalled"])
            out.append(f"\n{label}: {summary['segments_reached']} of {total} segments reached"
                       + ("" if stalled else " (each within 0.5 mm / 5 mrad of its end pose)"))
            out += [f"  {line}" for line in stalled]
        if "obstacle_events" in summary:
            out += [f"  {line}" for line in str(summary["obstacle_events"]).split(" | ")]
        if "goal_outcomes" in summary:
            out.append(f"\n{label}: closest pair {summary['collision_min_pair']} at "
                       f"{summary['collision_min_distance_m']:.4f} m")
            out += [f"  {line}" for line in str(summary["goal_outcomes"]).split(" | ")]
        out += allowance_lines(label, summary)
    return "\n".join(out) + "\n" if out else ""


def goal_metrics(record: RunRecord, commands: Sequence[Any], model: DualArmModel,
                 collision: CollisionModel, absolute: Any = None) -> dict[str, float | int | str]:
    """How each goal of a script ended (:func:`~dualarm_control.drive_monitor.judge_goals`, stalls
    explained by the robot's collision model; absolute goals on ``absolute``'s pose) and the smallest link-pair distance over the run [m]
    (coal, on the recorded positions, the pairs ``collision`` allows excluded)."""
    outcomes = judge_goals(model, commands, *timed_positions(record), record.final_positions, collision,
                           absolute=absolute)
    closest = closest_pair(collision, record.positions)
    return {"goals_reached": sum(o.state == "reached" for o in outcomes),
            "goals_stalled": sum(o.state == "stalled" for o in outcomes),
            "goal_outcomes": " | ".join(o.text() for o in outcomes),
            "collision_min_distance_m": closest.distance, "collision_min_pair": closest.text}


def final_errors(record: RunRecord, scenario: Scenario, model: DualArmModel) -> tuple[float, float]:
    """Relative position [m] and orientation [rad] error of the final state vs the scenario's end pose."""
    end_position, end_rotation = scenario.end_pose(record.positions[0], model, record.period)
    p, r = model.relative_pose(record.final_positions)
    return float(np.linalg.norm(p - end_position)), rotation_angle(r, end_rotation)


def convergence_time(time: FloatArray, error: FloatArray, threshold: float) -> float:
    """First time [s] after which ``error`` stays below ``threshold`` (NaN if it never does)."""
    above = np.nonzero(error >= threshold)[0]
    if above.size == 0:
        return float(time[0])
    last = int(above[-1])
    return float(time[last + 1]) if last + 1 < time.size else float("nan")


def task_metrics(log: RunRecord, part: TaskValues, scenario: Scenario,
                 model: DualArmModel | None = None) -> dict[str, float | int | str]:
    """The metrics.json record of one task run (keys in docs/constraint_based.md; a carry's need ``model``)."""
    spec = scenario.tasks
    assert spec is not None, f"scenario {scenario.name!r} has no tasks"
    after = log.time >= spec.convergence_time
    circle_name = next((s.name for s in spec.tasks if s.type == "circle"), None)
    circle_error = (np.linalg.norm(part.values[circle_name], axis=1) if circle_name is not None
                    else np.full(log.time.shape, np.nan))  # a task set without a circle (a user's own types)
    equality = [part.values[name] - part.bounds[name] for name, kind in part.kinds.items() if kind != INEQUALITY]
    equality_error = np.linalg.norm(np.hstack(equality), axis=1) if equality else np.full(log.time.shape, np.nan)
    violations = [part.values[name] - part.bounds[name] for name, kind in part.kinds.items() if kind == INEQUALITY]
    worst = max(float(v.max()) for v in violations) if violations else float("nan")
    tasks = spec.build(part.gain)
    table = [t for t in tasks if isinstance(t, TablePlaneTask)]
    singular = [t for t in tasks if isinstance(t, ManipulabilityTask)]
    min_table = min(float(-part.values[t.name].max()) for t in table) if table else float("nan")
    margin = min(float((part.bounds[t.name] - part.values[t.name]).min()) for t in singular) if singular \
        else float("nan")
    manip = min(float((-2.0 * part.values[t.name]).min()) for t in singular) if singular else float("nan")
    p50, p99 = percentiles(log.cycle_time)
    record: dict[str, float | int | str] = {
        "label": log.label,
        "gain": part.gain,
        "force": int(part.force),
        "duration_s": float(log.time[-1] + log.period),
        "circle_rms_error_m": float(np.sqrt(np.mean(circle_error[after] ** 2))),
        "circle_max_error_after_convergence_m": float(circle_error[after].max()),
        "convergence_time_1mm_s": convergence_time(log.time, circle_error, 1e-3) if circle_name else float("nan"),
        "equality_rms_error_after_convergence": float(np.sqrt(np.mean(equality_error[after] ** 2))),
        "equality_final_error": float(equality_error[-1]),
        "max_inequality_violation": worst,
        "min_table_distance_m": min_table,
        "table_contacts": int(log.table_contacts.sum()),
        "min_singularity_margin": margin,
        "min_manipulability_det": manip,
        "solver_failures": int(sum(s in FAILURE_STATUSES for s in log.status)),
        "cycle_time_p50_s": p50,
        "cycle_time_p99_s": p99,
    }
    if log.internal_wrench is not None and spec.held is not None:
        absolute = [s.name for s in spec.tasks if s.type == "absolute_pose"]
        record.update(hold_metrics(log, part, spec.held, spec.convergence_time, absolute))
        if spec.held.phases is not None:  # a carry: its path, joint limits and closest pair while held
            record.update(carry_metrics(log, part, scenario, model or DualArmModel(scenario.robot)))
    elif part.force:
        record.update(force_metrics(log, part.set_point, spec.convergence_time, spec.force.contact_threshold))
    return record


TASK_TOLERANCE = 1e-3
"""A task's default tolerance on |f - b| at the end of a run (its units: m for positions; ``<task>.tolerance``)."""


def task_verdicts(log: RunRecord, part: TaskValues, scenario: Scenario, model: DualArmModel
                  ) -> dict[str, float | int | str]:
    """Each equality task's verdict at the end of a task run (issue 40, a stall said out loud for tasks too):
    ``reached`` when |f - b| <= its tolerance (``scenario.<task>.tolerance``, default :data:`TASK_TOLERANCE`),
    else ``stalled``, naming the collision pair and the joint limits that held the arms at the final
    configuration (:func:`~dualarm_control.drive_monitor.held_by`, the scenario's collision model). A circle
    task (a moving target) is judged the same way, at the run's last cycle."""
    spec = scenario.tasks
    assert spec is not None
    tolerances = {s.name: s.value("tolerance", float, TASK_TOLERANCE) for s in spec.tasks}
    q = log.final_positions if np.all(np.isfinite(log.final_positions)) else log.positions[-1]
    t = float(log.time[-1] + log.period)
    collision = scenario.collision_model(model)
    outcomes = []
    carry = final_task_errors(log, part, scenario, model, log.positions[-1], float(log.time[-1])) \
        if spec.held is not None and spec.held.phases is not None else {}  # a carry: on its plan's targets
    for name, kind in part.kinds.items():
        if kind == INEQUALITY:
            continue
        error = carry.get(name, float(np.linalg.norm(part.values[name][-1] - part.bounds[name])))
        head = f"task '{name}' (t = {t:g} s)"
        if error <= tolerances[name]:
            outcomes.append((True, f"{head}: reached, |f - b| = {error:.3g}"))
        else:
            text = held_by(model, q, f"|f - b| = {error:.3g} (tolerance {tolerances[name]:g}) at the end of the run",
                           collision)
            outcomes.append((False, f"{head}: stalled: {text}"))
    return {"tasks_reached": sum(ok for ok, _ in outcomes), "tasks_stalled": sum(not ok for ok, _ in outcomes),
            "task_outcomes": " | ".join(text for _, text in outcomes)}


def force_metrics(log: RunRecord, set_point: float, settle: float, threshold: float) -> dict[str, float | int]:
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
    error = log.contact_force - set_point
    return {
        "first_contact_s": float(log.time[first]),
        "contact_lost_cycles": int(np.count_nonzero(~touching[first:])),
        "force_rms_error_n": float(np.sqrt(np.mean(error[window] ** 2))),
        "force_rms_error_from_first_touch_n": float(np.sqrt(np.mean(error[first:] ** 2))),
        "measured_force_rms_error_n": float(np.sqrt(np.mean((log.measured_force[window] - set_point) ** 2))),
        "contact_force_mean_n": float(log.contact_force[window].mean()),
        "contact_force_min_n": float(log.contact_force[window].min()),
        "contact_force_max_n": float(log.contact_force[window].max()),
        "contact_force_peak_n": float(log.contact_force.max()),
        "normal_offset_final_m": float(log.normal_offset[-1]),
    }


def plan_record(result: PlanResult, model: DualArmModel, execution: ExecutionResult | None) -> dict[str, Any]:
    """The plan.json document of paper 003's plan (see the module docstring)."""
    cfg = result.config
    path = cfg.corner.sample()
    c = cfg.corner
    points = []
    for i in range(len(path)):
        points.append({
            "index": i + 1,
            "key_point": (i + 1) in cfg.key_points,
            "position_m": path.positions[i].tolist(),
            "tangent": path.tangents[i].tolist(),
            "index_value": float(result.indices[i]),
            "baseline_index_value": float(result.baseline.indices[i]),
            "closure_error_m": float(result.closure_position_errors[i]),
            "closure_error_rad": float(result.closure_rotation_errors[i]),
            "configuration_rad": result.configurations[i].tolist(),
            "baseline_configuration_rad": result.baseline.configurations[i].tolist(),
        })
    doc: dict[str, Any] = {
        "format": PLAN_FORMAT,
        "description": "Global manipulability plan of a relative path (Faroni et al., eq 14-20) and the "
                       "pseudo-inverse baseline (eq 12-13) from the same first configuration.",
        "scenario": cfg.name,
        "scenario_file": str(cfg.source) if cfg.source else None,
        "units": {"configurations": "rad", "positions": "m (right tool in the left tool frame F1)",
                  "index": "m^2/rad^2, c = u^T J_r J_r^T u with u = [t; 0] (eq 14), lower is better",
                  "runtime_s": "s wall clock"},
        "joint_names": model.joint_names,
        "average_index": result.average_index,
        "baseline_average_index": result.baseline_average_index,
        "index_ratio": result.average_index / result.baseline_average_index,
        "max_closure_error_m": float(np.max(result.closure_position_errors)),
        "max_closure_error_rad": float(np.max(result.closure_rotation_errors)),
        "joint_limit_violations": result.joint_limit_violations,
        "baseline_joint_limit_violations": int(np.sum((result.baseline.configurations < model.q_min)
                                                      | (result.baseline.configurations > model.q_max))),
        "baseline_max_closure_error_m": float(np.max(result.baseline.position_errors)),
        "runtime_s": result.runtime_s,
        "baseline_runtime_s": result.baseline_runtime_s,
        "starts": cfg.starts,
        "inner_starts": min(cfg.starts, cfg.inner_starts),
        "seed": cfg.seed,
        "workers": result.workers,
        "path": {
            "kind": "corner",
            "side_m": c.side, "fillet_radius_m": c.fillet_radius, "height_m": c.height,
            "samples": list(c.samples), "rpy_rad": list(c.rpy),
            "rotation": path.rotation.tolist(),
            "positions_m": path.positions.tolist(),
            "tangents": path.tangents.tolist(),
            "key_points": list(cfg.key_points),
        },
        "parameters": {
            "lambda_key": cfg.lambda_key, "lambda_inner": cfg.lambda_inner, "candidates": cfg.candidates,
            "inner_spread_rad": cfg.inner_spread,
            "baseline": asdict(cfg.baseline),
            "execution": {"gain": cfg.execution_gain, "velocity_scale": cfg.execution_velocity_scale,
                          "subdivisions": cfg.execution_subdivisions, "settle_time": cfg.execution_settle},
        },
        "indices": result.indices.tolist(),
        "baseline_indices": result.baseline.indices.tolist(),
        "configurations": result.configurations.tolist(),
        "points": points,
        "key_stage": {"best_start": result.best_key_start, "values": result.key_values.tolist(),
                      "start_values": result.key_start_values.tolist(),
                      "candidates": cfg.candidates, "candidate_starts": result.candidate_starts,
                      "candidate_whole_path_costs": result.candidate_costs},
        "inner_stage": {"best_starts": result.best_inner_starts, "values": result.inner_values.tolist()},
        "initial_configuration_study": {
            "planned_first_configuration_average_index": result.baseline_average_index,
            "random_first_configurations_average_index": [float(np.mean(b.indices)) for b in result.random_baselines],
            "random_first_configurations_rad": [b.configurations[0].tolist() for b in result.random_baselines],
        },
    }
    closest = closest_pair(CollisionModel.shared(model, model.description.collision_allowed), result.configurations)
    doc["closest_pair_m"], doc["closest_pair"], doc["closest_pair_point"] = closest.distance, closest.text, closest.index + 1
    if execution is not None:
        doc["executed_max_error_m"] = execution.max_error_m
        doc["executed_max_error_rad"] = execution.max_error_rad
        doc["execution"] = asdict(execution)
    return doc


def prepare_output(out: Path) -> Path:
    """``out`` made (with its parents) and checked writable, before a command's work: DualArmError naming the
    directory and why when it cannot be (a regular file on the way, no permission, a read-only file system),
    with nothing written."""
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise DualArmError(f"output directory {out}: cannot write there (a file, not a directory)")
    try:
        out.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=out):  # writable: a probe file, removed at once
            pass
    except OSError as exc:
        raise DualArmError(f"output directory {out}: cannot write there ({exc.strerror or exc})") from None
    return out


def write_json(path: Path, doc: Mapping[str, Any], indent: int = 2) -> Path:
    """Write ``doc`` (metrics.json: ``{run: record}``; plan.json) as indented JSON, creating the directory."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(doc, indent=indent) + "\n")
    return path


TABLE_I_ROWS = (
    ("mean ||qd||_0 (active joints)", "l0_mean", 1.0, "{:.3f}"),
    ("mean ||qd||_1 [rad/s]", "l1_mean", 1.0, "{:.3f}"),
    ("mean ||qd||_2 [rad/s]", "l2_mean", 1.0, "{:.3f}"),
    ("int ||qd||_0 dt [joint s]", "l0_integral", 1.0, "{:.2f}"),
    ("int ||qd||_1 dt [rad]", "l1_integral", 1.0, "{:.3f}"),
    ("int ||qd||_2 dt [rad]", "l2_integral", 1.0, "{:.3f}"),
    ("duration [s]", "duration_s", 1.0, "{:.2f}"),
    ("final position error [m]", "final_position_error_m", 1.0, "{:.2e}"),
    ("final orientation error [rad]", "final_orientation_error_rad", 1.0, "{:.2e}"),
    ("max tracking error [m]", "max_tracking_error_m", 1.0, "{:.2e}"),
    ("rms tracking error [m]", "rms_tracking_error_m", 1.0, "{:.2e}"),
    ("max tracking error [rad]", "max_tracking_error_rad", 1.0, "{:.2e}"),
    ("absolute frame: max tracking error [m]", "absolute_max_error_m", 1.0, "{:.2e}"),
    ("absolute frame: rms tracking error [m]", "absolute_rms_error_m", 1.0, "{:.2e}"),
    ("absolute frame: max tracking error [rad]", "absolute_max_error_rad", 1.0, "{:.2e}"),
    ("position limit violations", "joint_position_limit_violations", 1.0, "{:.0f}"),
    ("velocity limit violations", "joint_velocity_limit_violations", 1.0, "{:.0f}"),
    ("solver failures", "solver_failures", 1.0, "{:.0f}"),
    ("cycle time p50 [ms]", "cycle_time_p50_s", 1e3, "{:.3f}"),
    ("cycle time p99 [ms]", "cycle_time_p99_s", 1e3, "{:.3f}"),
    ("max joint acceleration [rad/s^2]", "max_joint_acceleration", 1.0, "{:.2f}"),
    ("active-set switches per s", "active_set_switches_per_s", 1.0, "{:.2f}"),
    ("closest joint-limit margin [% of range]", "joint_limit_min_margin", 100.0, "{:.2f}"),
    ("final joint-limit margin [% of range]", "joint_limit_final_margin", 100.0, "{:.2f}"),
    ("time in the repulsive zone [joint s]", "repulsive_zone_joint_s", 1.0, "{:.2f}"),
    ("joints entering the repulsive zone", "repulsive_zone_joints", 1.0, "{:.0f}"),
    ("depth-weighted time in the zone [joint s]", "repulsive_zone_depth_s", 1.0, "{:.3f}"),
)
"""Table I of paper 000, plus errors, limits and timings: (label, key, scale, format)."""
TASK_ROWS = (
    ("circle RMS error after convergence [mm]", "circle_rms_error_m", 1e3, "{:.4f}"),
    ("circle max error after convergence [mm]", "circle_max_error_after_convergence_m", 1e3, "{:.4f}"),
    ("time to circle error < 1 mm [s]", "convergence_time_1mm_s", 1.0, "{:.2f}"),
    ("equality tasks' error at the end, norm of f-b", "equality_final_error", 1.0, "{:.4g}"),
    ("max inequality violation f-b", "max_inequality_violation", 1.0, "{:.4g}"),
    ("min table distance [m]", "min_table_distance_m", 1.0, "{:.3f}"),
    ("table contact points", "table_contacts", 1.0, "{:.0f}"),
    ("min singularity margin b5-f5", "min_singularity_margin", 1.0, "{:.4g}"),
    ("solver failures", "solver_failures", 1.0, "{:.0f}"),
    ("cycle time p50 [ms]", "cycle_time_p50_s", 1e3, "{:.3f}"),
    ("cycle time p99 [ms]", "cycle_time_p99_s", 1e3, "{:.3f}"),
    ("first contact [s]", "first_contact_s", 1.0, "{:.2f}"),
    ("contact lost cycles after first touch", "contact_lost_cycles", 1.0, "{:.0f}"),
    ("force RMS error [N]", "force_rms_error_n", 1.0, "{:.3f}"),
    ("force RMS error from first touch [N]", "force_rms_error_from_first_touch_n", 1.0, "{:.3f}"),
    ("peak contact force [N]", "contact_force_peak_n", 1.0, "{:.2f}"),
    ("measured force RMS error [N]", "measured_force_rms_error_n", 1.0, "{:.3f}"),
    *HOLD_ROWS,
    *CARRY_ROWS,
)
"""Paper 001's metrics (task runs): (label, key, scale, format)."""


def format_table(results: Mapping[str, Mapping[str, Any]], kind: str) -> str:
    """A Markdown table of ``{run: record}``, one column per run: paper 001's metrics for the
    ``tasks`` kind, Table I of paper 000 otherwise (rows that no run has are left out)."""
    names = list(results)
    lines = ["| metric | " + " | ".join(names) + " |", "|---|" + "---:|" * len(names)]
    for label, key, scale, fmt in TASK_ROWS if kind == "tasks" else TABLE_I_ROWS:
        if any(key in results[n] for n in names):
            cells = [fmt.format(results[n][key] * scale) if key in results[n] else "n/a" for n in names]
            lines.append(f"| {label} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def write_figures(kind: str, out: Path, title: str, runs: Sequence[RunRecord] = (),
                  scenario: Scenario | None = None, plan: PlanResult | None = None) -> list[str]:
    """The figures of a run's kind, in ``out`` (the one place that picks them); their file names.

    ``segments``, ``goals`` (paper 000): velocity_norms.png (Fig. 5) of every run. ``tasks``
    (paper 001, needs the ``scenario``): tool_path.png (with a circle task) and task_values.png of every run,
    joint_velocities.png of the first and, in the force variant, contact_force.png of the first
    (where its contact force is known). ``plan`` (paper 003): index_along_path.png (Fig. 4) and
    initial_configuration.png (Fig. 5) of the ``plan`` result.
    """
    if kind == "plan":
        assert plan is not None, "the plan figures need the plan result"
        plot_indices(plan, out / "index_along_path.png")
        plot_initial_configurations(plan, out / "initial_configuration.png")
        return ["index_along_path.png", "initial_configuration.png"]
    if kind != "tasks":
        plot_velocity_norms(runs, out / "velocity_norms.png", title=f"{title}: |qd_i| and active joints")
        return ["velocity_norms.png"]
    assert scenario is not None and scenario.tasks is not None, "the task figures need the task scenario"
    circle = next((t for t in scenario.tasks.build(1.0) if isinstance(t, CircleTask)), None)
    files = []
    if circle is not None:  # the tool path in the pan frame: a circle task's
        plot_tool_paths(runs, circle.radius, out / "tool_path.png")
        files.append("tool_path.png")
    plot_task_values(runs, out / "task_values.png")
    plot_joint_velocities(runs[0], out / "joint_velocities.png")
    files += ["task_values.png", "joint_velocities.png"]
    if runs[0].internal_wrench is not None:  # a held object: its internal wrench, no contact force
        plot_internal_wrench(runs, out / "internal_wrench.png")
        files.append("internal_wrench.png")
    elif _tasks(runs[0]).force and np.isfinite(runs[0].contact_force).any():
        plot_contact_force(runs[0], out / "contact_force.png")
        files.append("contact_force.png")
    return files


def _tasks(log: RunRecord) -> TaskValues:
    """The task part of a task run's record."""
    assert log.tasks is not None, f"run {log.label!r} has no tasks"
    return log.tasks


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig: Any, path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    _pyplot().close(fig)


def plot_tool_paths(logs: Sequence[RunRecord], radius: float, path: Path) -> None:
    """Fig. 4: brush tip in the pan frame (x-y plane), one line per run, and the circle."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(5.5, 5.0))
    a = np.linspace(0, 2 * np.pi, 200)
    ax.plot(radius * 1e3 * np.cos(a), radius * 1e3 * np.sin(a), "r:", lw=1.0, label=f"circle D = {radius * 1e3:g} mm")
    for log in logs:
        ax.plot(_tasks(log).tip_in_pan[:, 0] * 1e3, _tasks(log).tip_in_pan[:, 1] * 1e3, lw=1.0, label=log.label)
        ax.plot(_tasks(log).tip_in_pan[0, 0] * 1e3, _tasks(log).tip_in_pan[0, 1] * 1e3, "ko", ms=3)
    ax.set_xlabel("x in pan frame [mm]")
    ax.set_ylabel("y in pan frame [mm]")
    ax.set_aspect("equal")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title("brush tip relative to the pan (Fig. 4)")
    _save(fig, path)


def plot_task_values(logs: Sequence[RunRecord], path: Path) -> None:
    """Fig. 5: ||f_1-3|| and each inequality f_i (worst row) over time, bounds in red."""
    plt = _pyplot()
    names = list(_tasks(logs[0]).values)
    fig, axes = plt.subplots(len(names), 1, figsize=(7.0, 2.0 * len(names)), sharex=True, squeeze=False)
    for ax, name in zip(axes[:, 0], names, strict=True):
        for log in logs:
            values = _tasks(log).values[name]
            if _tasks(log).kinds[name] == "equality":
                ax.semilogy(log.time, np.maximum(np.linalg.norm(values, axis=1), 1e-9), lw=1.0, label=log.label)
                ax.set_ylabel(f"||{name}|| [m]")
            else:
                ax.plot(log.time, values.max(axis=1), lw=1.0, label=log.label)
                ax.set_ylabel(f"{name}" + (" (max row)" if values.shape[1] > 1 else ""))
        if _tasks(logs[0]).kinds[name] != "equality":
            ax.axhline(float(_tasks(logs[0]).bounds[name].max()), color="r", lw=1.0)
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=8)
    axes[-1, 0].set_xlabel("time [s]")
    fig.suptitle("task functions f_i and bounds b_i (red) (Fig. 5)")
    _save(fig, path)


def plot_joint_velocities(log: RunRecord, path: Path) -> None:
    """Fig. 8: all 14 commanded joint velocities of one run."""
    plt = _pyplot()
    fig, axes = plt.subplots(2, 1, figsize=(7.0, 5.0), sharex=True)
    for arm, ax in enumerate(axes):
        for j in range(7):
            ax.plot(log.time, log.commands[:, 7 * arm + j], lw=0.8, label=f"q{j + 1}")
        ax.set_ylabel(f"{('left', 'right')[arm]} qd [rad/s]")
        ax.grid(alpha=0.3)
    axes[0].legend(ncol=7, fontsize=7)
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(f"joint velocities, {log.label} (Fig. 8)")
    _save(fig, path)


def plot_contact_force(log: RunRecord, path: Path) -> None:
    """Fig. 11 (last row): contact force (pybullet), filtered sensor value, set point; offset f_F."""
    plt = _pyplot()
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(7.0, 4.5), sharex=True)
    top.plot(log.time, log.measured_force, lw=0.7, color="0.6", label="sensor f_c (noisy, filtered)")
    top.plot(log.time, log.contact_force, lw=1.0, label="contact force (pybullet)")
    top.axhline(_tasks(log).set_point, color="r", lw=1.0, label="set point")
    top.set_ylabel("force along pan normal [N]")
    top.legend(fontsize=8)
    top.grid(alpha=0.3)
    bottom.plot(log.time, log.normal_offset * 1e3, lw=1.0)
    bottom.set_ylabel("f_F offset [mm]")
    bottom.set_xlabel("time [s]")
    bottom.grid(alpha=0.3)
    fig.suptitle(f"contact force control (eq 9), {log.label}")
    _save(fig, path)


def plot_velocity_norms(runs: Sequence[RunRecord], path: Path, title: str = "") -> None:
    """Fig. 5-style PNG: per run (column), per-joint |qd| of the commands over time and the active-joint count."""
    plt = _pyplot()
    fig, axes = plt.subplots(2, len(runs), figsize=(5.0 * len(runs), 6.0), sharex="col", squeeze=False)
    for col, run in enumerate(runs):
        top, bottom = axes[0][col], axes[1][col]
        t, qd = run.time, run.commands
        for j in range(qd.shape[1]):
            top.plot(t, np.abs(qd[:, j]), lw=0.8, label=f"q{j + 1}")
        top.set_title(run.label)
        top.set_ylabel("|qd_i| [rad/s]")
        top.grid(alpha=0.3)
        active = np.count_nonzero(np.abs(qd) > ACTIVITY_THRESHOLD, axis=1)
        bottom.step(t, active, where="post", color="k", lw=1.0)
        bottom.set_ylim(-0.5, qd.shape[1] + 0.5)
        bottom.set_ylabel(f"||qd||_0 (|qd_i| > {ACTIVITY_THRESHOLD:g})")
        bottom.set_xlabel("time [s]")
        bottom.grid(alpha=0.3)
    axes[0][-1].legend(ncol=2, fontsize=6, loc="upper right")
    if title:
        fig.suptitle(title)
    _save(fig, path)


def plot_indices(result: PlanResult, out: Path) -> None:
    """Fig. 4: c along the path for the global method and the baseline from the same start."""
    plt = _pyplot()
    i = np.arange(1, len(result.indices) + 1)
    fig, ax = plt.subplots(figsize=(7, 3.6))
    ax.plot(i, result.indices, "b.-", label=f"global method (mean {result.average_index:.3f})")
    ax.plot(i, result.baseline.indices, "r.-", label=f"pseudo-inverse + null-space gradient (mean "
            f"{result.baseline_average_index:.3f})")
    for k in result.config.key_points:
        ax.axvline(k, color="0.85", lw=0.8, zorder=0)
    h1, h2, _ = result.config.corner.samples
    ax.axvspan(h1 + 0.5, h1 + h2 + 0.5, color="y", alpha=0.15, label="fillet")
    ax.set_xlabel("path point i (grey: key points)")
    ax.set_ylabel(r"$c = u^T J_r J_r^T u$ [m$^2$/rad$^2$]")
    ax.set_title(f"{result.config.name}: index along the path (paper Fig. 4), {result.config.starts} starts, "
                 f"{result.config.candidates} candidates")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    _save(fig, out)


def plot_initial_configurations(result: PlanResult, out: Path) -> None:
    """Fig. 5: the baseline from the planned first configuration vs random feasible ones."""
    plt = _pyplot()
    i = np.arange(1, len(result.indices) + 1)
    fig, ax = plt.subplots(figsize=(7, 3.6))
    ax.plot(i, result.baseline.indices, "b.-",
            label=f"from the planned q_1 (mean {result.baseline_average_index:.3f})")
    for b, color in zip(result.random_baselines, ("r", "g", "m", "c", "k"), strict=False):
        ax.plot(i, b.indices, color + ".-", label=f"from a random feasible q_1 (mean {np.mean(b.indices):.3f})")
    ax.set_xlabel("path point i")
    ax.set_ylabel(r"$c$ [m$^2$/rad$^2$]")
    ax.set_title("pseudo-inverse baseline: effect of the initial configuration (paper Fig. 5)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    _save(fig, out)
