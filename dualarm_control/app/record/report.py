"""Run summaries (metrics.json), the Table I printout and Fig. 5-style plots.

The same functions summarise an in-process experiment and a recorded bag, so both give
the same keys computed the same way.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from dualarm_control.kinematics import FloatArray
from dualarm_control.metrics import (
    active_set_switches_per_s,
    limit_violations,
    max_joint_acceleration,
    percentiles,
    velocity_norm_metrics,
)
from dualarm_control.solvers.base import ACTIVITY_THRESHOLD, FAILURE_STATUSES

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
    p50, p99 = percentiles(cycle_times)
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
