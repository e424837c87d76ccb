"""The metrics of a run holding one object with two hands (issue 41; docs/cooperative.md): the internal wrench
about its setpoint, the drift of the held relative pose and the absolute task's error.

Window: from the end of the identification (``internal_force`` ``motion_start``: the grasp plus two still
steps) to the end of the run, or to the release of a carry (``held_object.release_time``). Keys (metrics.json):

* ``internal_force_max_n``, ``internal_force_rms_n``: max and RMS of |f_I - f_I*| [N] (h_I in F1);
* ``internal_torque_max_nm``, ``internal_torque_rms_nm``: the same for the moment [N m];
* ``internal_force_settled_max_n``, ``internal_torque_settled_max_nm``: the max from ``convergence_time`` on;
* ``relative_drift_max_m``, ``relative_drift_max_rad``: the held relative pose's largest position and
  orientation error against its nominal target (the relative_pose task ``internal_force.task``; it includes
  the admittance's offset, which is how far the control let the grasp give);
* ``absolute_error_final_m``, ``absolute_error_final_rad``: the absolute tasks' error at the end;
* ``identified_mass_kg``: the payload the still step identified (NaN: the run ended before it).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from dualarm_control.app.record.run_record import RunRecord, TaskValues
from dualarm_control.references.held import HeldSetup


def hold_metrics(log: RunRecord, part: TaskValues, held: HeldSetup, convergence_time: float,
                 absolute: list[str]) -> dict[str, float]:
    """The metrics of the module docstring for a run with an internal wrench column."""
    assert log.internal_wrench is not None
    control = held.control
    held_until = log.time < held.release_time
    window = (log.time >= control.motion_start) & held_until
    settled = (log.time >= max(convergence_time, control.motion_start)) & held_until
    error = log.internal_wrench - np.asarray(control.setpoint, float)
    force = np.linalg.norm(error[:, :3], axis=1)
    torque = np.linalg.norm(error[:, 3:], axis=1)
    hold = part.values[control.task]
    out = {
        "internal_force_max_n": float(np.max(force[window])),
        "internal_force_rms_n": float(np.sqrt(np.mean(force[window] ** 2))),
        "internal_torque_max_nm": float(np.max(torque[window])),
        "internal_torque_rms_nm": float(np.sqrt(np.mean(torque[window] ** 2))),
        "internal_force_settled_max_n": float(np.max(force[settled])),
        "internal_torque_settled_max_nm": float(np.max(torque[settled])),
        "relative_drift_max_m": float(np.linalg.norm(hold[window, :3], axis=1).max()),
        "relative_drift_max_rad": float(np.linalg.norm(hold[window, 3:], axis=1).max()),
        "identified_mass_kg": float(log.identified_mass),
    }
    if absolute:
        out["absolute_error_final_m"] = max(float(np.linalg.norm(part.values[a][-1, :3])) for a in absolute)
        out["absolute_error_final_rad"] = max(float(np.linalg.norm(part.values[a][-1, 3:])) for a in absolute)
    return out


HOLD_ROWS = (
    ("internal force max about the setpoint [N]", "internal_force_max_n", 1.0, "{:.3f}"),
    ("internal force RMS [N]", "internal_force_rms_n", 1.0, "{:.3f}"),
    ("internal force max after convergence [N]", "internal_force_settled_max_n", 1.0, "{:.3f}"),
    ("internal torque max about the setpoint [N m]", "internal_torque_max_nm", 1.0, "{:.3f}"),
    ("internal torque RMS [N m]", "internal_torque_rms_nm", 1.0, "{:.3f}"),
    ("internal torque max after convergence [N m]", "internal_torque_settled_max_nm", 1.0, "{:.3f}"),
    ("relative drift max [mm]", "relative_drift_max_m", 1e3, "{:.3f}"),
    ("relative drift max [mrad]", "relative_drift_max_rad", 1e3, "{:.3f}"),
    ("absolute error at the end [mm]", "absolute_error_final_m", 1e3, "{:.3f}"),
    ("identified payload [kg]", "identified_mass_kg", 1.0, "{:.4f}"),
)
"""The held-object rows of the task table: (label, key, scale, format)."""


def plot_internal_wrench(logs: Sequence[RunRecord], path: Path) -> None:
    """The internal force |f_I - f_I*| [N] and torque |m_I - m_I*| [N m] over time, one line per run (runs with an
    internal wrench column), the end of the still steps dashed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (top, bottom) = plt.subplots(2, 1, figsize=(7.0, 4.5), sharex=True)
    for log in logs:
        if log.internal_wrench is None:
            continue
        top.plot(log.time, np.linalg.norm(log.internal_wrench[:, :3], axis=1), lw=0.8, label=log.label)
        bottom.plot(log.time, np.linalg.norm(log.internal_wrench[:, 3:], axis=1), lw=0.8, label=log.label)
    top.set_ylabel("internal force [N]")
    bottom.set_ylabel("internal torque [N m]")
    bottom.set_xlabel("time [s]")
    for ax in (top, bottom):
        ax.grid(alpha=0.3)
    top.legend(fontsize=8)
    fig.suptitle("internal wrench of the held object (about its setpoint)")
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
