"""In-process execution of a plan in the pybullet cell: joint-space tracking of the ruckig trajectory.

The cell starts at the plan's first configuration; every 5 ms control period the command is
``qd = qd_ref(t) + K (q_ref(t) - q)`` inside the eq (23) bounds (joint-space tracking,
:func:`~dualarm_control.joint_tracking.joint_tracking_velocity`, K = ``execution.gain``; the
controller node runs the same law with ``reference:=joint``) with the
reference from :class:`~dualarm_control.planning.joint_trajectory.JointPathTrajectory`
through the planned configurations and ``execution.subdivisions - 1`` closure-projected
knots between each pair (:func:`~dualarm_control.planning.joint_trajectory.densify`).
The executed relative pose (pinocchio, from the measured joint positions) is compared with
the desired path: position error = distance to the continuous corner (line, arc, line),
orientation error = angle between the measured relative rotation and R_d. The same errors of
the reference itself (q_ref, no physics) separate interpolation from tracking.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from dualarm_control.joint_tracking import joint_tracking_velocity
from dualarm_control.kinematics import DualArmModel, FloatArray, rotation_angle
from dualarm_control.limits import JointLimits, velocity_bounds
from dualarm_control.planning.config import PlanConfig
from dualarm_control.planning.joint_trajectory import plan_trajectory
from dualarm_sim.cell import CellConfig, DualArmCell

CONTROL_PERIOD = 0.005  # s, as the controller node


@dataclass(frozen=True)
class ExecutionResult:
    """Executed relative path errors (max and rms over all control periods).

    Attributes:
        duration: trajectory duration [s] (settling time excluded).
        max_error_m, rms_error_m: executed distance to the path [m].
        max_error_rad, rms_error_rad: executed orientation error [rad].
        reference_max_error_m, reference_max_error_rad: same errors of the reference q_ref(t).
        sample_max_error_m, sample_max_error_rad: executed pose vs the path samples, at the
            times the reference passes them [m], [rad].
        max_joint_tracking_error: max |q_ref - q| [rad].
        steps: control periods simulated.
    """

    duration: float
    max_error_m: float
    rms_error_m: float
    max_error_rad: float
    rms_error_rad: float
    reference_max_error_m: float
    reference_max_error_rad: float
    sample_max_error_m: float
    sample_max_error_rad: float
    max_joint_tracking_error: float
    steps: int


def execute_plan(
    config: PlanConfig,
    configurations: FloatArray,
    model: DualArmModel | None = None,
    progress: Callable[[float, str], None] | None = None,
) -> ExecutionResult:
    """Track the plan's joint trajectory in the simulated cell and measure the relative path error."""
    model = model or DualArmModel()
    path = config.corner.sample()
    sub = config.execution_subdivisions
    traj = plan_trajectory(model, path, configurations, sub, config.execution_velocity_scale)
    steps = math.ceil((traj.duration + config.execution_settle) / CONTROL_PERIOD)
    sample_steps = {round(t / CONTROL_PERIOD): i // sub for i, t in enumerate(traj.sample_times) if i % sub == 0}
    r_d = path.rotation
    limits = JointLimits(model.q_min, model.q_max, model.qd_max)
    pos_err, rot_err, ref_pos, ref_rot, track = [], [], [], [], []
    sample_pos, sample_rot = [], []
    every = max(steps // 100, 1)
    with DualArmCell(CellConfig(control_period=CONTROL_PERIOD), initial_positions=configurations[0]) as cell:
        state = cell.state()
        for k in range(steps + 1):
            t = k * CONTROL_PERIOD
            ref = traj.sample(t)
            q = np.asarray(state.positions)
            p, r = model.relative_pose(q)
            pos_err.append(config.corner.distance(p))
            rot_err.append(rotation_angle(r, r_d))
            p_ref, r_ref = model.relative_pose(ref.positions)
            ref_pos.append(config.corner.distance(p_ref))
            ref_rot.append(rotation_angle(r_ref, r_d))
            track.append(float(np.max(np.abs(ref.positions - q))))
            if k in sample_steps:
                i = sample_steps[k]
                sample_pos.append(float(np.linalg.norm(p - path.positions[i])))
                sample_rot.append(rotation_angle(r, r_d))
            if k == steps:
                break
            lower, upper = velocity_bounds(q, limits, CONTROL_PERIOD)
            cell.apply_command(joint_tracking_velocity(q, ref.positions, ref.velocities, config.execution_gain,
                                                       lower, upper))
            state = cell.step()
            if progress is not None and (k % every == 0 or k == steps - 1):
                progress((k + 1) / steps, "execute")
    pe, re_ = np.array(pos_err), np.array(rot_err)
    return ExecutionResult(
        duration=traj.duration,
        max_error_m=float(pe.max()),
        rms_error_m=float(np.sqrt(np.mean(pe**2))),
        max_error_rad=float(re_.max()),
        rms_error_rad=float(np.sqrt(np.mean(re_**2))),
        reference_max_error_m=float(max(ref_pos)),
        reference_max_error_rad=float(max(ref_rot)),
        sample_max_error_m=float(max(sample_pos)),
        sample_max_error_rad=float(max(sample_rot)),
        max_joint_tracking_error=float(max(track)),
        steps=steps,
    )
