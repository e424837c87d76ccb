"""Ready positions of a dual-arm robot: a start configuration in which the tools face each other.

A small inverse-kinematics search (scipy's bounded least squares, several seeded starts) on the
arms' model (:class:`~dualarm_control.kinematics.DualArmModel`). The residuals, each weighted:

* the relative pose of F2 in F1 against ``[0, 0, distance]`` with R = Rx(pi) (rpy 180 0 0: the
  tools' z axes point at each other, as at the start of the approach of the assembly task):
  position [m] and log3 of the rotation error [rad], weight 10;
* the tools' midpoint at ``center`` [m] (world), weight 1;
* the line from the right tool to the left tool along the world's +y (the left arm on the left),
  weight 1;
* each joint's distance from the middle of its range, relative to the range, weight 0.2.

Then the relative pose alone, from that compromise, to 1e-6 (the soft terms only choose where
in the redundancy the solution lies). Joints are bounded to their range shrunk by ``margin``
(10 % of each side). Among the starts the
solution with a relative pose error below 1e-6 that lies farthest from the joint limits is kept,
among those whose smallest singular value of the relative Jacobian (eq 5) is at least half the
best one (away from singularities), and whose shapes keep at least ``clearance`` (5 cm) apart: every
pair the collision limit checks, tools included, with only the robot's own allowed pairs (those
that overlap by construction) left out: a start that needs the collision limit at once is no ready
configuration. Deterministic for a seed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from scipy.optimize import least_squares

from dualarm_control.errors import DualArmError
from dualarm_control.kinematics import DualArmModel, FloatArray

FACING = pin.rpy.rpyToMatrix(math.pi, 0.0, 0.0)
POSE_WEIGHT, CENTER_WEIGHT, LINE_WEIGHT, MIDDLE_WEIGHT = 10.0, 1.0, 1.0, 0.2
SOLVED = 1e-6  # relative pose error [m, rad] below which a start counts as solved
CLEARANCE = 0.05
"""[m] the smallest distance of any checked pair of shapes at a ready configuration."""


@dataclass(frozen=True)
class Ready:
    """A ready configuration.

    Attributes:
        q: joint positions [rad], (n,). pose_error: ||relative pose error|| [m + rad].
        sigma_min: smallest singular value of the relative Jacobian at q.
        limit_margin: smallest distance of a joint from its limits, relative to its range.
        center: the tools' midpoint [m], (3,).
        clearance: the closest checked pair's distance [m] and its links ("link_a – link_b").
    """

    q: FloatArray
    pose_error: float
    sigma_min: float
    limit_margin: float
    center: FloatArray
    clearance: tuple[float, str] = (math.inf, "")


def default_center(model: DualArmModel) -> FloatArray:
    """A point in front of the arms: the mean of their first joints' origins, moved along +x by
    0.45 times the mean arm reach (a comfortable distance for most arms) [m], (3,)."""
    origins, reach = [], 0.0
    for frame_id in model.tool_frame_ids:
        joint = model.model.frames[frame_id].parentJoint
        reach += float(np.linalg.norm(model.model.frames[frame_id].placement.translation))
        while model.model.parents[joint] != 0:
            reach += float(np.linalg.norm(model.model.jointPlacements[joint].translation))
            joint = model.model.parents[joint]
        pose = pin.SE3.Identity()
        j = joint
        while j != 0:
            pose = model.model.jointPlacements[j] * pose
            j = model.model.parents[j]
        origins.append(pose.translation)
    return np.mean(origins, axis=0) + np.array([0.45 * reach / 2.0, 0.0, 0.0])


def find_ready(model: DualArmModel, distance: float = 0.3, center: FloatArray | None = None, starts: int = 24,
               seed: int = 0, margin: float = 0.1, clearance: float = CLEARANCE) -> Ready:
    """The ready configuration (module docstring); DualArmError when no start reaches the pose."""
    if not (math.isfinite(distance) and distance > 0):
        raise DualArmError(f"--distance {distance!r}: expected a distance > 0 [m]")
    c = default_center(model) if center is None else np.asarray(center, dtype=float)
    span = model.q_max - model.q_min
    finite = np.isfinite(span)
    span = np.where(finite, span, 2 * math.pi)
    lo = np.where(finite, model.q_min + margin * span, -math.pi)
    hi = np.where(finite, model.q_max - margin * span, math.pi)
    middle = 0.5 * (lo + hi)
    target = pin.SE3(FACING, np.array([0.0, 0.0, distance]))

    def residuals(q: FloatArray) -> FloatArray:
        o1, o2 = model.tool_poses(q)
        error = pin.log6(target.actInv(o1.actInv(o2))).vector
        mid = 0.5 * (o1.translation + o2.translation)
        line = o1.translation - o2.translation
        return np.concatenate((POSE_WEIGHT * error, CENTER_WEIGHT * (mid - c),
                               LINE_WEIGHT * np.array([line[0], line[2]]), MIDDLE_WEIGHT * (q - middle) / span))

    from dualarm_control.collision import CollisionModel

    collision = CollisionModel.shared(model, model.description.collision_allowed)
    rng = np.random.default_rng(seed)
    found_all: list[Ready] = []
    closest_refused: tuple[float, str] = (math.inf, "")
    for k in range(starts):
        q0 = middle if k == 0 else rng.uniform(lo, hi)
        rough = least_squares(residuals, q0, bounds=(lo, hi), xtol=1e-10, ftol=1e-10, max_nfev=300).x
        q = least_squares(lambda q: residuals(q)[:6], rough, bounds=(lo, hi), xtol=1e-14, ftol=1e-14,
                          gtol=1e-14, max_nfev=200).x  # the pose exactly, from the compromise
        o1, o2 = model.tool_poses(q)
        error = float(np.linalg.norm(pin.log6(target.actInv(o1.actInv(o2))).vector))
        if error > SOLVED:
            continue
        sigma = float(np.linalg.svd(model.relative_state(q).jacobian, compute_uv=False)[-1])
        margin_q = float(np.min(np.minimum(q - model.q_min, model.q_max - q)[finite] / span[finite])) \
            if finite.any() else 1.0
        pair = collision.closest(q) if collision.pairs else None
        near = (math.inf, "") if pair is None else (pair.distance, f"{pair.link_a} – {pair.link_b}")
        if near[0] < clearance:
            closest_refused = min(closest_refused, near)
            continue
        found_all.append(Ready(q, error, sigma, margin_q, 0.5 * (o1.translation + o2.translation), near))
    if not found_all:
        refused = (f" ({closest_refused[1]} at {closest_refused[0]:.3f} m was the clearest refused: under "
                   f"{clearance} m)" if math.isfinite(closest_refused[0]) else "")
        raise DualArmError(f"no ready configuration found with the tools {distance} m apart around {c.round(3)} "
                           f"in {starts} starts{refused}: try another --center or --distance")
    floor = 0.5 * max(r.sigma_min for r in found_all)
    return max((r for r in found_all if r.sigma_min >= floor), key=lambda r: r.limit_margin)
