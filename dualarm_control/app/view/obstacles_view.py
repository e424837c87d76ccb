"""The cell's obstacles as a bag recorded them, drawn by ``dualarm view`` (Rerun) and the video (docs/obstacles.md).

A bag keeps the scene latched on ``/dualarm/obstacles`` and, when something moves, its markers on
``/collision_objects`` at every step (:mod:`dualarm_control.ros.obstacle_markers`): both
visualization_msgs/MarkerArray in the frame ``world``. :func:`read_obstacles` reads them into plain
values; :func:`log_obstacles` logs them to Rerun under ``obstacles/<name>``: a shape at the
entity's origin (a box, an ellipsoid, a cylinder, a mesh's file) and its pose as a transform, static
or, for a marker that moves, on the run's timeline (the markers' stamps, the clock of the joint states).

A live marker is shown as the controller takes it (:mod:`dualarm_control.ros.obstacle_io`): from its
first ADD until a DELETE of its name, a DELETEALL, or the end of its ``lifetime`` (0: forever) with no
newer ADD; an ADD after that shows it again. Those spans (:attr:`ObstacleTrack.spans`) clear it in Rerun
(``rr.Clear`` at the end, the shape logged again at the next start) and hide it in the video. DELETE and
DELETEALL on the live topic touch only the live markers, as in the controller (the latched scene is the
configuration's). A DELETE or DELETEALL with a zero stamp (RViz needs none) takes the latest stamp seen
on the topic.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from dualarm_control.arrays import FloatArray
from dualarm_control.ros.marker_kinds import (
    ADD,
    CUBE,
    CYLINDER,
    DELETE,
    DELETEALL,
    LIVE_TOPIC,
    MESH_RESOURCE,
    SPHERE,
    marker_name,
)
from dualarm_control.ros.marker_kinds import OBSTACLES_TOPIC as SCENE_TOPIC

HIDDEN_AT = (0.0, 0.0, -1000.0)
"""Where the video's camera puts an obstacle that is not shown at a frame's stamp [m]."""


@dataclass
class ObstacleTrack:
    """One obstacle's shape and poses.

    Attributes:
        name: the marker's ns (``<ns>_<id>`` for an id other than 0). kind: the marker type.
        scale: [m] (3,). colour: RGBA 0-1 (4,). mesh: a MESH_RESOURCE's file path ('' otherwise).
        stamps: the poses' stamps [ns], (k,). positions: [m], (k, 3). quaternions: (x, y, z, w), (k, 4).
        spans: when it is shown, [start, end) [ns] each, in order; end None: until the end of the run
            (the latched scene's one span: [-1, None)).
        spans_logged, poses_logged: how many of the first spans' starts and poses a live view has logged already.
    """

    name: str
    kind: int
    scale: FloatArray
    colour: FloatArray
    mesh: str = ""
    stamps: list[int] = field(default_factory=list)
    positions: list[FloatArray] = field(default_factory=list)
    quaternions: list[FloatArray] = field(default_factory=list)
    spans: list[tuple[int, int | None]] = field(default_factory=list)
    spans_logged: int = 0
    poses_logged: int = 0

    def add(self, stamp: int, marker: Any) -> None:
        """One more pose at ``stamp`` [ns]: it continues the last span when that has not ended before ``stamp``
        (its end moves to this pose's lifetime's end), else it starts a new one."""
        p, o = marker.pose.position, marker.pose.orientation
        self.stamps.append(stamp)
        self.positions.append(np.array([p.x, p.y, p.z], dtype=float))
        self.quaternions.append(np.array([o.x, o.y, o.z, o.w], dtype=float))
        lifetime = marker.lifetime.sec * 1_000_000_000 + marker.lifetime.nanosec
        end = stamp + lifetime if lifetime > 0 and stamp >= 0 else None
        if self.spans and self.shown(stamp):
            self.spans[-1] = (self.spans[-1][0], end)
        else:
            self.spans.append((stamp, end))

    def remove(self, stamp: int) -> None:
        """A DELETE (or DELETEALL) at ``stamp`` [ns]: the last span ends there unless it ended before."""
        if self.spans and self.shown(stamp):
            self.spans[-1] = (self.spans[-1][0], stamp)

    def shown(self, stamp: int) -> bool:
        """Whether the obstacle is shown at ``stamp`` [ns] (its last span started at or before it and has not ended)."""
        for start, end in reversed(self.spans):
            if start <= stamp:
                return end is None or stamp < end
        return False

    @property
    def live(self) -> bool:
        """Whether it came from the live topic (not the latched scene)."""
        return bool(self.spans) and self.spans[0][0] >= 0

    def ends(self, until: int | None = None) -> list[int]:
        """The stamps [ns] where a span ended, those at or before ``until`` only when given."""
        return [end for _, end in self.spans if end is not None and (until is None or end <= until)]

    def trimmed(self) -> ObstacleTrack:
        """This track with its last pose and its last span only (what a live view keeps after logging: a later
        DELETE with a zero stamp takes that pose's)."""
        return ObstacleTrack(self.name, self.kind, self.scale, self.colour, self.mesh, self.stamps[-1:],
                             self.positions[-1:], self.quaternions[-1:], self.spans[-1:],
                             spans_logged=len(self.spans[-1:]), poses_logged=len(self.stamps[-1:]))


def _stamp(marker: Any) -> int:
    return int(marker.header.stamp.sec) * 1_000_000_000 + int(marker.header.stamp.nanosec)


def add_markers(tracks: dict[str, ObstacleTrack], message: Any, live: bool, latest_ns: int = 0) -> None:
    """A MarkerArray's obstacles (rosbags' or rclpy's message) into ``tracks`` by name: ADD of CUBE, SPHERE,
    CYLINDER, MESH_RESOURCE a new track for a new name, one more pose for a known one, stamped with the
    marker's stamp [ns] when ``live`` (the moving obstacles' topic), -1 for the latched scene; on the live
    topic, DELETE ends the named track's span and DELETEALL every live track's, at the marker's stamp or,
    when that is zero, the latest stamp seen (of the tracks' poses and ``latest_ns``: a live view's clock)."""
    for marker in message.markers:
        action = int(marker.action)
        if live and action in (DELETE, DELETEALL):
            name = marker_name(marker)
            gone = [t for t in tracks.values() if t.live and (action == DELETEALL or t.name == name)]
            stamp = _stamp(marker) or max([latest_ns, *(t.stamps[-1] for t in tracks.values() if t.live and t.stamps)])
            for old in gone:
                old.remove(stamp)
            continue
        if action != ADD or marker.type not in (CUBE, SPHERE, CYLINDER, MESH_RESOURCE):
            continue
        name = marker_name(marker)
        track = tracks.get(name)
        if track is None:
            s, c = marker.scale, marker.color
            track = tracks[name] = ObstacleTrack(
                name, int(marker.type), np.array([s.x, s.y, s.z], dtype=float),
                np.array([c.r, c.g, c.b, c.a if c.a > 0 else 1.0], dtype=float),
                str(marker.mesh_resource).removeprefix("file://"))
        track.add(_stamp(marker) if live else -1, marker)


def read_obstacles(bag: Path) -> dict[str, ObstacleTrack]:
    """The obstacles a bag recorded, by name: the latched scene's (one pose each) and the live markers'
    (one pose per message, ADD only), in the order first seen. {} for a bag without them."""
    from rosbags.highlevel import AnyReader

    tracks: dict[str, ObstacleTrack] = {}
    with AnyReader([Path(bag)]) as reader:
        conns = [c for c in reader.connections if c.topic in (SCENE_TOPIC, LIVE_TOPIC)]
        if not conns:
            return tracks
        for connection, _, raw in reader.messages(connections=conns):
            add_markers(tracks, reader.deserialize(raw, connection.msgtype), connection.topic == LIVE_TOPIC)
    return tracks


def _shape(track: ObstacleTrack) -> Any:
    """The Rerun archetype drawing ``track``'s shape at its entity's origin (None for a mesh that is not a file)."""
    import rerun as rr

    half = track.scale / 2.0
    colour = (np.clip(track.colour, 0.0, 1.0) * 255).astype(np.uint8)
    if track.kind == CUBE:
        return rr.Boxes3D(half_sizes=[half], colors=[colour], fill_mode="solid")
    if track.kind == SPHERE:
        return rr.Ellipsoids3D(half_sizes=[half], colors=[colour], fill_mode="solid")
    if track.kind == CYLINDER:
        return rr.Cylinders3D(lengths=[track.scale[2]], radii=[max(half[0], half[1])], colors=[colour], fill_mode="solid")
    if track.mesh and Path(track.mesh).is_file():
        return rr.Asset3D(path=track.mesh)  # scaled by InstancePoses3D: its vertices in the file's units times the scale
    return None


def log_obstacles(tracks: dict[str, ObstacleTrack], start_ns: int, recording: Any = None, world: str = "world",
                  until_ns: int | None = None) -> None:
    """Each obstacle under ``obstacles/<name>``: its shape in its own frame ``obstacle_<name>`` and that
    frame's pose in the named frame ``world`` (the URDF's root link, where the URDF's links hang: the
    markers' frame). A scene obstacle (one pose, from the latched scene) is static; a live one is on the
    ``time`` timeline at (stamp - ``start_ns``) [s]: its shape at each span's start, its poses, and an
    ``rr.Clear`` at each span's end (at or before ``until_ns`` when given: a live view logs an end once the
    run's clock has passed it, for a newer ADD may still extend the span)."""
    import rerun as rr

    from dualarm_control.app.view.rerun_view import TIMELINE

    def at(stamp: int) -> None:
        rr.set_time(TIMELINE, duration=(stamp - start_ns) * 1e-9, recording=recording)

    for track in tracks.values():
        path, frame = f"obstacles/{track.name}", f"obstacle_{track.name}"
        shape = _shape(track)
        if shape is None:
            continue
        parts = [shape, rr.CoordinateFrame(frame)]
        if track.kind == MESH_RESOURCE:
            parts.append(rr.InstancePoses3D(scales=[track.scale]))
        if not track.live:  # static data wins over temporal data in Rerun: only for a still obstacle
            rr.log(path + "/shape", *parts, static=True, recording=recording)
            rr.log(path, rr.Transform3D(translation=track.positions[0], quaternion=rr.Quaternion(xyzw=track.quaternions[0]),
                                        parent_frame=world, child_frame=frame), static=True, recording=recording)
            continue
        for start, _ in track.spans[track.spans_logged:]:
            at(start)
            rr.log(path + "/shape", *parts, recording=recording)
        new = slice(track.poses_logged, None)
        if track.stamps[new]:
            n = len(track.stamps[new])
            rr.send_columns(path, indexes=[rr.TimeColumn(TIMELINE, duration=(np.array(track.stamps[new]) - start_ns) * 1e-9)],
                            columns=rr.Transform3D.columns(translation=np.array(track.positions[new]),
                                                           quaternion=np.array(track.quaternions[new]),
                                                           parent_frame=[world] * n, child_frame=[frame] * n),
                            recording=recording)
        for end in track.ends(until_ns):
            at(end)
            rr.log(path, rr.Clear(recursive=True), recording=recording)
    rr.disable_timeline(TIMELINE, recording=recording)


class CameraObstacles:
    """The obstacles as visual-only bodies of the video's pybullet client, the moving ones placed per frame."""

    def __init__(self, tracks: dict[str, ObstacleTrack], client: int) -> None:
        import pybullet as p

        self._p, self.client = p, client
        self.bodies: dict[str, int] = {}
        self.tracks = tracks
        for track in tracks.values():
            half, colour = (track.scale / 2.0).tolist(), track.colour.tolist()
            if track.kind == CUBE:
                visual = p.createVisualShape(p.GEOM_BOX, halfExtents=half, rgbaColor=colour, physicsClientId=client)
            elif track.kind == SPHERE:
                visual = p.createVisualShape(p.GEOM_SPHERE, radius=max(half), rgbaColor=colour, physicsClientId=client)
            elif track.kind == CYLINDER:
                visual = p.createVisualShape(p.GEOM_CYLINDER, radius=max(half[0], half[1]), length=track.scale[2],
                                             rgbaColor=colour, physicsClientId=client)
            elif track.mesh and Path(track.mesh).is_file():
                visual = p.createVisualShape(p.GEOM_MESH, fileName=track.mesh, meshScale=track.scale.tolist(),
                                             rgbaColor=colour, physicsClientId=client)
            else:
                continue
            self.bodies[track.name] = p.createMultiBody(0.0, -1, visual, basePosition=track.positions[0].tolist(),
                                                        baseOrientation=track.quaternions[0].tolist(),
                                                        physicsClientId=client)

    def place(self, stamp_ns: int) -> None:
        """Each moving obstacle at its last recorded pose at or before ``stamp_ns``, or out of sight
        (:data:`HIDDEN_AT`) where it is not shown then (before its first ADD, after a DELETE or its lifetime)."""
        for name, body in self.bodies.items():
            track = self.tracks[name]
            if not track.live:
                continue
            if not track.shown(stamp_ns):
                self._p.resetBasePositionAndOrientation(body, HIDDEN_AT, (0.0, 0.0, 0.0, 1.0), physicsClientId=self.client)
            else:  # shown: a span started at a pose at or before stamp_ns (stamps ascending)
                i = int(np.searchsorted(track.stamps, stamp_ns, side="right")) - 1
                self._p.resetBasePositionAndOrientation(body, track.positions[i].tolist(),
                                                        track.quaternions[i].tolist(), physicsClientId=self.client)
