"""The metrics of a carry (issue 41, item 5; docs/cooperative.md "The scenario `carry`"), beside those of any held
object (:mod:`~dualarm_control.app.record.hold_metrics`, over the same window): from the end of the identification
(``motion_start``) to the release (``held_object.release_time``), the box in both hands. Keys (metrics.json):

* ``path_error_max_m``, ``path_error_rms_m``, ``path_error_max_rad``: the absolute frame against its planned path
  (:class:`~dualarm_control.references.carry.CarryPlan`, rebuilt from the run's first joint positions as the
  controller built it): |p_a - p*| [m] and the angle of R*^T R_a [rad];
* ``absolute_error_final_m`` / ``_rad``: the same at the last cycle before the release (the set-down pose);
* ``held_joint_limit_violations``: joint positions beyond their limits (1e-6 rad) over the run;
* ``held_collision_min_distance_m``, ``held_collision_min_pair``: the closest pair of the scenario's collision model
  (the box on the left tool, the support it is put on allowed) while held;
* with the simulator's box pose (``RunRecord.object_pose``: in one process, or /held_object/pose in a bag):
  ``slip_left_max_m`` / ``_rad``, ``slip_right_max_m`` / ``_rad``: the box's pose in each tool frame,
  X_i = T_i^-1 T_o (T_i from the recorded joints' kinematics), against X_i just after the grasp (grasp_time +
  :data:`GRASP_SETTLE`): max |p_i - p_i0| [m] and the angle of R_i0^T R_i [rad] while held;
  ``placed_box_moved_m``: how far the box is at the end of the run from where it was at the last cycle held
  (the drop onto the support and anything after: it stays where it was put).

One function serves ``dualarm experiment`` and ``dualarm report BAG``: the same figures from the same record.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pinocchio as pin

from dualarm_control.app.record.run_record import RunRecord, TaskValues
from dualarm_control.drive_monitor import closest_pair
from dualarm_control.kinematics import (
    Configuration,
    DualArmModel,
    FloatArray,
    rotation_angle,
)
from dualarm_control.metrics import limit_violations
from dualarm_control.references.carry import CarryPlan
from dualarm_control.references.held import carry_plan, carry_tasks
from dualarm_control.scenario import Scenario
from dualarm_control.tasks import AbsolutePoseTask, Task, evaluate_tasks

IntArray = npt.NDArray[np.intp]

GRASP_SETTLE = 0.02
"""[s] after ``grasp_time``: the box's pose in each tool frame then is the grasp's (the slip's reference)."""

POSITION_TOLERANCE = 1e-6
"""[rad] a joint beyond its limit by more counts as a violation (the report's own tolerance)."""


def run_plan(log: RunRecord, scenario: Scenario, model: DualArmModel, gain: float
             ) -> tuple[list[Task], CarryPlan, int, int]:
    """A carry's tasks at ``gain``, its plan from the run's first joint positions (as the controller built it),
    and the indices of its relative_pose and absolute_pose tasks."""
    spec = scenario.tasks
    assert spec is not None and spec.held is not None
    held, phases = spec.held, spec.held.phases
    assert phases is not None
    tasks = spec.build(gain)
    held_index = [t.name for t in tasks].index(held.control.task)
    absolute_index = next(i for i, t in enumerate(tasks) if isinstance(t, AbsolutePoseTask))
    plan = carry_plan(model, tasks, held_index, absolute_index, phases, held.control, scenario.limits,
                      log.positions[0])
    return tasks, plan, held_index, absolute_index


def final_task_errors(log: RunRecord, part: TaskValues, scenario: Scenario, model: DualArmModel,
                      q: FloatArray, t: float) -> dict[str, float]:
    """|f - b| of each task of a carry at q (n,) [rad] and t [s] on the plan's targets then (the verdicts')."""
    tasks, plan, held_index, absolute_index = run_plan(log, scenario, model, part.gain)
    conf = Configuration(model, q)
    return {rows.name: float(np.linalg.norm(rows.value - rows.bound))
            for rows in evaluate_tasks(carry_tasks(tasks, plan, t, held_index, absolute_index), conf, t)}


def carry_metrics(log: RunRecord, part: TaskValues, scenario: Scenario, model: DualArmModel) -> dict[str, float | str]:
    """The keys of the module docstring for a carry's run record (its task values' gain builds the tasks)."""
    tasks, plan, _, absolute_index = run_plan(log, scenario, model, part.gain)
    held = scenario.tasks.held  # type: ignore[union-attr]
    assert held is not None
    absolute = tasks[absolute_index]
    assert isinstance(absolute, AbsolutePoseTask)
    window = np.nonzero((log.time >= held.control.motion_start) & (log.time < held.release_time))[0]
    position = np.zeros(len(window))
    angle = np.zeros(len(window))
    for j, k in enumerate(window):
        state = absolute.state(Configuration(model, log.positions[k]))
        target = plan.absolute(float(log.time[k]))
        position[j] = float(np.linalg.norm(state.position - target.position))
        angle[j] = rotation_angle(state.rotation, target.rotation)
    closest = closest_pair(scenario.collision_model(model), log.positions[window])
    out = slip_metrics(log, model, held.control.grasp_time, window) if log.object_pose is not None else {}
    return {**out,
        "path_error_max_m": float(position.max()),
        "path_error_rms_m": float(np.sqrt(np.mean(position ** 2))),
        "path_error_max_rad": float(angle.max()),
        "absolute_error_final_m": float(position[-1]),
        "absolute_error_final_rad": float(angle[-1]),
        "held_joint_limit_violations": limit_violations(np.vstack((log.positions, log.final_positions)),
                                                        model.q_min, model.q_max, POSITION_TOLERANCE),
        "held_collision_min_distance_m": closest.distance,
        "held_collision_min_pair": closest.text,
    }


CARRY_ROWS = (
    ("path error max [mm]", "path_error_max_m", 1e3, "{:.3f}"),
    ("slip in the left grasp max [mm]", "slip_left_max_m", 1e3, "{:.4f}"),
    ("slip in the right grasp max [mm]", "slip_right_max_m", 1e3, "{:.4f}"),
    ("slip in the grasps max [mrad]", "slip_max_rad", 1e3, "{:.4f}"),
    ("box moved after the last cycle held [mm]", "placed_box_moved_m", 1e3, "{:.3f}"),
    ("path error RMS [mm]", "path_error_rms_m", 1e3, "{:.3f}"),
    ("path error max [mrad]", "path_error_max_rad", 1e3, "{:.3f}"),
    ("joint limit violations", "held_joint_limit_violations", 1.0, "{:.0f}"),
    ("closest collision distance while held [mm]", "held_collision_min_distance_m", 1e3, "{:.1f}"),
)
"""The carry's rows of the task table: (label, key, scale, format)."""


def _in_tools(model: DualArmModel, q: FloatArray, pose: FloatArray) -> list[tuple[FloatArray, FloatArray]]:
    """The box's pose (position [m], rotation) in the left and the right tool frame at q (n,) [rad], from its world
    pose (x, y, z, qx, qy, qz, qw)."""
    conf = Configuration(model, q)
    x, y, z, w = pose[3:]
    rotation = pin.Quaternion(w, x, y, z).normalized().toRotationMatrix()
    out = []
    for name in ("left_tool", "right_tool"):
        tool = conf.frame(name)
        out.append((tool.rotation.T @ (pose[:3] - tool.position), tool.rotation.T @ rotation))
    return out


def slip_metrics(log: RunRecord, model: DualArmModel, grasp_time: float, window: IntArray) -> dict[str, float]:
    """``slip_*`` and ``placed_box_moved_m`` (module docstring) over the cycles ``window`` (indices, ascending)."""
    assert log.object_pose is not None
    poses = log.object_pose
    finite = np.all(np.isfinite(poses), axis=1)
    after = np.nonzero((log.time >= grasp_time + GRASP_SETTLE) & finite)[0]
    held = window[finite[window]]
    if not len(after) or not len(held):
        return {}
    reference = _in_tools(model, log.positions[after[0]], poses[after[0]])
    slip = np.zeros((len(held), 2, 2))
    for j, k in enumerate(held):
        for i, ((p, r), (p0, r0)) in enumerate(zip(_in_tools(model, log.positions[k], poses[k]), reference,
                                                   strict=True)):
            slip[j, i] = (float(np.linalg.norm(p - p0)), rotation_angle(r, r0))
    last = np.nonzero(finite)[0][-1]
    return {"slip_left_max_m": float(slip[:, 0, 0].max()), "slip_left_max_rad": float(slip[:, 0, 1].max()),
            "slip_right_max_m": float(slip[:, 1, 0].max()), "slip_right_max_rad": float(slip[:, 1, 1].max()),
            "slip_max_rad": float(slip[:, :, 1].max()),
            "placed_box_moved_m": float(np.linalg.norm(poses[last, :3] - poses[held[-1], :3]))}
