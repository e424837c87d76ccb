"""The report of a run: summaries (metrics.json), tables and the figures that fit the scenario's kind.

Relative motion (paper 000): Table I and the Fig. 5-style velocity norms. Tasks (paper 001):
Fig. 4/6/10: tool path in the pan frame; Fig. 5/7/11: f_i over time with their bounds;
Fig. 8/12: the 14 joint velocities; Fig. 11 (last row): the contact force. The same functions
summarise an in-process experiment and a recorded bag (:class:`RunRecord`), so both give the
same keys computed the same way.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from dualarm_control.app.run.experiment import RunRecord, TaskValues, tasks_source
from dualarm_control.kinematics import DualArmModel, FloatArray, rotation_angle
from dualarm_control.metrics import (
    active_set_switches_per_s,
    limit_violations,
    max_joint_acceleration,
    percentiles,
    velocity_norm_metrics,
)
from dualarm_control.scenario import Scenario
from dualarm_control.solvers.base import ACTIVITY_THRESHOLD, FAILURE_STATUSES
from dualarm_control.tasks import (
    INEQUALITY,
    CircleTask,
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
TRACKING_KEYS = ("max_tracking_error_m", "rms_tracking_error_m", "max_tracking_error_rad")
"""Added when per-cycle tracking errors are known (in-process runs, bags with controller diagnostics)."""


def summarize(
    *,
    commands: FloatArray,
    positions: FloatArray,
    velocities: FloatArray,
    period: float,
    statuses: Sequence[str],
    cycle_times: FloatArray,
    final_errors: tuple[float, float],
    q_limits: tuple[FloatArray, FloatArray],
    qd_max: FloatArray,
    tracking_errors: tuple[FloatArray, FloatArray] | None = None,
) -> dict[str, float | int]:
    """The metrics.json record of one run.

    Args:
        commands: commanded joint velocities per cycle [rad/s], (N, n) (Table I uses these).
        positions, velocities: measured joint state per cycle, (N, n).
        period: control period [s].
        statuses: solver status per cycle (N,).
        cycle_times: controller cycle wall times [s], (N,).
        final_errors: (position [m], orientation [rad]) error at the end.
        q_limits: (q_min, q_max) [rad]; qd_max: velocity limits [rad/s].
        tracking_errors: per-cycle relative (position [m], orientation [rad]) error against the
            cycle's target, (N,) each; gives max/rms tracking errors when given.
    """
    norms = velocity_norm_metrics(commands, period)
    vel_violations = limit_violations(np.vstack((commands, velocities)), -qd_max, qd_max, VELOCITY_TOLERANCE)
    p50, p99 = percentiles(cycle_times[np.isfinite(cycle_times)])  # a bag's unparsable times are NaN
    out: dict[str, float | int] = dict(asdict(norms))
    out.update(
        final_position_error_m=float(final_errors[0]),
        final_orientation_error_rad=float(final_errors[1]),
        joint_position_limit_violations=limit_violations(positions, *q_limits, POSITION_TOLERANCE),
        joint_velocity_limit_violations=vel_violations,
        solver_failures=int(sum(s in FAILURE_STATUSES for s in statuses)),
        cycle_time_p50_s=p50,
        cycle_time_p99_s=p99,
        max_joint_acceleration=max_joint_acceleration(commands, period),
        active_set_switches_per_s=active_set_switches_per_s(commands, period),
    )
    if tracking_errors is not None:
        pos, rot = (np.asarray(e, dtype=float)[np.isfinite(e)] for e in tracking_errors)
        if pos.size and rot.size:
            out.update(max_tracking_error_m=float(pos.max()), rms_tracking_error_m=float(np.sqrt(np.mean(pos**2))),
                       max_tracking_error_rad=float(rot.max()))
    return out


def summarize_run(record: RunRecord, scenario: Scenario | None,
                  model: DualArmModel | None = None) -> dict[str, float | int | str]:
    """The metrics.json record of a run, in-process or from a bag: Table I's keys for relative
    motion (:func:`summarize`), paper 001's for tasks (:func:`task_metrics`). The scenario may be
    None for a relative-motion record that holds its ``final_errors`` (a bag's)."""
    if record.tasks is not None:
        assert scenario is not None
        return task_metrics(record, record.tasks, scenario)
    model = model or (DualArmModel(scenario.urdf_path) if scenario is not None else DualArmModel())
    errors = record.final_errors
    if errors is None:
        assert scenario is not None, "a run without recorded final errors needs its scenario"
        errors = final_errors(record, scenario, model)
    return dict(summarize(
        commands=record.commands,
        positions=np.vstack((record.positions, record.final_positions)),
        velocities=record.velocities,
        period=record.period,
        statuses=record.status,
        cycle_times=record.cycle_time,
        final_errors=errors,
        q_limits=(model.q_min, model.q_max),
        qd_max=model.qd_max,
        tracking_errors=(record.position_error, record.orientation_error),
    ))


def final_errors(record: RunRecord, scenario: Scenario, model: DualArmModel) -> tuple[float, float]:
    """Relative position [m] and orientation [rad] error of the final state vs the scenario's end pose."""
    end_position, end_rotation = scenario.end_pose(record.positions[0], model, record.period)
    p, r = model.relative_pose(record.final_positions)
    return float(np.linalg.norm(p - end_position)), rotation_angle(r, end_rotation)


def write_figures(scenario: Scenario, logs: Sequence[RunRecord], out: Path, title: str,
                  contact: bool = True) -> list[str]:
    """The figures that fit the scenario's kind, in ``out``; returns their file names.

    Relative motion: velocity_norms.png (Fig. 5 of paper 000) of every run. Tasks (paper 001):
    tool_path.png and task_values.png of every run, joint_velocities.png of the first, and in the
    force variant (with ``contact``) contact_force.png of the first.
    """
    spec = scenario.tasks
    if spec is None:
        plot_velocity_norms({log.label: (log.time, log.commands) for log in logs}, out / "velocity_norms.png",
                            title=f"{title}: |qd_i| and active joints")
        return ["velocity_norms.png"]
    circle = next(t for t in spec.build(1.0) if isinstance(t, CircleTask))
    plot_tool_paths(logs, circle.radius, out / "tool_path.png")
    plot_task_values(logs, out / "task_values.png")
    plot_joint_velocities(logs[0], out / "joint_velocities.png")
    files = ["tool_path.png", "task_values.png", "joint_velocities.png"]
    if contact and _tasks(logs[0]).force:
        plot_contact_force(logs[0], out / "contact_force.png")
        files.append("contact_force.png")
    return files


def format_results(scenario: Scenario, results: Mapping[str, Mapping[str, Any]]) -> str:
    """The table of the scenario's kind: Table I (relative motion) or paper 001's metrics (tasks)."""
    return format_table(results) if scenario.tasks is None else format_task_table(results)


def write_metrics(path: Path, results: Mapping[str, Mapping[str, Any]]) -> None:
    """Write ``{solver: record}`` as indented JSON (creating the directory)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(results, indent=2, sort_keys=False) + "\n")


def format_table(results: Mapping[str, Mapping[str, Any]]) -> str:
    """Table I of paper 000 for the given runs, plus errors, limits and timings."""
    names = list(results)
    rows = [
        ("mean ||qd||_0 (active joints)", "l0_mean", "{:.3f}"),
        ("mean ||qd||_1 [rad/s]", "l1_mean", "{:.3f}"),
        ("mean ||qd||_2 [rad/s]", "l2_mean", "{:.3f}"),
        ("int ||qd||_0 dt [joint s]", "l0_integral", "{:.2f}"),
        ("int ||qd||_1 dt [rad]", "l1_integral", "{:.3f}"),
        ("int ||qd||_2 dt [rad]", "l2_integral", "{:.3f}"),
        ("duration [s]", "duration_s", "{:.2f}"),
        ("final position error [m]", "final_position_error_m", "{:.2e}"),
        ("final orientation error [rad]", "final_orientation_error_rad", "{:.2e}"),
        ("max tracking error [m]", "max_tracking_error_m", "{:.2e}"),
        ("rms tracking error [m]", "rms_tracking_error_m", "{:.2e}"),
        ("max tracking error [rad]", "max_tracking_error_rad", "{:.2e}"),
        ("position limit violations", "joint_position_limit_violations", "{:d}"),
        ("velocity limit violations", "joint_velocity_limit_violations", "{:d}"),
        ("solver failures", "solver_failures", "{:d}"),
        ("cycle time p50 [ms]", "cycle_time_p50_s", "ms"),
        ("cycle time p99 [ms]", "cycle_time_p99_s", "ms"),
        ("max joint acceleration [rad/s^2]", "max_joint_acceleration", "{:.2f}"),
        ("active-set switches per s", "active_set_switches_per_s", "{:.2f}"),
    ]
    width = max(len(r[0]) for r in rows)
    cols = [max(len(n), 12) for n in names]
    lines = ["metric".ljust(width) + "".join(f"  {n:>{c}}" for n, c in zip(names, cols, strict=True))]
    lines.append("-" * len(lines[0]))
    for label, key, fmt in rows:
        cells = []
        for name, c in zip(names, cols, strict=True):
            value = results[name].get(key)
            if value is None:
                text = "n/a"
            elif fmt == "ms":
                text = f"{value * 1e3:.3f}"
            else:
                text = fmt.format(value)
            cells.append(f"  {text:>{c}}")
        lines.append(label.ljust(width) + "".join(cells))
    return "\n".join(lines)


def plot_velocity_norms(runs: Mapping[str, tuple[FloatArray, FloatArray]], path: Path, title: str = "") -> None:
    """Fig. 5-style PNG: per solver, per-joint |qd| over time and the active-joint count.

    Args:
        runs: ``{solver: (time (N,), commands (N, n))}``.
        path: output PNG.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = len(runs)
    fig, axes = plt.subplots(2, n, figsize=(5.0 * n, 6.0), sharex="col", squeeze=False)
    for col, (name, (t, qd)) in enumerate(runs.items()):
        top, bottom = axes[0][col], axes[1][col]
        for j in range(qd.shape[1]):
            top.plot(t, np.abs(qd[:, j]), lw=0.8, label=f"q{j + 1}")
        top.set_title(name)
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
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def convergence_time(time: FloatArray, error: FloatArray, threshold: float) -> float:
    """First time [s] after which ``error`` stays below ``threshold`` (NaN if it never does)."""
    above = np.nonzero(error >= threshold)[0]
    if above.size == 0:
        return float(time[0])
    last = int(above[-1])
    return float(time[last + 1]) if last + 1 < time.size else float("nan")


def task_metrics(log: RunRecord, part: TaskValues, scenario: Scenario) -> dict[str, float | int | str]:
    """The metrics.json record of one task run (keys in docs/constraint_based.md)."""
    spec = tasks_source(scenario)
    after = log.time >= spec.convergence_time
    circle_name = next(s.name for s in spec.tasks if s.type == "circle")
    circle_error = np.linalg.norm(part.values[circle_name], axis=1)
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
        "convergence_time_1mm_s": convergence_time(log.time, circle_error, 1e-3),
        "max_inequality_violation": worst,
        "min_table_distance_m": min_table,
        "table_contacts": int(log.table_contacts.sum()),
        "min_singularity_margin": margin,
        "min_manipulability_det": manip,
        "solver_failures": int(sum(s in FAILURE_STATUSES for s in log.status)),
        "cycle_time_p50_s": p50,
        "cycle_time_p99_s": p99,
    }
    if part.force:
        record.update(force_metrics(log, part.set_point, spec.convergence_time, spec.force.contact_threshold))
    return record


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


TABLE_ROWS = (
    ("circle RMS error after convergence [mm]", "circle_rms_error_m", 1e3, "{:.4f}"),
    ("circle max error after convergence [mm]", "circle_max_error_after_convergence_m", 1e3, "{:.4f}"),
    ("time to circle error < 1 mm [s]", "convergence_time_1mm_s", 1.0, "{:.2f}"),
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
)


def format_task_table(results: Mapping[str, Mapping[str, Any]]) -> str:
    """A Markdown table of the task-run metrics, one column per run (rows absent everywhere are left out)."""
    names = list(results)
    lines = ["| metric | " + " | ".join(names) + " |", "|---|" + "---:|" * len(names)]
    for label, key, scale, fmt in TABLE_ROWS:
        if not any(key in results[n] for n in names):
            continue
        cells = [fmt.format(results[n][key] * scale) if key in results[n] else "n/a" for n in names]
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    return "\n".join(lines)
