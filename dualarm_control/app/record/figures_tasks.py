"""Plots of task runs like paper 001's figures, and the metrics table.

Fig. 4/6/10: tool path in the pan frame; Fig. 5/7/11: f_i over time with their bounds;
Fig. 8/12: the 14 joint velocities; Fig. 11 (last row): the contact force.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from dualarm_control.app.run.tasks import TaskRunLog


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


def plot_tool_paths(logs: Sequence[TaskRunLog], radius: float, path: Path) -> None:
    """Fig. 4: brush tip in the pan frame (x-y plane), one line per run, and the circle."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(5.5, 5.0))
    a = np.linspace(0, 2 * np.pi, 200)
    ax.plot(radius * 1e3 * np.cos(a), radius * 1e3 * np.sin(a), "r:", lw=1.0, label=f"circle D = {radius * 1e3:g} mm")
    for log in logs:
        ax.plot(log.tip_in_pan[:, 0] * 1e3, log.tip_in_pan[:, 1] * 1e3, lw=1.0, label=log.label)
        ax.plot(log.tip_in_pan[0, 0] * 1e3, log.tip_in_pan[0, 1] * 1e3, "ko", ms=3)
    ax.set_xlabel("x in pan frame [mm]")
    ax.set_ylabel("y in pan frame [mm]")
    ax.set_aspect("equal")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title("brush tip relative to the pan (Fig. 4)")
    _save(fig, path)


def plot_task_values(logs: Sequence[TaskRunLog], path: Path) -> None:
    """Fig. 5: ||f_1-3|| and each inequality f_i (worst row) over time, bounds in red."""
    plt = _pyplot()
    names = list(logs[0].values)
    fig, axes = plt.subplots(len(names), 1, figsize=(7.0, 2.0 * len(names)), sharex=True, squeeze=False)
    for ax, name in zip(axes[:, 0], names, strict=True):
        for log in logs:
            values = log.values[name]
            if log.kinds[name] == "equality":
                ax.semilogy(log.time, np.maximum(np.linalg.norm(values, axis=1), 1e-9), lw=1.0, label=log.label)
                ax.set_ylabel(f"||{name}|| [m]")
            else:
                ax.plot(log.time, values.max(axis=1), lw=1.0, label=log.label)
                ax.set_ylabel(f"{name}" + (" (max row)" if values.shape[1] > 1 else ""))
        if logs[0].kinds[name] != "equality":
            ax.axhline(float(logs[0].bounds[name].max()), color="r", lw=1.0)
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=8)
    axes[-1, 0].set_xlabel("time [s]")
    fig.suptitle("task functions f_i and bounds b_i (red) (Fig. 5)")
    _save(fig, path)


def plot_joint_velocities(log: TaskRunLog, path: Path) -> None:
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


def plot_contact_force(log: TaskRunLog, path: Path) -> None:
    """Fig. 11 (last row): contact force (pybullet), filtered sensor value, set point; offset f_F."""
    plt = _pyplot()
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(7.0, 4.5), sharex=True)
    top.plot(log.time, log.measured_force, lw=0.7, color="0.6", label="sensor f_c (noisy, filtered)")
    top.plot(log.time, log.contact_force, lw=1.0, label="contact force (pybullet)")
    top.axhline(log.set_point, color="r", lw=1.0, label="set point")
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
