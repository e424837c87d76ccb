"""The figures of a run's report, picked by its kind in one place (:func:`write_figures`).

Relative motion (paper 000): the Fig. 5-style velocity norms. Tasks (paper 001): Fig. 4/6/10: tool path in
the pan frame; Fig. 5/7/11: f_i over time with their bounds; Fig. 8/12: the 14 joint velocities; Fig. 11
(last row): the contact force; a held object's internal wrench. Plans (paper 003): Fig. 4 (the index along
the path) and Fig. 5 (the baseline from other initial configurations). An in-process experiment and a
recorded bag draw the same figures from the same :class:`RunRecord`.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from dualarm_control.app.record.hold_metrics import plot_internal_wrench
from dualarm_control.app.record.run_record import RunRecord, TaskValues
from dualarm_control.metrics import ACTIVITY_THRESHOLD
from dualarm_control.scenario import Scenario
from dualarm_control.tasks import CircleTask

if TYPE_CHECKING:  # the planner is only imported where a plan is made
    from dualarm_control.app.plan.optimise import PlanResult


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


def pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig: Any, path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    pyplot().close(fig)


def plot_tool_paths(logs: Sequence[RunRecord], radius: float, path: Path) -> None:
    """Fig. 4: brush tip in the pan frame (x-y plane), one line per run, and the circle."""
    plt = pyplot()
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
    save_figure(fig, path)


def plot_task_values(logs: Sequence[RunRecord], path: Path) -> None:
    """Fig. 5: ||f_1-3|| and each inequality f_i (worst row) over time, bounds in red."""
    plt = pyplot()
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
    save_figure(fig, path)


def plot_joint_velocities(log: RunRecord, path: Path) -> None:
    """Fig. 8: all 14 commanded joint velocities of one run."""
    plt = pyplot()
    fig, axes = plt.subplots(2, 1, figsize=(7.0, 5.0), sharex=True)
    for arm, ax in enumerate(axes):
        for j in range(7):
            ax.plot(log.time, log.commands[:, 7 * arm + j], lw=0.8, label=f"q{j + 1}")
        ax.set_ylabel(f"{('left', 'right')[arm]} qd [rad/s]")
        ax.grid(alpha=0.3)
    axes[0].legend(ncol=7, fontsize=7)
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(f"joint velocities, {log.label} (Fig. 8)")
    save_figure(fig, path)


def plot_contact_force(log: RunRecord, path: Path) -> None:
    """Fig. 11 (last row): contact force (pybullet), filtered sensor value, set point; offset f_F."""
    plt = pyplot()
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
    save_figure(fig, path)


def plot_velocity_norms(runs: Sequence[RunRecord], path: Path, title: str = "") -> None:
    """Fig. 5-style PNG: per run (column), per-joint |qd| of the commands over time and the active-joint count."""
    plt = pyplot()
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
    save_figure(fig, path)


def plot_indices(result: PlanResult, out: Path) -> None:
    """Fig. 4: c along the path for the global method and the baseline from the same start."""
    plt = pyplot()
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
    save_figure(fig, out)


def plot_initial_configurations(result: PlanResult, out: Path) -> None:
    """Fig. 5: the baseline from the planned first configuration vs random feasible ones."""
    plt = pyplot()
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
    save_figure(fig, out)
