"""Is a goal reached by the arms, or stalled? (The interactive trajectory node's judge; no ROS.)

The online generator (:mod:`dualarm_control.online_trajectory`) says when its *target* is at
the goal (state ``reached``). The arms follow with a tracking error; when joint limits stop
them (the goal inside the reach bound but not in the arms' workspace, or only across a limit),
the target arrives and the arms do not. So, per cycle, with the measured relative pose
``(p, R)`` of the joint state and the goal ``(p_g, R_g)``:

* the goal is **reached** when the target is and ``||p - p_g|| <= position_tolerance`` [m] and
  ``angle(R_g R^T) <= angle_tolerance`` [rad] (defaults 0.5 mm, 5 mrad: inside the issue's
  1 mm / 0.01 rad);
* it is **stalled** when the target has been at the goal for ``stall_time`` [s] (default 2 s;
  the tracking error of the relative pose task decays with the task gain, e^{-k t}) without
  that: the remaining error and the joints within ``limit_margin`` [rad] of a position limit
  are reported, and, with a collision model, the closest link pair when it is closer than the
  collision limit's influence distance (the collision limit stopped the arms): the reason then
  starts "collision constraint: left_flange – right_link_5 at 0.030 m" (:func:`stall_reason`).

:func:`judge_goals` gives the same verdicts after the fact, for a scripted goals run (in one
process or from a bag): each goal is judged where the arms are when the next command comes.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from dualarm_control.collision import CollisionModel, CollisionParams
from dualarm_control.drive_status import MOVING, REACHED, STALLED, GoalProgress
from dualarm_control.goal_script import TimedCommand, TimedGoal
from dualarm_control.kinematics import DualArmModel, FloatArray

POSITION_TOLERANCE = 5e-4  # m
ANGLE_TOLERANCE = 5e-3  # rad
STALL_TIME = 2.0  # s
LIMIT_MARGIN = 1e-2  # rad
COLLISION_NEAR = CollisionParams().kept_distances[0]
"""A stall is blamed on the collision limit when the closest pair is nearer than this [m] (d_i + 2 shape margins)."""


def stall_reason(model: DualArmModel, q: FloatArray, distance: float, angle: float, when: str,
                 collision: CollisionModel | None = None, near: float = COLLISION_NEAR) -> str:
    """Why the arms stopped short of a goal at q (n,) [rad], ``distance`` [m] and ``angle`` [rad] from it.

    "collision constraint: A – B at 0.030 m; " first when ``collision`` has a pair closer than
    ``near`` [m], then the remaining error ``when`` (e.g. "2 s after the target arrived") and the
    joints at a position limit."""
    return held_by(model, q, f"remaining error {distance * 1000:.2f} mm, {angle:.4f} rad {when}", collision, near)


def held_by(model: DualArmModel, q: FloatArray, error: str, collision: CollisionModel | None = None,
            near: float = COLLISION_NEAR) -> str:
    """What held the arms at q (n,) [rad] short of a reference, around the ``error`` text: "collision constraint:
    A – B at 0.030 m; " first when ``collision`` has a pair closer than ``near`` [m], then ``error``, then the
    joints within :data:`LIMIT_MARGIN` of a position limit."""
    joints = joints_at_limit(model, q)
    text = f"{error}; joints at a limit: {', '.join(joints) if joints else 'none'}"
    if collision is not None and collision.pairs:
        near_pairs = collision.distances(q, within=near)
        if near_pairs:
            closest = min(near_pairs, key=lambda p: p.distance)
            text = f"collision constraint: {closest.link_a} – {closest.link_b} at {closest.distance:.3f} m; " + text
    return text


def joints_at_limit(model: DualArmModel, q: FloatArray, margin: float = LIMIT_MARGIN) -> list[str]:
    """Names of the joints of q (n,) [rad] within ``margin`` [rad] of their lower or upper limit."""
    near = (q <= model.q_min + margin) | (q >= model.q_max - margin)
    return [name for name, hit in zip(model.joint_names, near, strict=True) if hit]


@dataclass(frozen=True)
class Verdict:
    """The node's view of the goal this cycle: ``state`` (``moving``, ``reached``, ``stalled``, or
    the generator's own), the measured ``distance`` [m] and ``angle`` [rad] to the goal, and a
    ``reason`` (a stall's remaining error and joints at a limit)."""

    state: str
    distance: float
    angle: float
    reason: str = ""


class GoalMonitor:
    """Judges each cycle of one goal (:meth:`reset` for a new goal); see the module docstring."""

    def __init__(self, model: DualArmModel, position_tolerance: float = POSITION_TOLERANCE,
                 angle_tolerance: float = ANGLE_TOLERANCE, stall_time: float = STALL_TIME,
                 collision: CollisionModel | None = None, collision_near: float = COLLISION_NEAR,
                 pose: Callable[[FloatArray], tuple[FloatArray, FloatArray]] | None = None) -> None:
        self.model = model
        self.pose = pose if pose is not None else model.relative_pose  # what the goals are poses of (issue 41)
        self.collision = collision
        self.collision_near = collision_near
        self.position_tolerance = position_tolerance
        self.angle_tolerance = angle_tolerance
        self.stall_time = stall_time
        self.reset()

    def reset(self) -> None:
        """A new goal (or none): forget when the target arrived."""
        self.arrived: float | None = None  # time [s] the target reached the goal
        self.final: str | None = None  # reached / stalled: kept until the next goal
        self.final_reason = ""  # a stall's reason, repeated with every later verdict (a client may miss the first)

    def judge(self, progress: GoalProgress, goal: tuple[FloatArray, FloatArray] | None, q: FloatArray,
              t: float) -> Verdict:
        """The verdict at time t [s] for the generator's ``progress``, its goal ``(p_g (3,), R_g (3, 3))``
        (None: no goal) and the measured joint positions q (n,) [rad]."""
        if goal is None:
            return Verdict(progress.state, 0.0, 0.0)
        p, r = self.pose(q)
        distance = float(np.linalg.norm(p - goal[0]))
        angle = float(np.linalg.norm(pin.log3(goal[1] @ r.T)))
        if self.final is not None:
            return Verdict(self.final, distance, angle, self.final_reason)
        if progress.state != REACHED:
            self.arrived = None
            return Verdict(progress.state, distance, angle)
        if distance <= self.position_tolerance and angle <= self.angle_tolerance:
            self.final = REACHED
            return Verdict(REACHED, distance, angle)
        if self.arrived is None:
            self.arrived = t
        if t - self.arrived < self.stall_time:
            return Verdict(MOVING, distance, angle)
        self.final = STALLED
        self.final_reason = stall_reason(self.model, q, distance, angle,
                                         f"{self.stall_time:g} s after the target arrived", self.collision,
                                         self.collision_near)
        return Verdict(STALLED, distance, angle, self.final_reason)


@dataclass(frozen=True)
class GoalOutcome:
    """How one goal ended: ``index`` in its script (or segment list), its time ``t`` [s], the ``state``
    (``reached`` or ``stalled``), the measured ``distance`` [m] and ``angle`` [rad] to it where it was
    judged, the ``reason`` of a stall (:func:`stall_reason`) and its ``label`` ('' : "goal <index>")."""

    index: int
    t: float
    state: str
    distance: float
    angle: float
    reason: str = ""
    label: str = ""

    def text(self) -> str:
        head = f"{self.label or f'goal {self.index}'} (t = {self.t:g} s): {self.state}"
        return head + (f": {self.reason}" if self.reason else f", error {self.distance * 1000:.3f} mm, {self.angle:.5f} rad")


def pose_distance(model: DualArmModel, q: FloatArray, position: FloatArray, rotation: FloatArray,
                  frame: Callable[[DualArmModel, FloatArray], tuple[FloatArray, FloatArray]] | None = None
                  ) -> tuple[float, float]:
    """Distance [m] and angle [rad] of the relative pose at q (n,) [rad] (or of ``frame(model, q)``'s pose: the
    absolute frame's, issue 41) from ``(position (3,), rotation (3, 3) or an (x, y, z, w) quaternion)``."""
    p, r = model.relative_pose(q) if frame is None else frame(model, q)
    goal_r = np.asarray(rotation, dtype=float)
    if goal_r.shape == (4,):
        goal_r = pin.Quaternion(goal_r[3], *goal_r[:3]).normalized().toRotationMatrix()
    return float(np.linalg.norm(p - np.asarray(position, dtype=float))), float(np.linalg.norm(pin.log3(goal_r @ r.T)))


def _outcome(model: DualArmModel, q: FloatArray, distance: float, angle: float, index: int, t: float, when: str,
             label: str, collision: CollisionModel | None, near: float, position_tolerance: float,
             angle_tolerance: float) -> GoalOutcome:
    """Reached within the tolerances, else stalled with :func:`stall_reason` at q."""
    if distance <= position_tolerance and angle <= angle_tolerance:
        return GoalOutcome(index, t, REACHED, distance, angle, label=label)
    return GoalOutcome(index, t, STALLED, distance, angle, stall_reason(model, q, distance, angle, when, collision, near),
                       label)


def judge_goals(model: DualArmModel, commands: Sequence[TimedCommand], time: FloatArray, positions: FloatArray,
                final_positions: FloatArray, collision: CollisionModel | None = None,
                position_tolerance: float = POSITION_TOLERANCE, angle_tolerance: float = ANGLE_TOLERANCE,
                near: float = COLLISION_NEAR,
                absolute: Callable[[DualArmModel, FloatArray], tuple[FloatArray, FloatArray]] | None = None
                ) -> list[GoalOutcome]:
    """The verdict of every goal of a script after the run (twists are not judged). An absolute goal (issue 41)
    is judged on ``absolute``'s pose (the scenario's absolute frame: its world pose at q), not without it.

    A goal is judged at the last recorded cycle before the next command (the run's final
    positions for the last one): ``reached`` within the tolerances [m, rad], else ``stalled``
    with :func:`stall_reason`. ``time`` (N,) [s], ``positions`` (N, n) [rad], ``final_positions`` (n,)."""
    starts = [c.t for c in commands]
    out = []
    for i, command in enumerate(commands):
        if not isinstance(command, TimedGoal) or (command.absolute and absolute is None):
            continue
        if i + 1 < len(commands):
            k = int(np.searchsorted(time, starts[i + 1], side="left")) - 1
            q = positions[max(k, 0)]
        else:
            q = final_positions if np.all(np.isfinite(final_positions)) else positions[-1]
        distance, angle = pose_distance(model, q, command.position, command.orientation,
                                        absolute if command.absolute else None)
        when = "when the next command came" if i + 1 < len(commands) else "at the end of the run"
        out.append(_outcome(model, q, distance, angle, i, command.t, when, "", collision, near, position_tolerance,
                            angle_tolerance))
    return out


SEGMENT_WINDOW = (0.05, 0.25)
"""A segment is judged at its closest cycle to its end pose within this window [s] (before, after) its
end: a target still moving when the segment ends (no hold) puts the arms a tracking lag behind it, and
a lockstep bag's time axis may start a cycle or two off the trajectory node's clock."""


class SegmentJudge:
    """Every segment's verdict as the run goes (issue 40): segment k (``names[k]``, ending at ``ends[k]`` [s]
    with its end pose ``poses[k]`` = (p (3,), R (3, 3))) is judged at its closest sample to that pose within
    :data:`SEGMENT_WINDOW` of its end (:meth:`feed`, once the window has passed), the last one at the run's
    final positions (:meth:`finish`): ``reached`` within the tolerances, else ``stalled`` with
    :func:`stall_reason` (the collision pair or joint limit that held the arms, and the error left). A segment
    with no sample in its window is judged at the latest sample before the window closed. ``kind`` names a
    part in the verdicts ("segment 1 'approach'"; a plan's one part: "plan 1 'corner_path'"). The batch form is
    :func:`judge_segments`; the trajectory node feeds it live. ``frame`` (issue 41) judges the poses of another
    frame, ``frame(model, q)`` (the absolute frame's segments); ``others`` are judges fed alongside (their verdicts
    come with this one's)."""

    def __init__(self, model: DualArmModel, names: Sequence[str], ends: Sequence[float],
                 poses: Sequence[tuple[FloatArray, FloatArray]], collision: CollisionModel | None = None,
                 position_tolerance: float = POSITION_TOLERANCE, angle_tolerance: float = ANGLE_TOLERANCE,
                 near: float = COLLISION_NEAR, kind: str = "segment",
                 frame: Callable[[DualArmModel, FloatArray], tuple[FloatArray, FloatArray]] | None = None) -> None:
        self.model, self.collision, self.near, self.kind = model, collision, near, kind
        self.frame = frame  # the poses are of this frame (issue 41: the absolute frame's), None: the relative pose
        self.others: list[SegmentJudge] = []  # judges fed alongside (the absolute segments' beside the relative ones)
        self.names, self.ends, self.poses = list(names), list(ends), list(poses)
        self.position_tolerance, self.angle_tolerance = position_tolerance, angle_tolerance
        self.k = 0  # the segment being judged
        self.best: tuple[float, float, float, FloatArray] | None = None  # (score, distance, angle, q) in its window
        self.latest: FloatArray | None = None

    def _score(self, distance: float, angle: float) -> float:
        return distance / self.position_tolerance + angle / self.angle_tolerance

    def _judge(self, k: int, q: FloatArray, distance: float, angle: float, when: str) -> GoalOutcome:
        return _outcome(self.model, q, distance, angle, k, self.ends[k], when, f"{self.kind} {k + 1} '{self.names[k]}'",
                        self.collision, self.near, self.position_tolerance, self.angle_tolerance)

    def feed(self, t: float, q: FloatArray) -> list[GoalOutcome]:
        """A sample: joint positions q (n,) [rad] at time t [s] of the run; the verdicts it completes."""
        out: list[GoalOutcome] = []
        if not np.all(np.isfinite(q)):
            return out
        for other in self.others:
            out += other.feed(t, q)
        while self.k + 1 < len(self.names) and t > self.ends[self.k] + SEGMENT_WINDOW[1]:
            out.append(self._close(self.k))
        self.latest = q
        if self.k + 1 < len(self.names) and t >= self.ends[self.k] - SEGMENT_WINDOW[0]:
            distance, angle = pose_distance(self.model, q, *self.poses[self.k], self.frame)
            score = self._score(distance, angle)
            if self.best is None or score < self.best[0]:
                self.best = (score, distance, angle, q)
        return out

    def _close(self, k: int) -> GoalOutcome:
        """Segment k's verdict at its best sample (or the latest), then on to the next."""
        if self.best is None:
            q = self.latest if self.latest is not None else np.full(self.model.nq, np.nan)
            distance, angle = pose_distance(self.model, q, *self.poses[k], self.frame)
        else:
            _, distance, angle, q = self.best
        self.k, self.best = k + 1, None
        return self._judge(k, q, distance, angle, "at the segment's end")

    def run(self, time: FloatArray, positions: FloatArray, final: FloatArray) -> list[GoalOutcome]:
        """Every verdict of a recorded run: its cycles ``time`` (N,) [s], ``positions`` (N, n) [rad], then
        its ``final`` positions (n,)."""
        out: list[GoalOutcome] = []
        for t, q in zip(np.asarray(time, dtype=float).tolist(), positions, strict=True):
            out += self.feed(t, q)
        return out + self.finish(final)

    def finish(self, final: FloatArray | None = None) -> list[GoalOutcome]:
        """The verdicts still open at the run's end: the last segment at ``final`` (n,) [rad] (else the
        latest sample), any earlier one at its window's best."""
        out: list[GoalOutcome] = []
        while self.k + 1 < len(self.names):
            out.append(self._close(self.k))
        if self.k < len(self.names):
            q = final if final is not None and np.all(np.isfinite(final)) else self.latest
            if q is not None:
                distance, angle = pose_distance(self.model, q, *self.poses[self.k], self.frame)
                out.append(self._judge(self.k, q, distance, angle, "at the end of the run"))
            self.k += 1
        for other in self.others:
            out += other.finish(final)
        return out


def judge_segments(model: DualArmModel, names: Sequence[str], ends: Sequence[float],
                   poses: Sequence[tuple[FloatArray, FloatArray]], time: FloatArray, positions: FloatArray,
                   final_positions: FloatArray, collision: CollisionModel | None = None,
                   position_tolerance: float = POSITION_TOLERANCE, angle_tolerance: float = ANGLE_TOLERANCE,
                   near: float = COLLISION_NEAR) -> list[GoalOutcome]:
    """The verdict of every segment of a relative trajectory after the run (:class:`SegmentJudge` on the
    recorded cycles: ``time`` (N,) [s], ``positions`` (N, n) [rad], then ``final_positions`` (n,))."""
    return SegmentJudge(model, names, ends, poses, collision, position_tolerance, angle_tolerance,
                        near).run(time, positions, final_positions)


@dataclass(frozen=True)
class ClosestPair:
    """The closest link pair over a sequence of configurations: ``distance`` [m] (the collision model's
    margin when none is closer), ``text`` ("link_a – link_b", or "none closer than M m") and ``index``,
    the configuration it is at (-1 when none)."""

    distance: float
    text: str
    index: int


def closest_pair(collision: CollisionModel, configurations: FloatArray) -> ClosestPair:
    """:class:`ClosestPair` of ``configurations`` (k, n) [rad] (rows with a non-finite value skipped) on
    ``collision`` (coal; its allowed pairs excluded)."""
    best = ClosestPair(float(collision.margin), f"none closer than {collision.margin:g} m", -1)
    for i, q in enumerate(configurations):
        if not np.all(np.isfinite(q)):
            continue
        for pair in collision.distances(q, within=best.distance):
            if pair.distance < best.distance:
                best = ClosestPair(float(pair.distance), f"{pair.link_a} – {pair.link_b}", i)
    return best
