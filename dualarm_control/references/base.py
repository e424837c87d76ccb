"""The reference-source interface of a scenario, and the readers of the scenario file's keys.

A scenario (:class:`dualarm_control.scenario.Scenario`) is the cell (URDF, initial
configuration), the motion limits and ONE reference source: what the controller is asked to
follow. The kinds today:

* ``segments`` (paper 000, :class:`~dualarm_control.references.segments.SegmentsSource`):
  relative pose/screw segments, timed by ruckig from the measured start pose and streamed as
  relative targets (/relative_target) to the relative pose task;
* ``tasks`` (paper 001, :class:`~dualarm_control.references.tasks.TasksSource`): a set of
  tasks with gains and bounds evaluated at the cycle's time, optionally closed over a force
  sensor (/wrench); no target stream;
* ``plan`` (paper 003, :class:`~dualarm_control.references.plan.PlanSource`): a planned
  joint trajectory (/joint_reference) tracked in joint space.

A source is parsed from the scenario file (frozen, no run state). For a run it makes a
:class:`Tracker` (:meth:`ReferenceSource.tracker`): the source bound to a controller, giving one
:class:`~dualarm_control.controller.Cycle` per control period from the measured joints and the
cycle's :class:`StreamSample`. The controller node feeds it the samples it receives; the
in-process runner (:mod:`dualarm_control.app.run.experiment`) is one loop over a
:class:`StreamFollower` (:meth:`ReferenceSource.follower`): the same tracker fed by the source's
own stream from the measured start configuration, whatever the kind. So the node and the runner
run the same model, gain and cycle count (:func:`cycle_count`).

* ``goals`` (issue 18, :class:`~dualarm_control.references.goals.GoalsSource`): timed relative
  goals and twists (or live ones), replanned online by ruckig, streamed on /relative_target.

Over ROS the trajectory node publishes a source's :class:`TargetStream` (``stream``): what it
publishes at each cycle is the source's :class:`StreamSample`; the consumers (runner, nodes,
report) read only these members.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar, Protocol

from dualarm_control.kinematics import DualArmModel, FloatArray
from dualarm_control.trajectory import MotionLimits

if TYPE_CHECKING:
    from dualarm_control.collision import CollisionModel
    from dualarm_control.controller import ControllerParams, Cycle, RelativeController
    from dualarm_control.drive_monitor import SegmentJudge
    from dualarm_control.references.absolute import AbsoluteFrame

RELATIVE_TARGET = "/relative_target"
JOINT_REFERENCE = "/joint_reference"
WRENCH = "/wrench"
LEFT_WRENCH = "/left/wrench"
RIGHT_WRENCH = "/right/wrench"
"""The wrist F/T sensors of a held object's run (geometry_msgs/WrenchStamped in each tool frame)."""
HELD_OBJECT_POSE = "/held_object/pose"
"""The simulator's held box, its centre's world pose (geometry_msgs/PoseStamped, frame ``world``; ground truth
of the physics, not a sensor): what a carry's slip is measured on."""


@dataclass(frozen=True)
class RunOptions:
    """What a run adds to a scenario's source.

    Attributes:
        limits: the scenario's ruckig limits (relative motion).
        settle_time: control time after a trajectory ends [s].
        gain: task gain k [1/s] (tasks; None: the source's default).
        force: the force variant (tasks, eq 9 of paper 001).
        duration: run time [s] (tasks; None: the source's).
    """

    limits: MotionLimits
    settle_time: float
    gain: float | None = None
    force: bool = False
    duration: float | None = None


class Tracker(Protocol):
    """A reference source bound to a controller: one cycle per received sample.

    Attributes:
        label: run name (the solver for relative motion, "k=1 force" for tasks).
        steps: control periods of the run where the tracker decides it (tasks: their duration),
            else None (the stream's end decides: the trajectory node's, or :class:`StreamFollower`'s).
        uses_wrench: the cycle needs the F/T reading (force variant).
        controller: the controller it solves with (a live parameter change replaces it).
    """

    label: str
    steps: int | None
    uses_wrench: bool
    controller: RelativeController

    def track(self, q: FloatArray, sample: StreamSample | None, t: float, wrench: FloatArray | None) -> Cycle:
        """One cycle at measured joint positions q (n,) [rad] on the cycle's sample (None for a
        source without a stream: tasks), at time t [s] since the start and, when ``uses_wrench``,
        the raw F/T reading (6,)."""
        ...

    def report(self, cycle: Cycle, t: float) -> dict[str, Any]:
        """What a cycle reports beyond the solver's figures (the controller node's /diagnostics values)."""
        ...


def cycle_count(end: float, period: float) -> int:
    """Cycles at t = k T [s] before ``end`` [s], counted as the trajectory node counts them on its
    nanosecond clock (``t = k T_ns / 1e9``, the first t >= end has no target)."""
    if math.isinf(end):
        raise ValueError("a stream without an end has no cycle count")
    period_ns = round(period * 1e9)
    k = max(math.ceil(end * 1e9 / period_ns) - 1, 0)
    while k * period_ns / 1e9 < end:
        k += 1
    while k > 0 and (k - 1) * period_ns / 1e9 >= end:
        k -= 1
    return k


class StreamFollower:
    """A tracker fed by its source's own stream (the in-process runner's follower, paper 000's
    Fig. 3 in one process): the sample at t is ``stream.sample(t)``, as the trajectory node
    publishes it; ``steps`` is the tracker's, else :func:`cycle_count` of the stream's end."""

    def __init__(self, tracker: Tracker, stream: TargetStream | None, period: float) -> None:
        self.tracker = tracker
        self.stream = stream
        self.label = tracker.label
        self.uses_wrench = tracker.uses_wrench
        if tracker.steps is not None:
            self.steps = tracker.steps
        else:
            assert stream is not None, "a tracker without its own cycle count needs a stream"
            self.steps = cycle_count(stream.end, period)

    @property
    def controller(self) -> RelativeController:
        return self.tracker.controller

    @controller.setter
    def controller(self, value: RelativeController) -> None:
        self.tracker.controller = value

    def cycle(self, t: float, q: FloatArray, wrench: FloatArray | None) -> Cycle:
        """One cycle at time t [s] since the start (the sample of the source's own stream at t)."""
        return self.tracker.track(q, self.stream.sample(t) if self.stream is not None else None, t, wrench)


Follower = StreamFollower


@dataclass(frozen=True)
class StreamSample:
    """What the trajectory node publishes at one cycle (the source decides).

    Attributes:
        relative: the relative target (pose, twist, acceleration of F2 in F1: ``position``,
            ``rotation``, ``linear_velocity``, ``angular_velocity``, ``linear_acceleration``,
            ``angular_acceleration``) for /relative_target.
        joints: ``(q_ref, qd_ref)`` (n,) each [rad, rad/s] for /joint_reference, or None.
        stage: the stage's name (a segment's, "execute", "goal", "jog", "hold"): logged when it changes.
        absolute: the absolute frame's target (pose and twist in the world, the same members as ``relative``;
            issue 41), tracked under the relative pose, or None.
    """

    relative: Any
    joints: tuple[FloatArray, FloatArray] | None
    stage: str
    absolute: Any = None


class TargetStream(Protocol):
    """The targets of one run of a streaming source, sampled at non-decreasing times t [s].

    Attributes:
        end: time [s] of the first cycle with no target (trajectory + settle; inf: no end).
    """

    end: float

    def sample(self, t: float) -> StreamSample: ...


class ReferenceSource(Protocol):
    """What a scenario's controller follows (module docstring).

    Attributes:
        kind: "segments", "tasks", "plan" (issue 18: "goals"): names the report's figures and
            the run record's optional fields (task values where there are tasks, force where
            there is force).
        streams: the topics a controller cycle consumes besides /joint_states, in the node
            (the source decides what the controller node subscribes): segments
            (/relative_target), plan (/relative_target and /joint_reference), none for tasks (the
            force variant adds /wrench: ``Follower.uses_wrench``).

    Methods:
        describe(): one line for logs ("3 segments", "6 tasks", "plan <file>").
        initial_positions(default): the configuration the cell starts in [rad], (n,) (a plan's
            first configuration, else the scenario's ``default``).
        cell(options): extra :class:`~dualarm_sim.cell.CellConfig` fields of a run (tasks: the
            table height, the contact pair of the force variant), plain data.
        tracker(model, params, options): the source bound to a new controller (:class:`Tracker`).
        follower(model, params, q0, options): the tracker fed by the source's own stream from the
            measured start configuration q0 (n,) (:class:`StreamFollower`).
        stream(model, q0, options, period): the targets the trajectory node publishes for a run
            from q0 (n,) at ``period`` [s] (:class:`TargetStream`); ScenarioError for a source
            without a target stream (tasks).
    """

    kind: ClassVar[str]
    streams: ClassVar[tuple[str, ...]]

    def describe(self) -> str: ...

    def initial_positions(self, default: FloatArray) -> FloatArray: ...

    def cell(self, options: RunOptions) -> dict[str, Any]: ...

    def tracker(self, model: DualArmModel, params: ControllerParams, options: RunOptions) -> Tracker: ...

    def follower(self, model: DualArmModel, params: ControllerParams, q0: FloatArray,
                 options: RunOptions) -> StreamFollower: ...

    def stream(self, model: DualArmModel, q0: FloatArray, options: RunOptions, period: float) -> TargetStream: ...

    def judge(self, model: DualArmModel, q0: FloatArray, limits: MotionLimits,
              collision: CollisionModel | None) -> SegmentJudge | None:
        """The judge of the run's parts (segments, a plan) from the start q0 (n,) [rad]: each part's verdict,
        reached or stalled with what held the arms (issue 40); None: the source has no parts to judge."""
        ...


class SourceDefaults:
    """What most sources share: the cell starts at the scenario's configuration, with no extra
    fields; the follower is the tracker on the source's own stream."""

    def tracker(self, model: DualArmModel, params: ControllerParams, options: RunOptions) -> Tracker:
        raise NotImplementedError

    def stream(self, model: DualArmModel, q0: FloatArray, options: RunOptions, period: float) -> TargetStream:
        raise NotImplementedError

    def judge(self, model: DualArmModel, q0: FloatArray, limits: MotionLimits,
              collision: CollisionModel | None) -> SegmentJudge | None:
        """No parts to judge (goals are judged by their own monitor, tasks by their metrics)."""
        return None

    def follower(self, model: DualArmModel, params: ControllerParams, q0: FloatArray,
                 options: RunOptions) -> StreamFollower:
        tracker = self.tracker(model, params, options)
        stream = None if tracker.steps is not None else self.stream(model, q0, options, params.period)
        return StreamFollower(tracker, stream, params.period)

    def initial_positions(self, default: FloatArray) -> FloatArray:
        return default

    def cell(self, options: RunOptions) -> dict[str, Any]:
        return {}


class RelativeTracker:
    """The relative pose task on the cycle's relative target (paper 000, eq 13): segments and
    goals alike. Reports the tracking errors."""

    uses_wrench = False
    steps: int | None = None

    def __init__(self, controller: RelativeController, frame: AbsoluteFrame | None = None) -> None:
        self.controller = controller
        self.label = controller.params.solver
        self.frame = frame  # the absolute frame of a sample's absolute target (None: the halfway one, priority 2)

    def track(self, q: FloatArray, sample: StreamSample | None, t: float, wrench: FloatArray | None) -> Cycle:
        assert sample is not None, "the relative pose task needs a relative target"
        frame = self.frame
        out = self.controller.step(q, sample.relative, sample.absolute, frame.grasp if frame is not None else None,
                                   frame.weight if frame is not None else None)
        out.stage = sample.stage
        return out

    def report(self, cycle: Cycle, t: float) -> dict[str, Any]:
        return relative_report(cycle)


def relative_report(cycle: Cycle) -> dict[str, Any]:
    """A relative cycle's /diagnostics values: cycle time [s] and tracking errors [m, rad]."""
    out = {"cycle_time_s": f"{cycle.cycle_time:.6e}", "position_error_m": f"{cycle.position_error:.6e}",
           "orientation_error_rad": f"{cycle.orientation_error:.6e}"}
    if math.isfinite(cycle.absolute_position_error):  # an absolute target (issue 41)
        out["absolute_position_error_m"] = f"{cycle.absolute_position_error:.6e}"
        out["absolute_orientation_error_rad"] = f"{cycle.absolute_orientation_error:.6e}"
    return out
