"""Reference source of paper 003: a plan's joint trajectory sample + its relative pose and twist.

The trajectory node streams it; the controller tracks the joint reference under every limit of the
cycle, the collision limit included (:func:`~dualarm_control.joint_tracking.projected_tracking`;
paper 003's planner does not avoid collisions: a plan through the other arm stalls at the safety
distance, in a simulator with its contacts on, issue 39) and measures the relative pose error
against the reference's relative pose (eq 1-2 and 4-6 of paper 000 at q_ref).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from dualarm_control.collision import CollisionModel
from dualarm_control.controller import ControllerParams, Cycle, RelativeController
from dualarm_control.drive_monitor import SegmentJudge
from dualarm_control.kinematics import DualArmModel, FloatArray
from dualarm_control.planning.config import PlanConfig, load_plan_config
from dualarm_control.planning.joint_trajectory import plan_trajectory
from dualarm_control.planning.plan_file import read_plan
from dualarm_control.references.base import (
    JOINT_REFERENCE,
    RELATIVE_TARGET,
    RunOptions,
    SourceDefaults,
    StreamSample,
    relative_report,
)
from dualarm_control.trajectory import MotionLimits


@dataclass(frozen=True)
class PlanReference:
    """One reference sample at time t.

    Attributes:
        joint_positions, joint_velocities: q_ref [rad], qd_ref [rad/s], (14,).
        position, rotation: relative pose of q_ref (right tool in F1) [m], (3,), (3, 3).
        linear_velocity, angular_velocity: relative twist J_r(q_ref) qd_ref [m/s, rad/s], (3,) each.
        linear_acceleration, angular_acceleration: zeros (not used by the controller).
    """

    joint_positions: FloatArray
    joint_velocities: FloatArray
    position: FloatArray
    rotation: FloatArray
    linear_velocity: FloatArray
    angular_velocity: FloatArray
    linear_acceleration: FloatArray
    angular_acceleration: FloatArray


class PlanSource(SourceDefaults):
    """The executable joint trajectory of a plan along its scenario's path: a
    :class:`~dualarm_control.references.base.ReferenceSource` (streams: /joint_reference, and
    /relative_target for the pose error).

    The reference passes through the planned configurations and
    ``execution.subdivisions - 1`` closure-projected knots between each pair
    (:func:`~dualarm_control.planning.joint_trajectory.plan_trajectory`); the run starts at the
    plan's first configuration.
    """

    kind: ClassVar[str] = "plan"
    streams: ClassVar[tuple[str, ...]] = (RELATIVE_TARGET, JOINT_REFERENCE)

    def __init__(self, model: DualArmModel, config: PlanConfig, configurations: FloatArray, path: str = "") -> None:
        self.model = model
        self.path = Path(path)
        self.config = config
        self.configurations = configurations
        self.trajectory = plan_trajectory(model, config.corner.sample(), configurations,
                                          config.execution_subdivisions, config.execution_velocity_scale)
        self.duration = self.trajectory.duration
        self.settle_time = config.execution_settle
        self.gain = config.execution_gain

    @classmethod
    def from_file(cls, model: DualArmModel, plan_path: str | Path) -> PlanSource:
        """The source of a plan.json of ``dualarm plan``."""
        plan = read_plan(plan_path, model.joint_names, model.q_min, model.q_max)
        return cls(model, load_plan_config(plan.scenario), plan.configurations, str(plan_path))

    def initial_positions(self, default: FloatArray) -> FloatArray:
        return np.asarray(self.configurations[0])

    def tracker(self, model: DualArmModel, params: ControllerParams, options: RunOptions) -> PlanTracker:
        return PlanTracker(self, RelativeController(model, params))

    def describe(self) -> str:
        return f"plan {self.path}"

    def stream(self, model: DualArmModel, q0: FloatArray, options: RunOptions, period: float) -> PlanStream:
        return PlanStream(self)

    def judge(self, model: DualArmModel, q0: FloatArray, limits: MotionLimits,
              collision: CollisionModel | None) -> SegmentJudge:
        """The plan's one verdict (issue 39): at the end of the run, the relative pose of the plan's last
        configuration reached (0.5 mm / 5 mrad), or stalled, naming the collision pair or joint limit that
        held the arms (a plan through the other arm stops at the safety distance)."""
        end = self.sample(self.duration)
        return SegmentJudge(model, [self.config.name], [self.duration], [(end.position, end.rotation)], collision,
                            kind="plan")

    def sample(self, t: float) -> PlanReference:
        """The reference at ``t`` [s] (held at the last configuration after the end)."""
        ref = self.trajectory.sample(t)
        state = self.model.relative_state(ref.positions)
        twist = state.jacobian @ ref.velocities
        zero = np.zeros(3)
        return PlanReference(ref.positions, ref.velocities, state.position, state.rotation, twist[:3], twist[3:],
                             zero, zero)


class PlanStream:
    """The plan's joint reference and its relative pose, for the trajectory node."""

    def __init__(self, source: PlanSource) -> None:
        self.source = source
        self.end = source.duration + source.settle_time

    def sample(self, t: float) -> StreamSample:
        ref = self.source.sample(t)
        return StreamSample(ref, (ref.joint_positions, ref.joint_velocities), "execute")


class PlanTracker:
    """Joint-space tracking of the plan's trajectory (:meth:`RelativeController.track_joints`,
    K = the plan's ``execution.gain``) on the cycle's joint reference, the relative pose error
    measured against the reference's relative pose."""

    uses_wrench = False
    label = "plan"
    steps: int | None = None

    def __init__(self, source: PlanSource, controller: RelativeController) -> None:
        self.source = source
        self.controller = controller

    def track(self, q: FloatArray, sample: StreamSample | None, t: float, wrench: FloatArray | None) -> Cycle:
        assert sample is not None and sample.joints is not None, "joint tracking needs the joint reference"
        out = self.controller.track_joints(q, *sample.joints, sample.relative, self.source.gain)
        out.stage = "execute"
        return out

    def report(self, cycle: Cycle, t: float) -> dict[str, Any]:
        """The tracking errors; ``solver`` names what ran (no solver: joint-space tracking)."""
        return {**relative_report(cycle), "solver": "joint_tracking"}
