"""Relative goal and twist commands, validated (pure functions, no ROS).

A command asks the online generator (:mod:`dualarm_control.online_trajectory`) to move the
right tool (F2) relative to the left tool (F1): a **goal** pose ``(p_g [m], R_g)`` to reach
at rest, or a **twist** ``(v [m/s], w [rad/s])`` to follow (jogging). Both are expressed in
F1. The checks below turn raw numbers into a :class:`GoalCommand` / :class:`TwistCommand`
or raise :class:`CommandError` whose message is the reason given back to the user (on
``/diagnostics`` and in the log). A refused command changes nothing in the generator.

Checks (in this order):

1. **frame**: only ``left_tool`` (F1) is accepted. The empty frame id is read as
   ``left_tool`` too: it is what ``ros2 topic pub`` sends when the header is left out, and
   the relative pose has no other sensible default frame. Any other name is refused (no tf
   lookup in this package).
2. **finite values**: NaN or inf anywhere is refused.
3. **quaternion norm** (goals given as ``(x, y, z, w)``): ``| ||q|| - 1 | <=``
   :data:`QUATERNION_NORM_TOLERANCE` (0.01) is normalised silently (a quaternion typed with
   4 decimals is off by about 1e-4); farther from unit norm is refused.
4. **reach** (goals): ``||p_g|| <= reach`` [m], with ``reach`` the bound of
   :meth:`dualarm_control.kinematics.DualArmModel.relative_reach` (2.870 m for the cell's
   URDF: the two first joints 0.628 m apart plus the two chains' link offsets 1.101 m and
   1.141 m, triangle inequality). A goal farther than that cannot be reached by any
   configuration. (Goals inside it may still be out of reach because of joint limits: the
   node reports those as ``stalled``, not here.)
5. **stamp**: a command stamped [s] earlier than the last accepted command is refused (an
   older command reordered by the network must not undo a newer one); an equal stamp is
   accepted (a tool that does not stamp sends the same zero). ``None`` skips the check.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from dualarm_control.arrays import FloatArray
from dualarm_control.errors import DualArmError
from dualarm_control.kinematics import LEFT_TOOL

QUATERNION_NORM_TOLERANCE = 0.01
"""Largest ``| ||q|| - 1 |`` normalised silently; a quaternion farther from unit norm is refused."""

ACCEPTED_FRAMES = (LEFT_TOOL, "")
"""Frame ids a command may carry: F1 (``left_tool``), or empty (read as ``left_tool``)."""
ABSOLUTE_FRAMES = ("world", "")
"""Frame ids an absolute command (the absolute frame's pose or twist, issue 41) may carry: the cell's ``world``,
or empty (read as ``world``)."""


class CommandError(DualArmError, ValueError):
    """A command is refused; the message is the reason."""


@dataclass(frozen=True, eq=False)
class GoalCommand:
    """A validated goal: F2's pose in F1 to reach at rest.

    Attributes:
        position: p_g [m], (3,).
        rotation: R_g, (3, 3), orthonormal.
        stamp: command stamp [s] (None: not stamped).
    """

    position: FloatArray
    rotation: FloatArray
    stamp: float | None = None


@dataclass(frozen=True, eq=False)
class TwistCommand:
    """A validated twist of F2 relative to F1, expressed in F1.

    Attributes:
        linear: v [m/s], (3,).
        angular: w [rad/s], (3,).
        stamp: command stamp [s] (None: not stamped).
    """

    linear: FloatArray
    angular: FloatArray
    stamp: float | None = None


def check_frame(frame: str, accepted: tuple[str, ...] = ACCEPTED_FRAMES) -> None:
    """Refuse any frame but ``accepted``'s (by default ``left_tool``, or the empty frame id read as ``left_tool``)."""
    if frame not in accepted:
        where = f"{LEFT_TOOL!r} (F1)" if accepted == ACCEPTED_FRAMES else repr(accepted[0])
        raise CommandError(f"unknown frame {frame!r}: commands are expressed in {where}")


def finite_vector(values: object, size: int, what: str) -> FloatArray:
    """``values`` as a float array of shape (size,), or CommandError (wrong shape, NaN, inf)."""
    try:
        arr = np.array(values, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise CommandError(f"{what}: expected {size} numbers, got {values!r}") from None
    if arr.shape != (size,):
        raise CommandError(f"{what}: expected {size} numbers, got {arr.size}")
    if not np.all(np.isfinite(arr)):
        raise CommandError(f"{what} contains NaN or inf: {arr.tolist()}")
    return arr


def rotation_from_quaternion(xyzw: object) -> FloatArray:
    """Rotation matrix (3, 3) of a quaternion ``(x, y, z, w)`` within the norm tolerance.

    Raises:
        CommandError: NaN/inf, or ``| ||q|| - 1 | >`` :data:`QUATERNION_NORM_TOLERANCE`.
    """
    q = finite_vector(xyzw, 4, "quaternion")
    norm = float(np.linalg.norm(q))
    if abs(norm - 1.0) > QUATERNION_NORM_TOLERANCE:
        raise CommandError(f"quaternion norm {norm:.6g} is not 1 (tolerance {QUATERNION_NORM_TOLERANCE:g}); "
                           "give a unit quaternion (x, y, z, w)")
    x, y, z, w = q / norm
    return np.asarray(pin.Quaternion(w, x, y, z).toRotationMatrix(), dtype=float)


def rotation_from_rpy(rpy: object) -> FloatArray:
    """Rotation matrix (3, 3) ``Rz(yaw) Ry(pitch) Rx(roll)`` of ``(roll, pitch, yaw)`` [rad]
    (the URDF / ROS convention, fixed axes x, y, z). Only an input format: motions never
    interpolate these angles."""
    r = finite_vector(rpy, 3, "rpy")
    return np.asarray(pin.rpy.rpyToMatrix(float(r[0]), float(r[1]), float(r[2])), dtype=float)


def check_stamp(stamp: float | None, last_accepted: float | None) -> None:
    """Refuse a stamp [s] earlier than the last accepted one (None on either side: no check)."""
    if stamp is None or last_accepted is None:
        return
    if not math.isfinite(stamp):
        raise CommandError(f"stamp {stamp!r} is not finite")
    if stamp < last_accepted:
        raise CommandError(f"stamp {stamp:.9f} s is older than the last accepted command's {last_accepted:.9f} s")


def goal_command(position: object, orientation: object, *, frame: str = LEFT_TOOL, stamp: float | None = None,
                 last_stamp: float | None = None, reach: float = math.inf,
                 accepted: tuple[str, ...] = ACCEPTED_FRAMES) -> GoalCommand:
    """Validate a goal pose.

    Args:
        position: p_g [m] in F1, 3 numbers.
        orientation: a quaternion ``(x, y, z, w)`` (4 numbers) or a rotation matrix (3, 3)
            (orthonormal to 1e-6, det > 0).
        frame: the command's frame id (``left_tool`` or empty).
        stamp: its stamp [s] (None: not stamped).
        last_stamp: the last accepted command's stamp [s] (None: none yet).
        reach: largest accepted ``||p_g||`` [m] (``DualArmModel.relative_reach()``).
        accepted: the frame ids accepted (:data:`ABSOLUTE_FRAMES` for the absolute frame's goals).

    Raises:
        CommandError: the reason (see the module docstring for the order of the checks).
    """
    check_frame(frame, accepted)
    p = finite_vector(position, 3, "goal position")
    arr = np.array(orientation, dtype=float) if not isinstance(orientation, str) else np.array([])
    if arr.shape == (3, 3):
        if not np.all(np.isfinite(arr)):
            raise CommandError(f"goal rotation contains NaN or inf: {arr.tolist()}")
        ortho = float(np.max(np.abs(arr.T @ arr - np.eye(3))))
        if ortho > 1e-6 or np.linalg.det(arr) <= 0.0:
            raise CommandError(f"goal rotation is not a rotation matrix (max |R^T R - I| = {ortho:.3g})")
        rotation = arr
    else:
        rotation = rotation_from_quaternion(orientation)
    distance = float(np.linalg.norm(p))
    if distance > reach:
        raise CommandError(f"goal position {distance:.3f} m from the left tool is beyond the arms' reach "
                           f"{reach:.3f} m")
    check_stamp(stamp, last_stamp)
    return GoalCommand(position=p, rotation=rotation, stamp=stamp)


def twist_command(linear: object, angular: object, *, frame: str = LEFT_TOOL, stamp: float | None = None,
                  last_stamp: float | None = None, accepted: tuple[str, ...] = ACCEPTED_FRAMES) -> TwistCommand:
    """Validate a twist (v [m/s], w [rad/s], in F1); CommandError with the reason otherwise.

    A twist beyond the motion limits is not refused here: the generator follows it clipped
    to the limits (see :meth:`OnlineTrajectory.command_twist`).
    """
    check_frame(frame, accepted)
    v = finite_vector(linear, 3, "twist linear")
    w = finite_vector(angular, 3, "twist angular")
    check_stamp(stamp, last_stamp)
    return TwistCommand(linear=v, angular=w, stamp=stamp)
