"""Reference source of paper 000: relative motion segments, timed by ruckig from the start pose.

Keys under ``scenario.``: ``segments`` (ordered list of names) and per segment
``<seg>.type``: ``pose`` (``position`` [m] and ``rpy_deg`` of the peg frame F2 in the hole
frame F1) or ``screw`` (``axis`` in F1, ``angle_deg``, ``advance`` [m]); ``<seg>.hold`` [s].

``absolute_segments`` (issue 41): segments of the absolute frame (``absolute_frame``,
:mod:`dualarm_control.references.absolute`), the same keys in the world frame, timed by ruckig from the measured
absolute pose and run beside the relative ones from t = 0 (the run lasts as long as the longer of the two,
plus the settle time); the controller tracks them as the second priority under the relative pose. With
``absolute_segments``, ``segments`` may be left out: the relative pose is then held (and ``hold: true`` refuses
relative segments).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
import pinocchio as pin

from dualarm_control.collision import CollisionModel
from dualarm_control.controller import ControllerParams, RelativeController
from dualarm_control.drive_monitor import SegmentJudge
from dualarm_control.errors import ScenarioError
from dualarm_control.kinematics import DualArmModel, FloatArray
from dualarm_control.references.absolute import (
    HOLD_REASON,
    AbsoluteFrame,
    parse_absolute_frame,
)
from dualarm_control.references.base import (
    RELATIVE_TARGET,
    RelativeTracker,
    RunOptions,
    SourceDefaults,
    StreamSample,
)
from dualarm_control.scenario_keys import PREFIX, get, number, vector
from dualarm_control.trajectory import MotionLimits, RelativeTrajectory, Segment


@dataclass(frozen=True)
class SegmentSpec:
    """One segment as written in the file (resolved against the start pose later)."""

    name: str
    kind: str  # "pose" | "screw"
    position: FloatArray | None = None
    rotation: FloatArray | None = None
    axis: FloatArray | None = None
    angle: float = 0.0
    advance: float = 0.0
    hold: float = 0.0


@dataclass(frozen=True)
class SegmentsSource(SourceDefaults):
    """Relative segments (paper 000): a :class:`~dualarm_control.references.base.ReferenceSource`.

    Attributes:
        segments: the segments in order.
    """

    segments: tuple[SegmentSpec, ...]
    absolute: tuple[SegmentSpec, ...] = ()
    frame: AbsoluteFrame | None = None
    kind: ClassVar[str] = "segments"
    streams: ClassVar[tuple[str, ...]] = (RELATIVE_TARGET,)

    def describe(self) -> str:
        return f"{len(self.segments)} segments" + (f", {len(self.absolute)} absolute" if self.absolute else "")

    def tracker(self, model: DualArmModel, params: ControllerParams, options: RunOptions) -> RelativeTracker:
        return RelativeTracker(RelativeController(model, params), self.frame)

    def stream(self, model: DualArmModel, q0: FloatArray, options: RunOptions, period: float) -> SegmentsStream:
        absolute = None
        if self.absolute and self.frame is not None:
            absolute = chain(self.absolute, *self.frame.pose(model, q0), options.limits)
        return SegmentsStream(self.trajectory(*model.relative_pose(q0), options.limits), options.settle_time,
                              absolute)

    def end_pose(self, model: DualArmModel, q0: FloatArray, limits: MotionLimits,
                 period: float) -> tuple[FloatArray, FloatArray]:
        """The last segment's end pose (position [m] (3,), rotation (3, 3)) from q0's pose."""
        trajectory = self.trajectory(*model.relative_pose(q0), limits)
        end = trajectory.sample(trajectory.duration)
        return end.position, end.rotation

    def judge(self, model: DualArmModel, q0: FloatArray, limits: MotionLimits,
              collision: CollisionModel | None) -> SegmentJudge:
        """Every segment's verdict (:func:`segment_judge`), the trajectory planned from q0's relative pose as the
        trajectory node plans it; the absolute segments' too (on the absolute frame, planned from its pose at q0)."""
        judge = segment_judge(self.trajectory(*model.relative_pose(q0), limits), model, collision)
        if self.absolute and self.frame is not None:
            judge.others.append(segment_judge(chain(self.absolute, *self.frame.pose(model, q0), limits), model,
                                              collision, self.frame))
        return judge

    def trajectory(self, start_position: FloatArray, start_rotation: FloatArray,
                   limits: MotionLimits) -> RelativeTrajectory:
        """The ruckig relative trajectory from the measured start pose through all segments."""
        return chain(self.segments, start_position, start_rotation, limits)


def chain(specs: Sequence[SegmentSpec], start_position: FloatArray, start_rotation: FloatArray,
          limits: MotionLimits) -> RelativeTrajectory:
    """The ruckig trajectory from a start pose (position [m] (3,), rotation (3, 3)) through ``specs`` (relative
    segments in F1, or the absolute frame's in the world)."""
    segments: list[Segment] = []
    p, r = np.asarray(start_position, float), np.asarray(start_rotation, float)
    for spec in specs:
        if spec.kind == "pose":
            assert spec.position is not None and spec.rotation is not None
            seg = Segment.to_pose(spec.name, r, spec.position, spec.rotation, hold=spec.hold)
        else:
            assert spec.axis is not None
            seg = Segment.screw(spec.name, p, spec.axis, spec.angle, spec.advance, hold=spec.hold)
        segments.append(seg)
        p = np.asarray(seg.position)
        r = pin.exp3(seg.axis * seg.angle) @ r
    return RelativeTrajectory(start_position, start_rotation, segments, limits)


def segment_judge(trajectory: RelativeTrajectory, model: DualArmModel,
                  collision: CollisionModel | None = None, frame: AbsoluteFrame | None = None) -> SegmentJudge:
    """The :class:`~dualarm_control.drive_monitor.SegmentJudge` of ``trajectory``'s segments (names, end
    times [s] and end poses): the report's after the run, the trajectory node's live; with ``frame`` the segments
    of that absolute frame ("absolute segment k 'name'")."""
    n = len(trajectory.segments)
    return SegmentJudge(model, [seg.name for seg in trajectory.segments],
                        [*trajectory.segment_start_times[1:], trajectory.duration],
                        [trajectory.segment_end_pose(k) for k in range(n)], collision,
                        kind="segment" if frame is None else "absolute segment",
                        frame=None if frame is None else frame.pose)


class SegmentsStream:
    """The segments' targets for the trajectory node (stage: the segment's name)."""

    def __init__(self, trajectory: RelativeTrajectory, settle_time: float,
                 absolute: RelativeTrajectory | None = None) -> None:
        self.trajectory = trajectory
        self.absolute = absolute
        self.end = max(trajectory.duration, absolute.duration if absolute is not None else 0.0) + settle_time

    def sample(self, t: float) -> StreamSample:
        target = self.trajectory.sample(t)
        stage = f"segment {target.segment + 1}/{len(self.trajectory.segments)} '{target.segment_name}'"
        if self.absolute is None:
            return StreamSample(target, None, stage)
        absolute = self.absolute.sample(t)
        stage += f"; absolute {absolute.segment + 1}/{len(self.absolute.segments)} '{absolute.segment_name}'"
        return StreamSample(target, None, stage, absolute)


def parse_segments(flat: Mapping[str, Any]) -> SegmentsSource:
    """Read the segment keys (module docstring) from flattened parameters; ScenarioError on a bad value."""
    absolute = segment_specs(flat, "absolute_segments") if PREFIX + "absolute_segments" in flat else ()
    frame = parse_absolute_frame(flat, bool(absolute))
    if absolute and PREFIX + "segments" not in flat:  # the relative pose held where it starts
        return SegmentsSource((SegmentSpec("hold", "screw", axis=np.array([0.0, 0.0, 1.0])),), absolute, frame)
    if frame is not None and frame.hold:
        raise ScenarioError(f"scenario parameter '{PREFIX}segments': refused, {HOLD_REASON} (give absolute_segments "
                            "and no segments)")
    return SegmentsSource(segment_specs(flat, "segments"), absolute, frame)


def segment_specs(flat: Mapping[str, Any], key: str) -> tuple[SegmentSpec, ...]:
    """The segments named by ``scenario.<key>`` (a non-empty list of names), each from its keys."""
    names = get(flat, key)
    if not isinstance(names, list) or not all(isinstance(n, str) for n in names) or not names:
        raise ScenarioError(f"scenario parameter '{PREFIX}{key}': got {names!r}, expected a list of segment names")
    specs = []
    for seg in names:
        kind = get(flat, f"{seg}.type")
        hold = number(flat, f"{seg}.hold", 0.0)
        if kind == "pose":
            rpy = np.radians(vector(flat, f"{seg}.rpy_deg", 3))
            specs.append(SegmentSpec(seg, "pose", position=vector(flat, f"{seg}.position", 3),
                                     rotation=pin.rpy.rpyToMatrix(*rpy), hold=hold))
        elif kind == "screw":
            specs.append(SegmentSpec(seg, "screw", axis=vector(flat, f"{seg}.axis", 3),
                                     angle=math.radians(number(flat, f"{seg}.angle_deg", 0.0)),
                                     advance=number(flat, f"{seg}.advance", 0.0), hold=hold))
        else:
            raise ScenarioError(f"scenario parameter '{PREFIX}{seg}.type': got {kind!r}, expected one of: pose, screw")
    return tuple(specs)
