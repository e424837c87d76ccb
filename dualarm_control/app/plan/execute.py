"""In-process execution of a plan in the pybullet cell: joint-space tracking of the ruckig trajectory.

The cell starts at the plan's first configuration; every 5 ms control period the command is the
one nearest to ``qd = qd_ref(t) + K (q_ref(t) - q)`` within every limit of the cycle, the collision
limit included (joint-space tracking, :func:`~dualarm_control.joint_tracking.projected_tracking`,
K = ``execution.gain``; the controller node runs the same tracker with ``plan:=FILE``), in the
simulator with its contacts on: a plan through the other arm (paper 003's planner does not avoid
collisions) stalls at the safety distance, and the result names the closest pair. The
reference from :class:`~dualarm_control.planning.joint_trajectory.JointPathTrajectory`
through the planned configurations and ``execution.subdivisions - 1`` closure-projected
knots between each pair (:func:`~dualarm_control.planning.joint_trajectory.densify`).
The executed relative pose (pinocchio, from the measured joint positions) is compared with
the desired path: position error = distance to the continuous corner (line, arc, line),
orientation error = angle between the measured relative rotation and R_d. The same errors of
the reference itself (q_ref, no physics) separate interpolation from tracking.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from dualarm_control.app.run.experiment import run_scenario
from dualarm_control.collision import CollisionModel
from dualarm_control.controller import ControllerParams
from dualarm_control.controller_params import controller_params
from dualarm_control.drive_monitor import closest_pair
from dualarm_control.kinematics import DualArmModel, FloatArray, rotation_angle
from dualarm_control.planning.config import PlanConfig
from dualarm_control.references.plan import PlanSource
from dualarm_control.scenario import Scenario, load_scenario
from dualarm_control.trajectory import MotionLimits

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
        closest_distance_m, closest_pair: the closest link pair over the executed run [m] (coal, the
            robot's allowed pairs excluded; at most the collision model's margin).
        outcome: the plan's verdict (:meth:`PlanSource.judge`): "plan 1 'NAME' (t = T s): reached, ..." or
            "...: stalled: collision constraint: A – B at 0.031 m; remaining error ...".
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
    closest_distance_m: float = float("inf")
    closest_pair: str = ""
    outcome: str = ""

    @property
    def stalled(self) -> bool:
        """Whether the plan ended short of its last configuration's relative pose."""
        return ": stalled" in self.outcome


def plan_cell(config: PlanConfig, source: PlanSource) -> tuple[Scenario, ControllerParams]:
    """The cell a plan is executed in, and its controller's settings: the scenario file the plan was made from
    (``config.source``; its obstacles, allowed contacts and the controller defaults it sets, e.g. a joint
    acceleration bound, :meth:`~dualarm_control.scenario.Scenario.controller_defaults`) on the plan's robot,
    started at the plan's first configuration and tracking ``source``. A config with no file: the robot alone."""
    start = np.asarray(source.configurations[0], dtype=float)
    scenario = Scenario(name=config.name, description="plan execution", initial_positions=start, reference=source,
                        limits=MotionLimits(), settle_time=config.execution_settle, source=Path(config.name),
                        robot=config.robot)
    if config.source is not None:
        cell = load_scenario(str(config.source), config.robot, reference=source)
        scenario = replace(cell, description="plan execution", initial_positions=start, limits=MotionLimits(),
                           settle_time=config.execution_settle, source=Path(config.name))
    params = controller_params({**scenario.controller_defaults(), "control_period": CONTROL_PERIOD})
    return scenario, scenario.controller_params(params)


def execute_plan(
    config: PlanConfig,
    configurations: FloatArray,
    model: DualArmModel | None = None,
    progress: Callable[[float, str], None] | None = None,
) -> ExecutionResult:
    """Track the plan's joint trajectory in the simulated cell (the one runner,
    :func:`~dualarm_control.app.run.experiment.run_scenario`, on a
    :class:`~dualarm_control.references.plan.PlanSource`) and measure the relative path error."""
    model = model or DualArmModel(config.robot)
    source = PlanSource(model, config, configurations)
    scenario, params = plan_cell(config, source)
    record = run_scenario(scenario, params, model, progress)
    path = config.corner.sample()
    sub = config.execution_subdivisions
    traj = source.trajectory
    sample_steps = {round(t / CONTROL_PERIOD): i // sub for i, t in enumerate(traj.sample_times) if i % sub == 0}
    r_d = path.rotation
    pos_err, rot_err, ref_pos, ref_rot, track = [], [], [], [], []
    sample_pos, sample_rot = [], []
    for k, q in enumerate(np.vstack((record.positions, record.final_positions))):
        ref = traj.sample(k * CONTROL_PERIOD)
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
    pe, re_ = np.array(pos_err), np.array(rot_err)
    collision = CollisionModel.shared(model, model.description.collision_allowed)
    closest = closest_pair(collision, np.vstack((record.positions, record.final_positions)))
    verdicts = source.judge(model, configurations[0], scenario.limits, collision).run(
        record.time, record.positions, record.final_positions)
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
        steps=len(record.time),
        closest_distance_m=closest.distance,
        closest_pair=closest.text,
        outcome=" | ".join(v.text() for v in verdicts),
    )
