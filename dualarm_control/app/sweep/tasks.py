"""Random relative tasks (issue 28): seeded, reproducible, checked feasible before they run.

A task is a start configuration q0 (n,) and one relative goal (the pose of F2 in F1). Task ``i`` of
seed ``s`` draws from ``numpy.random.Generator(PCG64(SeedSequence(s, spawn_key=(i,))))``: the child
``SeedSequence(s).spawn(N)[i]`` would be, for any N, so task i does not depend on how many tasks
there are, and the same (s, i) gives the same task on any machine.

Rejection sampling, each draw until one passes (at most ``max_attempts``):

* **start**: the robot's ready positions plus a uniform offset of at most ``start_spread`` [rad]
  per joint, clipped to the joint range shrunk by ``joint_margin`` (a share of each side); kept when
  the relative Jacobian's manipulability sqrt(det(J J^T)) (eq 5) is at least ``manipulability_floor``,
  no checked link pair (the CollisionModel, with the scenario's and the robot's allowed pairs) is
  closer than ``clearance`` [m], and the tools are at most ``max_tool_distance`` [m] apart;
* **goal**: the start's relative pose moved by a uniform offset in a ball of ``goal_translation``
  [m] and turned by an angle up to ``goal_rotation`` [rad] about a uniform axis; kept when an IK
  solve of the relative pose (scipy's bounded least squares on the package's kinematics, from q0,
  within the shrunk range) reaches it to ``IK_TOLERANCE`` and the solution is collision-free too;
* **duration**: the ruckig trajectory's (the scenario's motion limits) plus the settle time, at
  most ``max_duration`` [s].
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin
from scipy.optimize import least_squares

from dualarm_control.collision import CollisionModel
from dualarm_control.errors import DualArmError
from dualarm_control.kinematics import DualArmModel, FloatArray
from dualarm_control.references.segments import SegmentSpec, SegmentsSource
from dualarm_control.trajectory import MotionLimits

IK_TOLERANCE = 1e-6
"""||log6(pose error)|| [m + rad] below which the relative goal counts as reachable."""


@dataclass(frozen=True)
class TaskSampling:
    """How random relative tasks are drawn (module docstring gives the rule of each field)."""

    joint_margin: float = 0.1
    start_spread: float = 0.5
    manipulability_floor: float = 0.2
    clearance: float = 0.04
    max_tool_distance: float = 0.8
    goal_translation: float = 0.05
    goal_rotation: float = math.radians(15.0)
    max_duration: float = 10.0
    max_attempts: int = 500

    def __post_init__(self) -> None:
        if not 0.0 <= self.joint_margin < 0.5:
            raise ValueError(f"joint_margin: got {self.joint_margin!r}, expected a share in [0, 0.5)")
        for key in ("start_spread", "max_tool_distance", "max_duration"):
            value = getattr(self, key)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{key}: got {value!r}, expected a finite number > 0")
        for key in ("manipulability_floor", "clearance", "goal_translation", "goal_rotation"):
            value = getattr(self, key)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"{key}: got {value!r}, expected a finite number >= 0")
        if self.max_attempts < 1:
            raise ValueError(f"max_attempts: got {self.max_attempts!r}, expected an integer >= 1")


@dataclass(frozen=True)
class RelativeTask:
    """One sampled task.

    Attributes:
        seed, index: what it was drawn from (module docstring).
        start: start joint positions [rad], (n,).
        goal_position: goal of p_r^1 [m], (3,). goal_rotation: goal of R_r^1, (3, 3).
        goal_configuration: the IK solution that proved the goal reachable [rad], (n,).
        duration: trajectory time plus settle time [s].
        attempts: draws rejected before this one (start and goal).
    """

    seed: int
    index: int
    start: FloatArray
    goal_position: FloatArray
    goal_rotation: FloatArray
    goal_configuration: FloatArray
    duration: float
    attempts: int = field(default=0, compare=False)

    def source(self) -> SegmentsSource:
        """The task as the paper-000 reference source: one pose segment to the goal."""
        return SegmentsSource((SegmentSpec("goal", "pose", position=self.goal_position,
                                           rotation=self.goal_rotation),))


def task_generator(seed: int, index: int) -> np.random.Generator:
    """The generator of task ``index`` of ``seed`` (independent of the number of tasks)."""
    if seed < 0 or index < 0:
        raise ValueError(f"seed and index must be >= 0, got {seed}, {index}")
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence(seed, spawn_key=(index,))))


class TaskSampler:
    """Draws :class:`RelativeTask` s for one robot (its model and collision model built once)."""

    def __init__(self, model: DualArmModel, sampling: TaskSampling, limits: MotionLimits, settle_time: float,
                 allowed: tuple[tuple[str, str], ...] = ()) -> None:
        self.model, self.sampling, self.limits, self.settle_time = model, sampling, limits, settle_time
        self.collision = CollisionModel.shared(model, tuple(model.description.collision_allowed) + tuple(allowed))
        span = model.q_max - model.q_min
        finite = np.isfinite(span)
        span = np.where(finite, span, 2 * math.pi)
        self.lower = np.where(finite, model.q_min + sampling.joint_margin * span, -math.pi)
        self.upper = np.where(finite, model.q_max - sampling.joint_margin * span, math.pi)
        self.ready = np.clip(model.description.ready, self.lower, self.upper)

    def manipulability(self, q: FloatArray) -> float:
        """sqrt(det(J J^T)) of the relative Jacobian (eq 5) at q."""
        j = self.model.relative_state(q).jacobian
        return float(math.sqrt(max(np.linalg.det(j @ j.T), 0.0)))

    def clear(self, q: FloatArray) -> bool:
        """No checked pair closer than the clearance at q."""
        return not self.collision.pairs or self.collision.closest(q).distance >= self.sampling.clearance

    def start_ok(self, q: FloatArray) -> bool:
        """The start rules of the module docstring (limits by construction)."""
        p, _ = self.model.relative_pose(q)
        return (float(np.linalg.norm(p)) <= self.sampling.max_tool_distance
                and self.manipulability(q) >= self.sampling.manipulability_floor and self.clear(q))

    def solve_ik(self, q0: FloatArray, position: FloatArray, rotation: FloatArray) -> tuple[FloatArray, float]:
        """Joint positions reaching the relative pose (position [m], rotation) from q0, and the error left."""
        target = pin.SE3(rotation, position)

        def residual(q: FloatArray) -> FloatArray:
            p, r = self.model.relative_pose(q)
            return np.asarray(pin.log6(target.actInv(pin.SE3(r, p))).vector)

        q = least_squares(residual, q0, bounds=(self.lower, self.upper), xtol=1e-14, ftol=1e-14, gtol=1e-14,
                          max_nfev=200).x
        return q, float(np.linalg.norm(residual(q)))

    def sample(self, seed: int, index: int) -> RelativeTask:
        """Task ``index`` of ``seed``; DualArmError when no draw passes in ``max_attempts``."""
        rng, s = task_generator(seed, index), self.sampling
        for attempt in range(s.max_attempts):
            q0 = np.clip(self.ready + rng.uniform(-s.start_spread, s.start_spread, self.model.nq),
                         self.lower, self.upper)
            direction, axis = rng.normal(size=3), rng.normal(size=3)
            offset = direction / np.linalg.norm(direction) * s.goal_translation * rng.uniform() ** (1 / 3)
            angle = s.goal_rotation * rng.uniform()
            if not self.start_ok(q0):
                continue
            p0, r0 = self.model.relative_pose(q0)
            position, rotation = p0 + offset, pin.exp3(axis / np.linalg.norm(axis) * angle) @ r0
            q_goal, error = self.solve_ik(q0, position, rotation)
            if error > IK_TOLERANCE or not self.clear(q_goal):
                continue
            task = RelativeTask(seed, index, q0, position, rotation, q_goal, 0.0, attempt)
            trajectory = task.source().trajectory(p0, r0, self.limits)
            duration = trajectory.duration + self.settle_time
            if duration <= s.max_duration:
                return RelativeTask(seed, index, q0, position, rotation, q_goal, duration, attempt)
        raise DualArmError(f"task {index} of seed {seed} on robot {self.model.description.name!r}: no feasible "
                           f"draw in {s.max_attempts} attempts (relax the sampling: spread, floor, clearance)")
