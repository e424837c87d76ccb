"""Log a run of the cell to Rerun: the URDF posed by the joint states, frames and plots.

Everything here takes plain arrays, whatever the run came from (a bag, the live cell, an
in-process run): :func:`log_run` is the one entry point; :func:`log_joints`,
:func:`log_series`, :func:`log_frames` and :func:`log_statuses` are its parts, which the live
view calls on each batch of messages. Time is the ``time`` timeline: seconds since the run's
start (a duration), one row per control cycle.

Entities: ``/<robot>/visual_geometries/<link>/...`` (the URDF, static, as Rerun's URDF importer
names it), ``/joint_tf/<joint>`` (each driven joint's transform per cycle), ``/frames/<name>``
(poses given in the left tool frame, drawn as axes; the tools' own axes are ``/frames/left_tool``
and ``/frames/right_tool``), ``/plot/<group>/<name>`` (scalars), ``/status`` (solver status
changes, text log), ``/collision/closest`` (the closest link pair within the collision limit's
influence distance, a line between its witness points, labelled with the pair and the distance). The blueprint puts the 3D view (collision geometry hidden) beside one
plot per series group.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from dualarm_control.arrays import FloatArray
from dualarm_control.metrics import ACTIVITY_THRESHOLD, l0_norms
from dualarm_control.status import FAILURE_STATUSES

APPLICATION_ID = "dualarm_control"
TIMELINE = "time"
"""Seconds since the start of the run (a duration timeline)."""
TOOL_FRAME = "left_tool"
"""Frame the relative poses are given in (URDF link of the left tool)."""
TOOL_FRAMES = ("left_tool", "right_tool")
AXIS_LENGTH_M = 0.08
EYE_POSITION = (2.2, -1.3, 2.0)
"""Camera of the 3D view [m] (world frame): both arms in view (``../shared/viz-notes.md``)."""
LOOK_TARGET = (0.4, 0.0, 0.9)

VELOCITY_L0 = "velocity/active_joints"
VELOCITY_L1 = "velocity/l1_rad_per_s"
TRACKING_POSITION = "tracking/position_error_m"
TRACKING_ORIENTATION = "tracking/orientation_error_rad"
SOLVE_TIME = "timing/solve_time_s"
CYCLE_TIME = "timing/cycle_time_s"
STATUS_ENTITY = "status"
CLOSEST_ENTITY = "collision/closest"
"""The closest link pair of each cycle, a line between its witness points (issue 27)."""
CLOSEST_DISTANCE = "collision/closest_distance_m"
NEAR_COLOR = (230, 40, 40)
"""Colour of the closest pair's line within 5 mm of the safety distance (held by the limit)."""
INFLUENCE_COLOR = (255, 170, 0)
WITNESS_RADIUS_M = 0.015
"""Radius of the closest pair's witness points as drawn [m] (a 3 cm gap is a few pixels from the camera)."""
"""Colour of the closest pair's line inside the influence distance."""


@dataclass(frozen=True)
class ClosestPairs:
    """The closest link pair of each cycle closer than the influence distance d_i (else NaN, '').

    Attributes:
        points: witness points p_a, p_b in the world [m], (N, 2, 3). distance: d [m], (N,).
        labels: "link_a – link_b 0.030 m" per cycle ('' when none within d_i).
        frame: the URDF's root link, the frame the points are given in (the world).
    """

    points: FloatArray
    distance: FloatArray
    labels: list[str]
    frame: str


def closest_pairs(model: Any, q: FloatArray, collision: Any = None) -> ClosestPairs:
    """:class:`ClosestPairs` of joint positions q (N, n) [rad]: ``collision`` (default: the robot's
    collision model, its ``collision_allowed`` pairs left out), the pairs closer than the default
    influence distance."""
    from dualarm_control.collision import CollisionModel, CollisionParams

    collision = collision or CollisionModel(model, allowed=model.description.collision_allowed)
    within = CollisionParams().kept_distances[0]
    q = np.asarray(q, dtype=float)
    points, distance, labels = np.full((len(q), 2, 3), np.nan), np.full(len(q), np.nan), [""] * len(q)
    for k, row in enumerate(q):
        if not np.all(np.isfinite(row)):
            continue
        near = collision.distances(row, within=within)
        if near:
            pair = min(near, key=lambda d: d.distance)
            points[k], distance[k] = (pair.point_a, pair.point_b), pair.distance
            labels[k] = f"{pair.link_a} – {pair.link_b} {pair.distance:.3f} m"
    return ClosestPairs(points, distance, labels, root_link(Path(model.urdf)))


def root_link(urdf: Path) -> str:
    """The URDF's root link (the one no joint has as its child): Rerun's name of the world frame."""
    import xml.etree.ElementTree as ET

    root = ET.parse(urdf).getroot()
    children = {child.get("link") for joint in root.iter("joint") for child in joint.iter("child")}
    return next(link.get("name", "") for link in root.iter("link") if link.get("name") not in children)


def log_closest_pairs(stamps: FloatArray, pairs: ClosestPairs, safety: float = 0.03, recording: Any = None) -> None:
    """The closest pair per cycle as a labelled line ``/collision/closest`` (red within 5 mm of the
    safety distance [m], orange inside d_i; an empty line when no pair is that close) and its
    distance as the plot ``/plot/collision/closest_distance_m``."""
    import rerun as rr

    stamps = np.asarray(stamps, dtype=float)
    near = np.isfinite(pairs.distance)
    strips = [p if ok else np.zeros((0, 3)) for p, ok in zip(pairs.points, near, strict=True)]
    colors = [NEAR_COLOR if ok and d < safety + 5e-3 else INFLUENCE_COLOR for d, ok in zip(pairs.distance, near,
                                                                                        strict=True)]
    if len(stamps):
        for entity in (CLOSEST_ENTITY, f"{CLOSEST_ENTITY}/points"):  # witness points are in the world frame
            rr.log(entity, rr.CoordinateFrame(pairs.frame), static=True, recording=recording)
        rr.send_columns(CLOSEST_ENTITY, indexes=[_time(stamps)],
                        columns=rr.LineStrips3D.columns(strips=strips, colors=colors, labels=pairs.labels,
                                                        radii=[0.004] * len(stamps)), recording=recording)
        rr.send_columns(f"{CLOSEST_ENTITY}/points", indexes=[_time(stamps)],  # the witness points, visible from afar
                        columns=rr.Points3D.columns(positions=np.concatenate(strips), colors=np.repeat(
                            np.array(colors, dtype=np.uint8), [len(x) for x in strips], axis=0),
                            radii=np.full(sum(len(x) for x in strips), WITNESS_RADIUS_M)).partition(
                            [len(x) for x in strips]), recording=recording)
    log_series(stamps, {CLOSEST_DISTANCE: pairs.distance}, recording)


def velocity_norm_series(qd: FloatArray, threshold: float = ACTIVITY_THRESHOLD) -> dict[str, FloatArray]:
    """‖q̇‖₀ (joints with |q̇ᵢ| > ``threshold``, Fig. 5 of paper 000) and ‖q̇‖₁ [rad/s] per cycle.

    Args:
        qd: joint velocities (commands) per cycle [rad/s], (N, n).
    Returns:
        ``{VELOCITY_L0: (N,), VELOCITY_L1: (N,)}``.
    """
    qd = np.asarray(qd, dtype=float)
    return {VELOCITY_L0: l0_norms(qd, threshold).astype(float), VELOCITY_L1: np.abs(qd).sum(axis=1)}


def _time(stamps: FloatArray) -> Any:
    import rerun as rr

    return rr.TimeColumn(TIMELINE, duration=np.asarray(stamps, dtype=float))


def robot_name(urdf: Path) -> str:
    """The ``<robot name=...>`` of a URDF: the root entity Rerun's importer logs it under."""
    import rerun.urdf

    return str(rerun.urdf.UrdfTree.from_file_path(urdf).name)


def log_model(urdf: Path, recording: Any = None) -> None:
    """The cell's URDF (static: geometry, fixed joints) and the tools' axes."""
    import rerun as rr

    rr.log_file_from_path(urdf, static=True, recording=recording)
    for frame in TOOL_FRAMES:
        rr.log(f"frames/{frame}", rr.TransformAxes3D(AXIS_LENGTH_M), rr.CoordinateFrame(frame), static=True,
               recording=recording)


def log_joints(urdf: Path, stamps: FloatArray, q: FloatArray, joint_names: Sequence[str],
               recording: Any = None) -> None:
    """Each URDF joint named in ``joint_names`` at every cycle: ``/joint_tf/<joint>``.

    Args:
        stamps: cycle times [s], (N,).
        q: joint positions [rad], (N, len(joint_names)), columns in ``joint_names`` order.
    """
    import rerun as rr
    import rerun.urdf

    q = np.asarray(q, dtype=float)
    column = {name: i for i, name in enumerate(joint_names)}
    tree = rerun.urdf.UrdfTree.from_file_path(urdf)
    for joint in tree.joints():
        if joint.name in column:
            rr.send_columns(f"joint_tf/{joint.name}", indexes=[_time(stamps)],
                            columns=joint.compute_transform_columns(q[:, column[joint.name]].tolist(), clamp=False),
                            recording=recording)


def log_series(stamps: FloatArray, series: Mapping[str, FloatArray], recording: Any = None) -> None:
    """Scalars ``/plot/<name>`` per cycle (non-finite samples are left out: a gap in the plot).

    Args:
        stamps: cycle times [s], (N,).
        series: ``{"group/name": values (N,)}``; the group is the plot it goes to.
    """
    import rerun as rr

    stamps = np.asarray(stamps, dtype=float)
    for name, values in series.items():
        values = np.asarray(values, dtype=float)
        keep = np.isfinite(values)
        if keep.any():
            rr.send_columns(f"plot/{name}", indexes=[_time(stamps[keep])],
                            columns=rr.Scalars.columns(scalars=values[keep]), recording=recording)


def log_frames(stamps: FloatArray, frames: Mapping[str, FloatArray], parent: str = TOOL_FRAME,
               recording: Any = None) -> None:
    """Poses in the ``parent`` frame per cycle, drawn as axes: ``/frames/<name>``.

    Args:
        stamps: cycle times [s], (N,).
        frames: ``{name: (N, 7) [x, y, z [m], qx, qy, qz, qw]}`` (e.g. the relative target, the goal).
    """
    import rerun as rr

    stamps = np.asarray(stamps, dtype=float)
    for name, poses in frames.items():
        poses = np.asarray(poses, dtype=float).reshape(-1, 7)
        keep = np.isfinite(poses).all(axis=1)
        if not keep.any():
            continue
        n = int(keep.sum())
        rr.log(f"frames/{name}", rr.TransformAxes3D(AXIS_LENGTH_M), rr.CoordinateFrame(name), static=True,
               recording=recording)
        rr.send_columns(f"frames/{name}/pose", indexes=[_time(stamps[keep])],
                        columns=rr.Transform3D.columns(translation=poses[keep, :3], quaternion=poses[keep, 3:],
                                                       parent_frame=[parent] * n, child_frame=[name] * n),
                        recording=recording)


def log_statuses(stamps: FloatArray, statuses: Sequence[str], previous: str | None = None,
                 recording: Any = None) -> str | None:
    """Solver status changes as a text log ``/status`` (a failure status at level ERROR).

    Args:
        stamps: cycle times [s], (N,). statuses: solver status per cycle (N,).
        previous: the status before the first cycle (the live view passes the last batch's).
    Returns:
        the last status (``previous`` when there is none).
    """
    import rerun as rr

    times, texts, levels = [], [], []
    for t, status in zip(np.asarray(stamps, dtype=float), statuses, strict=True):
        if status != previous:
            times.append(t)
            texts.append(f"solver status: {status}" if previous is None else f"solver status: {previous} -> {status}")
            levels.append("ERROR" if status in FAILURE_STATUSES else "INFO")
            previous = status
    if times:
        rr.send_columns(STATUS_ENTITY, indexes=[_time(np.array(times))],
                        columns=rr.TextLog.columns(text=texts, level=levels), recording=recording)
    return previous


def blueprint(robot: str, groups: Sequence[str], with_status: bool = True) -> Any:
    """3D view of the cell (collision geometry hidden, camera on both arms) beside one plot per group."""
    import rerun.blueprint as rrb

    camera = rrb.EyeControls3D(position=EYE_POSITION, look_target=LOOK_TARGET, eye_up=(0.0, 0.0, 1.0))
    spatial = rrb.Spatial3DView(origin="/", name="cell",
                                contents=["/**", f"- /{robot}/collision_geometries/**", "- /plot/**"],
                                eye_controls=camera)
    plots: list[Any] = [rrb.TimeSeriesView(origin=f"/plot/{group}", name=group) for group in groups]
    if with_status:
        plots.append(rrb.TextLogView(origin=f"/{STATUS_ENTITY}", name="solver status"))
    right = rrb.Vertical(*plots) if plots else rrb.Vertical()
    return rrb.Blueprint(rrb.Horizontal(spatial, right, column_shares=[3, 2]), rrb.TimePanel(timeline=TIMELINE),
                         collapse_panels=True)


def series_groups(names: Sequence[str]) -> list[str]:
    """The plot groups of series names ``group/name`` in first-seen order."""
    return list(dict.fromkeys(name.split("/", 1)[0] for name in names))


def log_run(urdf: Path, stamps: FloatArray, q: FloatArray, joint_names: Sequence[str],
            series: Mapping[str, FloatArray], *, frames: Mapping[str, FloatArray] | None = None,
            statuses: Sequence[str] | None = None, recording: Any = None, send_blueprint: bool = True,
            closest: ClosestPairs | None = None) -> None:
    """Log a whole run: the posed URDF, frames, plots and status changes, on the ``time`` timeline.

    Args:
        urdf: the cell's URDF (geometry and joint axes).
        stamps: cycle times [s] from the start of the run, (N,), non-decreasing.
        q: joint positions [rad], (N, n), columns in ``joint_names`` order.
        joint_names: URDF joint names of the columns of ``q`` (n,).
        series: ``{"group/name": (N,)}`` scalars per cycle, e.g. :func:`velocity_norm_series`,
            tracking errors, solve and cycle time [s], task values and bounds, contact force [N].
        frames: ``{name: (N, 7)}`` poses [x y z qx qy qz qw] in the left tool frame (the
            relative target, the goal).
        statuses: solver status per cycle (N,); its changes go to the text log.
        recording: a ``rerun.RecordingStream`` (default: the global one).
        send_blueprint: also send :func:`blueprint` (the layout of the viewer).
        closest: the closest link pair per cycle (:func:`closest_pairs`), drawn by :func:`log_closest_pairs`.
    """
    import rerun as rr

    stamps = np.asarray(stamps, dtype=float)
    q = np.asarray(q, dtype=float)
    n = len(stamps)
    if q.shape != (n, len(joint_names)):
        raise ValueError(f"q must be (N, {len(joint_names)}) with N = {n} stamps, got {q.shape}")
    for name, values in {**series, **(frames or {})}.items():
        if len(values) != n:
            raise ValueError(f"{name}: {len(values)} values for {n} stamps")
    if statuses is not None and len(statuses) != n:
        raise ValueError(f"statuses: {len(statuses)} values for {n} stamps")
    urdf = Path(urdf)
    if send_blueprint:
        groups = series_groups([*series, *([CLOSEST_DISTANCE] if closest is not None else [])])
        rr.send_blueprint(blueprint(robot_name(urdf), groups, statuses is not None), recording=recording)
    log_model(urdf, recording)
    log_joints(urdf, stamps, q, joint_names, recording)
    log_frames(stamps, frames or {}, recording=recording)
    log_series(stamps, series, recording)
    if statuses is not None:
        log_statuses(stamps, statuses, recording=recording)
    if closest is not None:
        log_closest_pairs(stamps, closest, recording=recording)
