"""Reference source of paper 003: a plan's joint trajectory sample + its relative pose and twist.

The trajectory node streams it; the controller tracks the joint reference
(:func:`~dualarm_control.joint_tracking.joint_tracking_velocity`) and measures the relative
pose error against the reference's relative pose (eq 1-2 and 4-6 of paper 000 at q_ref).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np

from dualarm_control.kinematics import DualArmModel, FloatArray
from dualarm_control.planning.config import load_plan_config
from dualarm_control.planning.joint_trajectory import plan_trajectory
from dualarm_control.planning.plan_file import read_plan
from dualarm_control.references.base import JOINT_REFERENCE


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


class PlanSource:
    """A plan.json turned into the executable joint trajectory of its scenario's path: a
    :class:`~dualarm_control.references.base.ReferenceSource` (stream: /joint_reference)."""

    kind: ClassVar[str] = "plan"

    def __init__(self, model: DualArmModel, plan_path: str | Path) -> None:
        self.model = model
        self.path = Path(plan_path)
        plan = read_plan(plan_path, model.joint_names)
        self.config = load_plan_config(plan.scenario)
        self.initial_positions = plan.configurations[0]
        self.trajectory = plan_trajectory(model, self.config.corner.sample(), plan.configurations,
                                          self.config.execution_subdivisions, self.config.execution_velocity_scale)
        self.duration = self.trajectory.duration
        self.settle_time = self.config.execution_settle
        self.gain = self.config.execution_gain

    @property
    def streams(self) -> tuple[str, ...]:
        return (JOINT_REFERENCE,)

    def describe(self) -> str:
        return f"plan {self.path}"

    def sample(self, t: float) -> PlanReference:
        """The reference at ``t`` [s] (held at the last configuration after the end)."""
        ref = self.trajectory.sample(t)
        state = self.model.relative_state(ref.positions)
        twist = state.jacobian @ ref.velocities
        zero = np.zeros(3)
        return PlanReference(ref.positions, ref.velocities, state.position, state.rotation, twist[:3], twist[3:],
                             zero, zero)
