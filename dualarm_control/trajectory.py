"""Desired relative pose and twist from a chain of jerk-limited segments (ruckig).

The controller tracks the pose of the right tool (peg, frame F2) in the left tool frame F1.
This module generates, for every control period, the desired relative pose
``x* = (p*, R*)`` and the desired relative twist ``x*' = [v*; w*]``, all expressed in F1
(positions in m, velocities in m/s and rad/s). The paper used Reflexxes; ruckig is used here.

Each :class:`Segment` moves from the previous segment's end pose ``(p_A, R_A)`` to
``(p_B, R_B)`` with ``R_B = exp(angle * axis) @ R_A``: the orientation turns about an axis
that is fixed in F1 for the whole segment, by an angle of any magnitude (a screwing turn of
more than 2*pi is fine; this is not Euler-angle interpolation). The segment has four
coordinates, ``q = [p_x, p_y, p_z, s]`` going from ``[p_A, 0]`` to ``[p_B, angle]``, with
per-coordinate limits (linear limits per position axis, angular limits on the angle ``s``).

The motion is phase-synchronized: all four coordinates follow one jerk-limited, rest-to-rest
(zero velocity and acceleration at both ends) profile, so the position moves on the straight
line from p_A to p_B and the angle progresses in step with it. It is computed offline, at
construction, by ruckig on one scalar path parameter ``sigma: 0 -> L`` [s], with
``q(t) = q_A + c * sigma(t)``, ``c = (q_B - q_A) / L`` and ``L = max_i |q_B,i - q_A,i| / vmax_i``.
The path-parameter limits are the tightest of ``limit_i / |c_i|`` over the moving coordinates,
so every coordinate respects its own limits and the slowest one is time-optimal. This is the
profile ruckig's ``Synchronization.Phase`` gives on the 4-DoF problem when it succeeds; that
mode however silently falls back to ``Synchronization.Time`` for some limit/displacement
combinations (a few percent of random segments with the default limits, e.g. a 5 cm move
with a 0.5 rad turn), which leaves the straight line, so the scalar formulation is used
throughout; it is at most slightly slower than time synchronization in those cases.

At time ``t`` within a segment:

* ``p(t) = p_A + c_p sigma(t)`` and ``v(t) = c_p sigma'(t)``;
* ``R(t) = exp(s(t) * axis) @ R_A`` with ``s = c_s sigma``, and ``w(t) = axis * s'(t)``
  (angular velocity in F1);
* accelerations ``c_p sigma''(t)`` and ``axis * c_s sigma''(t)`` are reported as well.

After the motion the segment may dwell (``hold`` seconds) at its exact end pose with zero
twist. Segment end poses are computed exactly from the segment data, not from sampling, so
there is no drift along a chain. Ruckig may execute a vanishingly small displacement (far
below a picometre) in zero time: the sample then steps to the exact end pose.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Sequence
from dataclasses import dataclass, fields

import numpy as np
import pinocchio as pin
import ruckig

from dualarm_control.arrays import FloatArray
from dualarm_control.errors import DimensionError, DualArmError, ParameterError

_Z_AXIS = (0.0, 0.0, 1.0)
_ROTATION_TOLERANCE = 1e-6  # max |R^T R - I| entry accepted for a rotation matrix
_ZERO_ANGLE = 1e-12  # rad: Segment.to_pose treats smaller rotations as none


class TrajectoryError(DualArmError, RuntimeError):
    """Ruckig could not compute a segment (the message names the segment and the result)."""


def _frozen_vector(value: object, what: str) -> FloatArray:
    """Return ``value`` as a read-only finite float array of shape (3,)."""
    arr = np.array(value, dtype=float)
    if arr.shape != (3,):
        raise DimensionError(f"{what}: expected shape (3,), got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{what}: expected finite values, got {arr.tolist()}")
    arr.setflags(write=False)
    return arr


def _check_rotation(value: object, what: str) -> FloatArray:
    """Return ``value`` as a (3, 3) float rotation matrix, or raise a ValueError."""
    arr = np.array(value, dtype=float)
    if arr.shape != (3, 3):
        raise DimensionError(f"{what}: expected shape (3, 3), got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{what}: expected finite values")
    ortho = np.max(np.abs(arr.T @ arr - np.eye(3)))
    if ortho > _ROTATION_TOLERANCE or np.linalg.det(arr) <= 0.0:
        raise ValueError(
            f"{what}: not a rotation matrix (max |R^T R - I| = {ortho:.3g}, det = {np.linalg.det(arr):.6g})"
        )
    return arr


def _finite_float(value: object, what: str) -> float:
    """Return ``value`` as a finite float, or raise a ValueError naming ``what``."""
    try:
        out = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise ValueError(f"{what}: expected a finite number, got {value!r}") from None
    if isinstance(value, bool) or not math.isfinite(out):
        raise ValueError(f"{what}: expected a finite number, got {value!r}")
    return out


def rotation_about(axis: FloatArray, angle: float) -> FloatArray:
    """Rotation matrix exp(angle * [axis]x) [-], for a unit ``axis`` (3,) and ``angle`` [rad]."""
    return np.asarray(pin.exp3(np.asarray(axis, dtype=float) * float(angle)))


@dataclass(frozen=True)
class MotionLimits:
    """Kinematic limits of the relative motion.

    Linear limits apply to each position coordinate of F2's origin in F1 separately (per
    axis, not to the norm). Angular limits apply to the scalar angle about the segment's
    axis, i.e. to the norm of the angular velocity / acceleration / jerk.

    All values must be finite and > 0; otherwise :class:`~dualarm_control.errors.ParameterError`
    (a ValueError) is raised, naming the field and the value.
    """

    max_linear_velocity: float = 0.05  # m/s per axis
    max_linear_acceleration: float = 0.2  # m/s^2 per axis
    max_linear_jerk: float = 1.0  # m/s^3 per axis
    max_angular_velocity: float = 0.5  # rad/s
    max_angular_acceleration: float = 1.0  # rad/s^2
    max_angular_jerk: float = 5.0  # rad/s^3

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            try:
                number = float(value)
            except (TypeError, ValueError):
                raise ParameterError(f.name, value, "a finite number > 0") from None
            if isinstance(value, bool) or not math.isfinite(number) or number <= 0.0:
                raise ParameterError(f.name, value, "a finite number > 0")
            object.__setattr__(self, f.name, number)


@dataclass(frozen=True, eq=False)
class Segment:
    """One motion from the previous segment's end pose ``(p_A, R_A)``, then an optional dwell.

    Attributes:
        name: label reported in :class:`TargetSample` (e.g. ``"approach"``).
        position: end position ``p_B`` of F2's origin in F1 [m], (3,), read-only.
        axis: unit rotation axis expressed in F1, fixed during the segment, (3,), read-only.
            A non-unit axis is normalized; a zero axis is only accepted with ``angle == 0``
            (it is then replaced by z).
        angle: rotation [rad] about ``axis``, any sign and magnitude (> pi allowed). The end
            orientation is ``R_B = exp(angle * axis) @ R_A``.
        hold: dwell [s] at the end pose, with zero twist, after the motion (>= 0).
    """

    name: str
    position: FloatArray
    axis: FloatArray
    angle: float
    hold: float = 0.0

    def __post_init__(self) -> None:
        what = f"segment {self.name!r}"
        object.__setattr__(self, "position", _frozen_vector(self.position, f"{what} position"))
        angle = _finite_float(self.angle, f"{what} angle")
        hold = _finite_float(self.hold, f"{what} hold")
        if hold < 0.0:
            raise ValueError(f"{what} hold: expected a duration >= 0 s, got {self.hold!r}")
        axis = np.array(_frozen_vector(self.axis, f"{what} axis"))
        norm = float(np.linalg.norm(axis))
        if norm < 1e-12:
            if angle != 0.0:
                raise ValueError(f"{what} axis: zero axis with a nonzero angle {angle!r}")
            axis = np.array(_Z_AXIS)
        else:
            axis = axis / norm
        axis.setflags(write=False)
        object.__setattr__(self, "axis", axis)
        object.__setattr__(self, "angle", angle)
        object.__setattr__(self, "hold", hold)

    @staticmethod
    def to_pose(
        name: str,
        start_rotation: FloatArray,
        position: FloatArray,
        rotation: FloatArray,
        hold: float = 0.0,
    ) -> Segment:
        """Segment to the pose ``(position, rotation)`` along the shortest rotation.

        Args:
            name: segment label.
            start_rotation: orientation R_A at the start of this segment (the previous
                segment's end orientation), (3, 3).
            position: end position [m] in F1, (3,).
            rotation: end orientation R_B in F1, (3, 3).
            hold: dwell [s] at the end pose.

        Returns:
            A segment whose axis/angle is ``pinocchio.log3(R_B @ R_A^T)`` (angle in [0, pi]);
            an angle below 1e-12 rad (round-off) is set to exactly 0, with the axis z.
        """
        r_a = _check_rotation(start_rotation, f"segment {name!r} start_rotation")
        r_b = _check_rotation(rotation, f"segment {name!r} rotation")
        rotvec = np.asarray(pin.log3(r_b @ r_a.T))
        angle = float(np.linalg.norm(rotvec))
        if angle < _ZERO_ANGLE:  # round-off of R @ R^T: no rotation, no ruckig sub-problem
            return Segment(name=name, position=position, axis=np.array(_Z_AXIS), angle=0.0, hold=hold)
        axis = rotvec / angle
        return Segment(name=name, position=position, axis=axis, angle=angle, hold=hold)

    @staticmethod
    def screw(
        name: str,
        start_position: FloatArray,
        axis: FloatArray,
        angle: float,
        advance: float,
        hold: float = 0.0,
    ) -> Segment:
        """Screwing segment: turn the orientation by ``angle`` about ``axis``, advance along it.

        The rotation is of the frame orientation (``R_B = exp(angle * axis) @ R_A``); the
        position moves along the (normalized) axis: ``p_B = start_position + advance * axis``.

        Args:
            name: segment label.
            start_position: p_A [m] in F1, (3,) (the previous segment's end position).
            axis: screw axis in F1, (3,), normalized here.
            angle: rotation [rad], any magnitude (e.g. ``2 * pi + 0.5``).
            advance: signed displacement [m] along ``axis``.
            hold: dwell [s] at the end pose.
        """
        p_a = _frozen_vector(start_position, f"segment {name!r} start_position")
        u = np.array(_frozen_vector(axis, f"segment {name!r} axis"))
        norm = float(np.linalg.norm(u))
        if norm < 1e-12:
            raise ValueError(f"segment {name!r} axis: a screw needs a nonzero axis, got {u.tolist()}")
        u = u / norm
        advance = _finite_float(advance, f"segment {name!r} advance")
        return Segment(name=name, position=p_a + advance * u, axis=u, angle=angle, hold=hold)


@dataclass(frozen=True, eq=False)
class TargetSample:
    """Desired relative state at one time, all vectors expressed in F1.

    Attributes:
        time: trajectory time t [s] that was sampled.
        position: p* [m], (3,).
        rotation: R*, (3, 3).
        linear_velocity: v* = dp*/dt [m/s], (3,).
        angular_velocity: w* [rad/s], (3,), with dR*/dt = [w*]x R*.
        segment: index of the active segment (the last one once done).
        segment_name: its name.
        done: True for t >= duration (end pose, zero twist).
        linear_acceleration: dv*/dt [m/s^2], (3,).
        angular_acceleration: dw*/dt [rad/s^2], (3,).
    """

    time: float
    position: FloatArray
    rotation: FloatArray
    linear_velocity: FloatArray
    angular_velocity: FloatArray
    segment: int
    segment_name: str
    done: bool
    linear_acceleration: FloatArray
    angular_acceleration: FloatArray

    @property
    def twist(self) -> FloatArray:
        """Desired twist ``[v*; w*]`` (m/s; rad/s), (6,)."""
        return np.concatenate((self.linear_velocity, self.angular_velocity))


@dataclass(frozen=True)
class _Plan:
    """Internal: one computed segment."""

    segment: Segment
    start_time: float  # s
    motion_duration: float  # s, ruckig's duration (0 for a zero motion)
    start_position: FloatArray
    start_rotation: FloatArray
    end_position: FloatArray
    end_rotation: FloatArray
    trajectory: ruckig.Trajectory | None  # of the path parameter sigma [s]; None for a zero motion
    rates: FloatArray  # (4,) dq/dsigma: m/s (position axes), rad/s (angle)


def _solve_segment(
    index: int, segment: Segment, p_a: FloatArray, limits: MotionLimits
) -> tuple[ruckig.Trajectory | None, FloatArray]:
    """Time-optimal, phase-synchronized profile of one segment (see the module docstring).

    Returns:
        The 1-DoF ruckig trajectory of the path parameter sigma: 0 -> L [s] (None if there is
        no motion, or one too small to represent), and the (4,) coordinate rates ``c``
        (m/s, m/s, m/s, rad/s) with ``q(t) = q_A + c * sigma(t)``.

    Raises:
        TrajectoryError: ruckig failed (the message names the segment and the result).
    """
    delta = np.concatenate((segment.position - p_a, [segment.angle]))
    moving = delta != 0.0
    vmax = np.array([limits.max_linear_velocity] * 3 + [limits.max_angular_velocity])
    amax = np.array([limits.max_linear_acceleration] * 3 + [limits.max_angular_acceleration])
    jmax = np.array([limits.max_linear_jerk] * 3 + [limits.max_angular_jerk])
    if not np.any(moving):
        return None, np.zeros(4)
    length = float(np.max(np.abs(delta[moving]) / vmax[moving]))  # s at full speed
    if not length > 0.0:  # underflow of a subnormal displacement
        return None, np.zeros(4)
    rates = delta / length
    inp = ruckig.InputParameter(1)
    inp.current_position = [0.0]
    inp.current_velocity = [0.0]
    inp.current_acceleration = [0.0]
    inp.target_position = [length]
    inp.target_velocity = [0.0]
    inp.target_acceleration = [0.0]
    speed = np.abs(rates[moving])
    # An axis with a subnormal displacement has a subnormal (or zero) speed and its ratio is inf;
    # the dominant axis's ratio (speed = vmax there) is finite and <= it, so the minima are right.
    with np.errstate(over="ignore", divide="ignore"):
        inp.max_velocity = [float(np.min(vmax[moving] / speed))]
        inp.max_acceleration = [float(np.min(amax[moving] / speed))]
        inp.max_jerk = [float(np.min(jmax[moving] / speed))]
    traj = ruckig.Trajectory(1)
    try:
        result = ruckig.Ruckig(1).calculate(inp, traj)
    except ruckig.RuckigError as exc:  # invalid input is raised, not returned
        detail = " ".join(str(exc).split())
    else:
        if result in (ruckig.Result.Working, ruckig.Result.Finished) and math.isfinite(traj.duration):
            return traj, rates
        detail = result.name
    raise TrajectoryError(
        f"segment {index} {segment.name!r}: ruckig failed from {p_a.tolist()} to "
        f"{segment.position.tolist()} / angle {segment.angle!r} rad ({detail})"
    )


class RelativeTrajectory:
    """Chain of segments, all computed offline at construction; sampling is a pure function of t.

    Args:
        start_position: p_A of the first segment [m] in F1, (3,).
        start_rotation: R_A of the first segment in F1, (3, 3) (orthonormality checked to 1e-6).
        segments: at least one :class:`Segment`; segment k starts at segment k-1's end pose.
        limits: kinematic limits shared by all segments.

    Attributes:
        duration: total duration [s], motions and holds.
        segment_start_times: start time [s] of each segment (its motion, then its hold).
        segment_motion_durations: ruckig duration [s] of each segment's motion (hold excluded).
        segments: the segments, as a tuple.
        limits: the limits.

    Raises:
        ValueError: no segment, or a malformed start pose.
        TrajectoryError: ruckig failed on a segment.
    """

    def __init__(
        self,
        start_position: FloatArray,
        start_rotation: FloatArray,
        segments: Sequence[Segment],
        limits: MotionLimits | None = None,
    ) -> None:
        self.limits = limits if limits is not None else MotionLimits()
        self.segments: tuple[Segment, ...] = tuple(segments)
        if not self.segments:
            raise ValueError("RelativeTrajectory needs at least one segment")
        for k, seg in enumerate(self.segments):
            if not isinstance(seg, Segment):
                raise TypeError(f"segments[{k}]: expected a Segment, got {type(seg).__name__}")
        p_a = _frozen_vector(start_position, "start_position")
        r_a = _check_rotation(start_rotation, "start_rotation")
        r_a.setflags(write=False)
        self._plans: list[_Plan] = []
        t0 = 0.0
        for k, seg in enumerate(self.segments):
            traj, rates = _solve_segment(k, seg, p_a, self.limits)
            motion = float(traj.duration) if traj is not None else 0.0
            r_b = rotation_about(seg.axis, seg.angle) @ r_a
            r_b.setflags(write=False)
            self._plans.append(_Plan(seg, t0, motion, p_a, r_a, seg.position, r_b, traj, rates))
            t0 = t0 + motion + seg.hold
            p_a, r_a = seg.position, r_b
        self.duration: float = t0
        self._start_times: tuple[float, ...] = tuple(plan.start_time for plan in self._plans)
        self.segment_start_times: list[float] = list(self._start_times)
        self.segment_motion_durations: list[float] = [plan.motion_duration for plan in self._plans]

    @property
    def start_position(self) -> FloatArray:
        """Start position [m] in F1, (3,) (copy)."""
        return self._plans[0].start_position.copy()

    @property
    def start_rotation(self) -> FloatArray:
        """Start orientation in F1, (3, 3) (copy)."""
        return self._plans[0].start_rotation.copy()

    @property
    def end_position(self) -> FloatArray:
        """Final position [m] in F1, (3,) (copy)."""
        return self._plans[-1].end_position.copy()

    @property
    def end_rotation(self) -> FloatArray:
        """Final orientation in F1, exactly the chained ``exp(angle_k axis_k)`` product, (3, 3)."""
        return self._plans[-1].end_rotation.copy()

    def segment_end_pose(self, k: int) -> tuple[FloatArray, FloatArray]:
        """Exact end pose ``(p_B [m], R_B)`` of segment ``k`` (copies)."""
        plan = self._plans[k]
        return plan.end_position.copy(), plan.end_rotation.copy()

    def sample(self, t: float) -> TargetSample:
        """Desired relative pose, twist and acceleration at time ``t`` [s].

        ``t < 0`` gives the start pose with zero twist (segment 0, not done); ``t >= duration``
        gives the exact end pose with zero twist and ``done=True``. Arrays are fresh copies.
        """
        t = _finite_float(t, "sample time t")
        if t < 0.0:
            plan = self._plans[0]
            return self._rest(t, 0, plan.start_position, plan.start_rotation, done=False)
        if t >= self.duration:
            k = len(self._plans) - 1
            plan = self._plans[k]
            return self._rest(t, k, plan.end_position, plan.end_rotation, done=True)
        k = bisect.bisect_right(self._start_times, t) - 1
        plan = self._plans[k]
        tau = t - plan.start_time
        if plan.trajectory is None or tau >= plan.motion_duration:
            return self._rest(t, k, plan.end_position, plan.end_rotation, done=False)
        (sigma,), (dsigma,), (ddsigma,) = plan.trajectory.at_time(tau)
        c_p, c_s = plan.rates[:3], float(plan.rates[3])
        axis = plan.segment.axis
        rotation = rotation_about(axis, c_s * sigma) @ plan.start_rotation
        return TargetSample(
            time=t,
            position=plan.start_position + c_p * sigma,
            rotation=rotation,
            linear_velocity=c_p * dsigma,
            angular_velocity=axis * (c_s * dsigma),
            segment=k,
            segment_name=plan.segment.name,
            done=False,
            linear_acceleration=c_p * ddsigma,
            angular_acceleration=axis * (c_s * ddsigma),
        )

    def _rest(self, t: float, k: int, position: FloatArray, rotation: FloatArray, *, done: bool) -> TargetSample:
        """Sample at rest at ``(position, rotation)``."""
        return TargetSample(
            time=t,
            position=position.copy(),
            rotation=rotation.copy(),
            linear_velocity=np.zeros(3),
            angular_velocity=np.zeros(3),
            segment=k,
            segment_name=self._plans[k].segment.name,
            done=done,
            linear_acceleration=np.zeros(3),
            angular_acceleration=np.zeros(3),
        )
