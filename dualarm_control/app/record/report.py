"""The report of a run: its summary (metrics.json) and tables, for the three papers' scenarios.

Relative motion (paper 000): Table I; tasks (paper 001): their metrics and verdicts. The same functions
summarise an in-process experiment and a recorded bag (:class:`RunRecord`), so both give the same keys
computed the same way. The figures are :mod:`dualarm_control.app.record.figures`; a plan's plan.json is
:mod:`dualarm_control.app.plan.record`.
"""

from __future__ import annotations

import json
import math
import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

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
    active_set_switches_per_s,
    joint_limit_metrics,
    limit_violations,
    max_joint_acceleration,
    percentiles,
    velocity_norm_metrics,
)
from dualarm_control.scenario import Scenario
from dualarm_control.status import FAILURE_STATUSES
from dualarm_control.tasks import (
    INEQUALITY,
    ManipulabilityTask,
    TablePlaneTask,
)

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
