"""Online relative motion: goals and twists accepted at any cycle, replanned by ruckig.

Paper 000 generates the desired relative motion with Reflexxes, an *online* trajectory
generator: at every control cycle a new target may arrive and the motion is replanned from
the current position, velocity and acceleration, so the reference never jumps. This module
does that with ruckig's online interface (``Ruckig(dofs, T).update(input, output)``), for the
pose of the right tool (F2) in the left tool frame (F1). Units: m, rad, s; every vector in F1.

State (held by :class:`OnlineTrajectory`, advanced by one period ``T`` per :meth:`~OnlineTrajectory.step`):
``p, v, a`` (3,) [m, m/s, m/s^2] and ``R`` (3, 3), ``w, alpha`` (3,) [rad/s, rad/s^2] with
``dR/dt = [w]x R`` and ``alpha = dw/dt``.

**Position** (3 DoF, per axis limits of :class:`~dualarm_control.trajectory.MotionLimits`,
exactly as the offline segments): one persistent ruckig instance; a goal uses the position
interface (target ``p_g``, zero velocity and acceleration, ``Synchronization.Phase``: a
straight line when ruckig finds one), a twist the velocity interface (target ``v_cmd``);
``out.pass_to_input(inp)`` carries the state to the next cycle.

**Orientation** (no Euler angles): three rotation coordinates ``s`` (a rotation vector)
relative to an *anchor* re-taken at every cycle, ``R(t) = exp([s(t)]x) R_k`` with
``R_k = R(t_k)``, ``s(t_k) = 0``. With the left Jacobian of SO(3)
``J_l(s) = I + A [s]x + B [s]x^2``, ``A = (1 - cos th)/th^2``, ``B = (th - sin th)/th^3``,
``th = ||s||``:

    (1)  w = J_l(s) s'
    (2)  alpha = J_l(s) s'' + (dJ_l/dt) s'

and at ``s = 0``: ``J_l = I``, ``(dJ_l/dt) s' = 1/2 s' x s' = 0``, so ``s' = w`` and
``s'' = alpha`` exactly: the cycle's ruckig problem starts from the true angular state
(no jump, no flip at +-pi: the goal enters as ``s_g = log3(R_g R_k^T)``, angle in [0, pi]).
The three coordinates get per-coordinate limits in an orthonormal basis ``Q`` (columns):
``|(Q^T s')_i| <= b_i vmax``, same ``b`` for acceleration and jerk, with ``||b|| <= 1``, so

    (3)  ||s'|| <= vmax,  ||s''|| <= amax,  ||s'''|| <= jmax      (a box inside the ball).

``Q``'s first column is the motion's direction (the goal's rotation vector, the commanded
angular velocity), and ``b`` (:func:`~dualarm_control.online_rotation.rotation_box`) gives each
sideways coordinate the least share that holds its state (4)
(:func:`~dualarm_control.online_rotation.least_shares`: the speed it still reaches while its
acceleration falls to zero), the rest of the ball to the first. From rest, or whenever the
state is parallel to the direction, the sideways coordinates are at rest and ``b = (1, 0, 0)``:
the orientation turns about the goal axis with the full scalar limits, the first coordinate
time-optimal on its own (``Synchronization.No``): the profile of today's rest-to-rest segment
(:class:`~dualarm_control.trajectory.RelativeTrajectory`), so a goal from rest takes no
longer than the segment, +1 cycle (the online run ends on a cycle). When no box along the
direction holds the state (a preemption turning the axis while the motion accelerates
sideways), last cycle's box is kept until one does: ruckig put the state in that box, so it
holds it (a box that does not hold the state makes ruckig overshoot its velocity limit while
it brings the acceleration down: up to 1.4 % over ``vmax`` before this rule).

What is guaranteed for the angular motion (vmax, amax, jmax the angular limits):

* ``||w|| <= vmax`` always (up to rounding): each cycle's ruckig plan starts from a state its
  box holds (4), so ``||s'|| <= ||b|| vmax <= vmax``, and ``J_l(s)`` has singular values 1 and
  ``|sinc(th/2)| <= 1``.
* Motions whose ``w``, ``alpha`` and direction stay parallel (every goal or jog started from
  rest, or along the current motion's axis): ``s`` stays on a line through 0, ``J_l(s) s' = s'``
  and the curvature terms of (2) vanish: ``||alpha|| <= amax`` and ``||dalpha/dt|| <= jmax``
  exactly (up to rounding).
* Otherwise (a preemption turning the rotation axis) the curvature terms of (2) add to
  the box limits: ``||alpha|| <= amax + vmax^3 T / 3`` (the term of (2) after one cycle,
  ``||s|| <= vmax T``: 2e-4 rad/s^2 with the default limits at T = 5 ms), and each cycle's
  change ``||alpha_k+1 - alpha_k|| <= (jmax + vmax amax / 2 + vmax^3 / 3) T`` (from
  ``dalpha/dt = s''' + 1/2 s' x s'' + 1/3 s' x (s' x s')`` at ``s = 0``; +5.8 % of jmax with
  the defaults). A state outside every box (after a limit change) is first braked back by
  ruckig. Sideways coordinates that move get at least a 1e-3 share (ruckig refuses zero
  limits), counted in ``||b||``; those at rest get 1e-3 uncounted and a zero target: they
  move by rounding only.

Position and orientation are each time-optimal and not synchronized with each other, so a
goal from rest takes ``max(position time, rotation time)``, which is the duration of a
rest-to-rest segment (one scalar path parameter, the slowest coordinate time-optimal).

Twists (jogging) use ruckig's velocity interface toward ``(v_cmd, w_cmd)``, clipped to the
velocity limits (per axis for ``v``, the norm for ``w``). With no new twist for
``jog_timeout`` (0.1 s) the target velocity becomes zero: the motion brakes to rest within
the limits. A goal or a twist accepted mid-motion replaces the previous one from the
current state (preemption).

States (:data:`IDLE` at rest without a goal, :data:`MOVING` toward a goal, :data:`JOGGING`
following or braking from a twist, :data:`REACHED` at rest exactly on the last goal), with the
status keys that report them, in :mod:`dualarm_control.drive_status`; the rotation coordinates'
functions, (1)-(4), in :mod:`dualarm_control.online_rotation`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin
import ruckig

from dualarm_control.drive_commands import (
    ACCEPTED_FRAMES,
    CommandError,
    GoalCommand,
    TwistCommand,
    goal_command,
    twist_command,
)
from dualarm_control.drive_status import IDLE, JOGGING, MOVING, REACHED, GoalProgress
from dualarm_control.online_rotation import (
    _IDLE,
    _MIN_SHARE,
    _at_the_limit,
    angular_acceleration,
    angular_velocity,
    rotation_box,
)
from dualarm_control.trajectory import (
    FloatArray,
    MotionLimits,
    TargetSample,
    TrajectoryError,
    _check_rotation,
    _frozen_vector,
)

DEFAULT_PERIOD = 0.005  # s
DEFAULT_JOG_TIMEOUT = 0.1  # s
_SNAP = 1e-9  # m or rad: a remaining distance a near-rest state may snap over (see _near_rest)


@dataclass(frozen=True)
class CommandResult:
    """Answer to a command: accepted or not, and why (the reason of a refusal, or a note)."""

    accepted: bool
    reason: str = ""


class OnlineTrajectory:
    """The relative target, advanced one period per :meth:`step`, steered by goals and twists.

    Args:
        position: initial p [m] in F1, (3,) (the measured relative pose: hold it).
        rotation: initial R in F1, (3, 3).
        limits: motion limits (per axis linear, norm angular; see the module docstring).
        period: cycle T [s] (ruckig's control cycle).
        jog_timeout: seconds without a new twist after which a jog brakes to rest.
        reach: largest accepted ``||p_g||`` [m] of a goal (``DualArmModel.relative_reach()``:
            2.870 m for the cell).
        frames: the frame ids a command may carry (the absolute frame's generator, issue 41:
            :data:`~dualarm_control.drive_commands.ABSOLUTE_FRAMES`, its pose in the world).

    The generator is deterministic: its time is ``cycles * period``; commands apply from the
    next :meth:`step`.
    """

    def __init__(self, position: FloatArray, rotation: FloatArray, limits: MotionLimits | None = None,
                 period: float = DEFAULT_PERIOD, jog_timeout: float = DEFAULT_JOG_TIMEOUT,
                 reach: float = math.inf, frames: tuple[str, ...] = ACCEPTED_FRAMES) -> None:
        if not (math.isfinite(period) and period > 0.0):
            raise ValueError(f"period: expected a duration > 0 s, got {period!r}")
        if not (math.isfinite(jog_timeout) and jog_timeout > 0.0):
            raise ValueError(f"jog_timeout: expected a duration > 0 s, got {jog_timeout!r}")
        self.limits = limits if limits is not None else MotionLimits()
        self.period = float(period)
        self.jog_timeout = float(jog_timeout)
        self.reach = float(reach)
        self.frames = frames
        self.cycles = 0
        self.p = np.array(_frozen_vector(position, "position"))
        self.r = np.array(_check_rotation(rotation, "rotation"))
        self.v, self.a = np.zeros(3), np.zeros(3)
        self.w, self.alpha = np.zeros(3), np.zeros(3)
        self.state = IDLE
        self.goal: GoalCommand | None = None
        self.twist: TwistCommand | None = None
        self.last_stamp: float | None = None
        self.commands = 0  # accepted commands (TargetSample.segment)
        self._twist_time = 0.0  # generator time of the last twist [s]
        self._pos = ruckig.Ruckig(3, self.period)
        self._pin = ruckig.InputParameter(3)
        self._pout = ruckig.OutputParameter(3)
        self._rot = ruckig.Ruckig(3, self.period)
        self._rin = ruckig.InputParameter(3)
        self._rout = ruckig.OutputParameter(3)
        self._pos_done = self._rot_done = True
        self._pos_left = self._rot_left = 0.0  # s, time to go of each plan
        self._box: tuple[FloatArray, FloatArray] | None = None  # last cycle's rotation box (Q, b)
        self.set_limits(self.limits)
        self._reset_position_input()

    # ------------------------------------------------------------------ commands

    @property
    def time(self) -> float:
        """Generator time [s]: cycles done times the period."""
        return self.cycles * self.period

    def set_limits(self, limits: MotionLimits) -> None:
        """New limits from the next cycle (a state beyond them is braked back by ruckig)."""
        self.limits = limits
        self._pin.max_velocity = [limits.max_linear_velocity] * 3
        self._pin.max_acceleration = [limits.max_linear_acceleration] * 3
        self._pin.max_jerk = [limits.max_linear_jerk] * 3

    def command_goal(self, position: object, orientation: object, *, frame: str | None = None,
                     stamp: float | None = None) -> CommandResult:
        """Go to the pose ``(position [m], orientation)`` in F1 and stop there.

        ``orientation``: quaternion ``(x, y, z, w)`` or rotation matrix (3, 3). Refused (with the
        reason, motion unchanged) per :func:`dualarm_control.drive_commands.goal_command`.
        """
        try:
            goal = goal_command(position, orientation, frame=self.frames[0] if frame is None else frame, stamp=stamp,
                                last_stamp=self.last_stamp, reach=self.reach, accepted=self.frames)
        except CommandError as exc:
            return CommandResult(False, str(exc))
        note = "preempts the current motion" if self.state in (MOVING, JOGGING) else ""
        self._accept(stamp)
        self.goal, self.twist = goal, None
        self.state = MOVING
        self._pin.control_interface = ruckig.ControlInterface.Position
        self._pin.synchronization = ruckig.Synchronization.Phase
        self._pin.target_position = goal.position.tolist()
        self._pin.target_velocity = [0.0] * 3
        self._pin.target_acceleration = [0.0] * 3
        self._pos_done = self._rot_done = False
        return CommandResult(True, note)

    def command_twist(self, linear: object, angular: object, *, frame: str | None = None,
                      stamp: float | None = None) -> CommandResult:
        """Follow the twist ``(linear [m/s], angular [rad/s])`` in F1 until ``jog_timeout`` passes
        without a new one; then brake to rest. Clipped to the velocity limits (the result's
        reason says so); refused per :func:`dualarm_control.drive_commands.twist_command`."""
        try:
            twist = twist_command(linear, angular, frame=self.frames[0] if frame is None else frame, stamp=stamp,
                                  last_stamp=self.last_stamp, accepted=self.frames)
        except CommandError as exc:
            return CommandResult(False, str(exc))
        lim = self.limits
        v = np.clip(twist.linear, -lim.max_linear_velocity, lim.max_linear_velocity)
        w = twist.angular
        speed = float(np.linalg.norm(w))
        if speed > lim.max_angular_velocity:
            w = w * (lim.max_angular_velocity / speed)
        clipped = not (np.array_equal(v, twist.linear) and np.array_equal(w, twist.angular))
        self._accept(stamp)
        self.goal, self.twist = None, TwistCommand(v, w, stamp)
        self.state = JOGGING
        self._twist_time = self.time
        self._set_velocity_target(v)
        self._pos_done = self._rot_done = False
        return CommandResult(True, "clipped to the velocity limits" if clipped else "")

    def hold(self, position: FloatArray, rotation: FloatArray) -> None:
        """Stop at once at ``(position [m] (3,), rotation (3, 3))`` (where the arms are): a target at
        rest, state :data:`IDLE`, the goal kept for reporting. For a node giving up on a goal the arms
        cannot reach (stalled): a jump of the target to the measured pose, not a planned motion."""
        self.p = np.array(_frozen_vector(position, "position"))
        self.r = np.array(_check_rotation(rotation, "rotation"))
        self.v, self.a = np.zeros(3), np.zeros(3)
        self.w, self.alpha = np.zeros(3), np.zeros(3)
        self.twist = None
        self.state = IDLE
        self._pos_done = self._rot_done = True
        self._pos_left = self._rot_left = 0.0
        self._box = None
        self._reset_position_input()

    def _accept(self, stamp: float | None) -> None:
        self.commands += 1
        if stamp is not None:
            self.last_stamp = stamp

    def _set_velocity_target(self, v: FloatArray) -> None:
        self._pin.control_interface = ruckig.ControlInterface.Velocity
        self._pin.synchronization = ruckig.Synchronization.Time
        self._pin.target_velocity = v.tolist()
        self._pin.target_acceleration = [0.0] * 3

    def _reset_position_input(self) -> None:
        self._pin.current_position = self.p.tolist()
        self._pin.current_velocity = self.v.tolist()
        self._pin.current_acceleration = self.a.tolist()

    # ------------------------------------------------------------------ cycle

    def step(self) -> TargetSample:
        """Advance one period and return the new target (pose, twist, acceleration in F1)."""
        self.cycles += 1
        if self.state == JOGGING and self.twist is not None and (
                self.time - self._twist_time > self.jog_timeout + 1e-9 * self.period):
            self.twist = TwistCommand(np.zeros(3), np.zeros(3), self.twist.stamp)  # brake to rest
            self._set_velocity_target(np.zeros(3))
        if self.state in (MOVING, JOGGING):
            if not self._pos_done:
                self._step_position()
            if not self._rot_done:
                self._step_rotation()
            if self._pos_done and self._rot_done:
                if self.state == MOVING:
                    self.state = REACHED
                elif self.twist is not None and not np.any(self.twist.linear) and not np.any(self.twist.angular):
                    self.state = IDLE
        return self.sample()

    def _near_rest(self, remaining: float, velocity: FloatArray, acceleration: FloatArray, amax: float,
                   jmax: float) -> bool:
        """The state is one cycle's change from rest on the target: ``remaining`` [m or rad] below
        :data:`_SNAP`, ``||v|| <= amax T`` and ``||a|| <= jmax T`` (a snap to rest stays inside the
        limits). Ruckig may fail on such a state (RuckigError "error in step 2", measured with a
        remaining 5e-13 rad, 1.8e-9 rad/s, -4.2e-6 rad/s^2 after a jog and a goal at the same pose)."""
        t = self.period
        return (remaining <= _SNAP and float(np.linalg.norm(velocity)) <= amax * t
                and float(np.linalg.norm(acceleration)) <= jmax * t)

    def _step_position(self) -> None:
        try:
            result = self._pos.update(self._pin, self._pout)
        except ruckig.RuckigError:
            lim = self.limits
            if self.goal is None or not self._near_rest(float(np.linalg.norm(self.goal.position - self.p)), self.v,
                                                        self.a, lim.max_linear_acceleration, lim.max_linear_jerk):
                raise
            result = ruckig.Result.Finished  # on the goal, at rest within one cycle's change
        if result not in (ruckig.Result.Working, ruckig.Result.Finished):
            raise TrajectoryError(f"ruckig failed on the relative position ({result.name})")
        if result == ruckig.Result.Finished and self.goal is not None:
            self.p, self.v, self.a = self.goal.position.copy(), np.zeros(3), np.zeros(3)
            self._reset_position_input()
            self._pos_done, self._pos_left = True, 0.0
            return
        self._pout.pass_to_input(self._pin)
        self.p = np.array(self._pout.new_position)
        self.v = np.array(self._pout.new_velocity)
        self.a = np.array(self._pout.new_acceleration)
        self._pos_left = max(float(self._pout.trajectory.duration) - float(self._pout.time), 0.0)
        if result == ruckig.Result.Finished and not np.any(self._pin.target_velocity):  # braked to rest
            self.v, self.a = np.zeros(3), np.zeros(3)
            self._reset_position_input()
            self._pos_done, self._pos_left = True, 0.0

    def _step_rotation(self) -> None:
        lim = self.limits
        vmax, amax, jmax = lim.max_angular_velocity, lim.max_angular_acceleration, lim.max_angular_jerk
        if self.goal is not None:
            direction = np.asarray(pin.log3(self.goal.rotation @ self.r.T))
            target_velocity = np.zeros(3)
        else:
            assert self.twist is not None
            target_velocity = self.twist.angular
            direction = target_velocity if np.any(target_velocity) else self.w
        if not np.any(self.w) and not np.any(self.alpha) and not np.any(
                direction if self.goal is not None else target_velocity):
            self._finish_rotation()
            return
        braking = amax**2 / (2.0 * jmax * vmax)
        q, b = rotation_box(direction, self.w / vmax, self.alpha / amax, braking, self._box)
        self._box = (q, b)
        share = np.maximum(b, _MIN_SHARE)
        idle = b <= _IDLE  # at rest, outside the norm budget: it stays there (a kept box's old sides)
        inp = self._rin
        # a straight motion (sides at rest): the first coordinate alone, time-optimal as the segment
        # (time synchronization would give the sides odd profiles of their 1e-17 rad targets)
        inp.synchronization = ruckig.Synchronization.No if np.all(idle[1:]) else ruckig.Synchronization.Time
        inp.current_position = [0.0] * 3
        velocity, acceleration = _at_the_limit(q.T @ self.w, q.T @ self.alpha, vmax * share, amax)
        inp.current_velocity = velocity.tolist()
        inp.current_acceleration = acceleration.tolist()
        inp.max_velocity = (vmax * share).tolist()
        inp.max_acceleration = (amax * share).tolist()
        inp.max_jerk = (jmax * share).tolist()
        if self.goal is not None:
            inp.control_interface = ruckig.ControlInterface.Position
            inp.target_position = np.where(idle, 0.0, q.T @ direction).tolist()
            inp.target_velocity = [0.0] * 3
        else:
            inp.control_interface = ruckig.ControlInterface.Velocity
            inp.target_velocity = np.clip(q.T @ target_velocity, -vmax * b, vmax * b).tolist()
        inp.target_acceleration = [0.0] * 3
        try:
            result = self._rot.update(inp, self._rout)
        except ruckig.RuckigError:
            if self.goal is None or not self._near_rest(float(np.linalg.norm(direction)), self.w, self.alpha,
                                                        amax, jmax):
                raise
            self._finish_rotation()  # on the goal, at rest within one cycle's change
            return
        if result not in (ruckig.Result.Working, ruckig.Result.Finished):
            raise TrajectoryError(f"ruckig failed on the relative orientation ({result.name})")
        self._rot_left = max(float(self._rout.trajectory.duration) - self.period, 0.0)
        s = q @ np.array(self._rout.new_position)
        ds = q @ np.array(self._rout.new_velocity)
        dds = q @ np.array(self._rout.new_acceleration)
        if result == ruckig.Result.Finished and self.goal is not None:
            self._finish_rotation()
            return
        self.r = np.asarray(pin.exp3(s)) @ self.r
        self.w = angular_velocity(s, ds)
        self.alpha = angular_acceleration(s, ds, dds)
        if result == ruckig.Result.Finished and not np.any(target_velocity):  # braked to rest
            self._finish_rotation()

    def _finish_rotation(self) -> None:
        if self.goal is not None:
            self.r = self.goal.rotation.copy()
        self.w, self.alpha = np.zeros(3), np.zeros(3)
        self._box = None
        self._rot_done, self._rot_left = True, 0.0

    # ------------------------------------------------------------------ outputs

    def sample(self) -> TargetSample:
        """The current target (copies), as the offline trajectory gives it."""
        name = "goal" if self.goal is not None else "jog" if self.twist is not None else "hold"
        return TargetSample(
            time=self.time, position=self.p.copy(), rotation=self.r.copy(),
            linear_velocity=self.v.copy(), angular_velocity=self.w.copy(),
            segment=self.commands, segment_name=name, done=self.state in (IDLE, REACHED),
            linear_acceleration=self.a.copy(), angular_acceleration=self.alpha.copy(),
        )

    def progress(self) -> GoalProgress:
        """State, distance [m], angle [rad] and time to go [s] to the goal (see :class:`GoalProgress`)."""
        if self.goal is None:
            left = max(self._pos_left, self._rot_left) if self.state == JOGGING else 0.0
            return GoalProgress(self.state, None, 0.0, 0.0, left)
        distance = float(np.linalg.norm(self.goal.position - self.p))
        angle = float(np.linalg.norm(pin.log3(self.goal.rotation @ self.r.T)))
        left = 0.0 if self.state == REACHED else max(self._pos_left, self._rot_left)
        return GoalProgress(self.state, self.goal.stamp, distance, angle, left)
