"""Joint-space trajectory through planned configurations (the executable form of a plan).

The planned configurations q_1..q_h (paper 003 gives geometry only, "without defining the
motion over time", Sect. III-A) are joined by a C2 cubic spline ``Q(s)`` in joint space,
parametrised by the arc length ``s`` [m] of the relative path at the samples (chord
lengths between consecutive sample positions), so that ``Q(s_i) = q_i`` exactly. The motion
law is one jerk-limited, rest-to-rest ruckig profile of the scalar ``s: 0 -> L``, as in
:mod:`dualarm_control.trajectory`:

* ``q(t) = Q(s(t))``, ``qd(t) = Q'(s) s'(t)``, ``qdd(t) = Q''(s) s'^2 + Q'(s) s''``;
* limits on s are the relative-motion limits (defaults of
  :class:`~dualarm_control.trajectory.MotionLimits`: 0.05 m/s, 0.2 m/s^2, 1 m/s^3), with the
  velocity limit further reduced so that no joint exceeds ``velocity_scale`` times its
  velocity limit anywhere on the spline (checked on a dense grid of s).

Between knots the relative pose follows the spline, not exactly the path. The plan's
consecutive configurations can differ by tenths of a radian (the optimiser uses the
redundancy between samples 1 cm apart), which puts a spline through them only ~2 mm from
the path; :func:`densify` therefore inserts closure-satisfying knots between the planned
ones (joint-space interpolation projected onto the chord between the two samples, eq 17),
which keeps every planned configuration as a knot.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import ruckig

from dualarm_control.kinematics import DualArmModel, FloatArray
from dualarm_control.planning.global_opt import project_to_pose
from dualarm_control.planning.path import SampledPath
from dualarm_control.trajectory import MotionLimits, TrajectoryError

_GRID_PER_INTERVAL = 50  # dense check of |Q'(s)| per spline interval


def densify(
    model: DualArmModel, path: SampledPath, configurations: FloatArray, subdivisions: int
) -> tuple[FloatArray, FloatArray]:
    """Insert ``subdivisions - 1`` knots between consecutive planned configurations.

    Knot k of interval i sits at ``s = k / subdivisions`` on the chord between samples i and
    i + 1; its configuration is the linear joint interpolation projected onto that pose
    (:func:`~dualarm_control.planning.global_opt.project_to_pose`, warm-started from the
    previous knot's projection offset). Returns (configurations, positions) of all knots,
    ((h - 1) * subdivisions + 1, 14) and (..., 3); the planned ones are every
    ``subdivisions``-th knot, unchanged.

    Raises:
        RuntimeError: a projection failed.
    """
    qs = np.asarray(configurations, dtype=float)
    out_q, out_p = [qs[0]], [path.positions[0]]
    for i in range(len(qs) - 1):
        for k in range(1, subdivisions):
            s = k / subdivisions
            position = (1.0 - s) * path.positions[i] + s * path.positions[i + 1]
            guess = (1.0 - s) * qs[i] + s * qs[i + 1]
            q = project_to_pose(model, guess, position, path.rotation)
            if q is None:
                raise RuntimeError(f"densify: no configuration on the chord between samples {i + 1} and {i + 2}")
            out_q.append(q)
            out_p.append(position)
        out_q.append(qs[i + 1])
        out_p.append(path.positions[i + 1])
    return np.array(out_q), np.array(out_p)


@dataclass(frozen=True)
class JointTarget:
    """Reference joint state at one time.

    Attributes:
        time: t [s].
        positions: q(t) [rad], (n,).
        velocities: qd(t) [rad/s], (n,).
        accelerations: qdd(t) [rad/s^2], (n,).
        path_parameter: s(t) [m].
        done: t >= duration.
    """

    time: float
    positions: FloatArray
    velocities: FloatArray
    accelerations: FloatArray
    path_parameter: float
    done: bool


class JointPathTrajectory:
    """Ruckig motion along a joint-space cubic spline through ``configurations``.

    Args:
        configurations: knot configurations q_i, (h, n) [rad], h >= 2.
        sample_positions: relative positions of the knots [m], (h, 3) (chord-length parameter).
        velocity_limits: joint velocity limits [rad/s], (n,).
        limits: relative-motion limits for s (linear fields used).
        velocity_scale: share of the joint velocity limits the reference may use, in (0, 1].

    Attributes:
        duration: total duration [s].
        knots: s_i [m], (h,).
        sample_times: t_i at which q(t_i) = q_i [s], (h,), one per knot.
    """

    def __init__(
        self,
        configurations: FloatArray,
        sample_positions: FloatArray,
        velocity_limits: FloatArray,
        limits: MotionLimits | None = None,
        velocity_scale: float = 0.5,
    ) -> None:
        qs = np.asarray(configurations, dtype=float)
        ps = np.asarray(sample_positions, dtype=float)
        if qs.ndim != 2 or qs.shape[0] < 2 or ps.shape != (qs.shape[0], 3):
            raise ValueError(f"need (h, n) configurations and (h, 3) positions with h >= 2; got {qs.shape}, {ps.shape}")
        if not 0.0 < velocity_scale <= 1.0:
            raise ValueError(f"velocity_scale must be in (0, 1], got {velocity_scale}")
        self.limits = limits or MotionLimits()
        chords = np.linalg.norm(np.diff(ps, axis=0), axis=1)
        if np.any(chords <= 0.0):
            raise ValueError("consecutive sample positions must differ")
        self.knots: FloatArray = np.concatenate(([0.0], np.cumsum(chords)))
        self.length = float(self.knots[-1])
        # imported here: scipy.interpolate would cost every node that never runs a plan 0.1-0.2 s to start
        from scipy.interpolate import CubicSpline

        self.spline = CubicSpline(self.knots, qs, axis=0)
        self._d1 = self.spline.derivative(1)
        self._d2 = self.spline.derivative(2)
        grid = np.linspace(0.0, self.length, _GRID_PER_INTERVAL * (len(self.knots) - 1) + 1)
        slope = np.max(np.abs(self._d1(grid)), axis=0)  # max |dq_j/ds| [rad/m]
        with np.errstate(divide="ignore"):
            joint_cap = np.where(slope > 0.0, velocity_scale * np.asarray(velocity_limits) / slope, np.inf)
        vmax = float(min(self.limits.max_linear_velocity, float(np.min(joint_cap))))
        inp = ruckig.InputParameter(1)
        inp.current_position, inp.current_velocity, inp.current_acceleration = [0.0], [0.0], [0.0]
        inp.target_position, inp.target_velocity, inp.target_acceleration = [self.length], [0.0], [0.0]
        inp.max_velocity = [vmax]
        inp.max_acceleration = [self.limits.max_linear_acceleration]
        inp.max_jerk = [self.limits.max_linear_jerk]
        traj = ruckig.Trajectory(1)
        result = ruckig.Ruckig(1).calculate(inp, traj)
        if result not in (ruckig.Result.Working, ruckig.Result.Finished) or not math.isfinite(traj.duration):
            raise TrajectoryError(f"ruckig failed on the joint path of length {self.length:.4g} m ({result.name})")
        self._traj = traj
        self.max_path_speed = vmax
        self.duration = float(traj.duration)
        times = []
        for s in self.knots:
            t = traj.get_first_time_at_position(0, float(s))
            times.append(self.duration if t is None else float(t))
        times[0] = 0.0
        self.sample_times: FloatArray = np.array(times)

    def sample(self, t: float) -> JointTarget:
        """Reference at time t [s]; before 0 the start at rest, after ``duration`` the end at rest."""
        if t <= 0.0:
            s, ds, dds = 0.0, 0.0, 0.0
        elif t >= self.duration:
            s, ds, dds = self.length, 0.0, 0.0
        else:
            (s,), (ds,), (dds,) = self._traj.at_time(t)
            s = min(max(s, 0.0), self.length)
        d1 = np.asarray(self._d1(s))
        return JointTarget(
            time=float(t),
            positions=np.asarray(self.spline(s)),
            velocities=d1 * ds,
            accelerations=np.asarray(self._d2(s)) * ds * ds + d1 * dds,
            path_parameter=float(s),
            done=t >= self.duration,
        )


def plan_trajectory(
    model: DualArmModel,
    path: SampledPath,
    configurations: FloatArray,
    subdivisions: int = 8,
    velocity_scale: float = 0.5,
    limits: MotionLimits | None = None,
) -> JointPathTrajectory:
    """The executable joint trajectory of a plan: :func:`densify` then :class:`JointPathTrajectory`.

    Args:
        model: the cell model (joint limits, kinematics for the densification).
        path: the sampled relative path the configurations were planned on.
        configurations: planned q_i, (h, 14) [rad], one per path sample.
        subdivisions: knots per path interval (1 = the planned configurations only).
        velocity_scale: share of the joint velocity limits the reference may use.
        limits: relative-motion limits of the path parameter.

    Returns:
        The trajectory; its knots ``subdivisions * i`` are the planned configurations.
    """
    knots, positions = densify(model, path, configurations, subdivisions)
    return JointPathTrajectory(knots, positions, model.qd_max, limits, velocity_scale)
