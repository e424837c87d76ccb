"""The cell's obstacles as a bag recorded them, drawn by ``dualarm view`` (Rerun) and the video (docs/obstacles.md).

A bag keeps the scene latched on ``/dualarm/obstacles`` and, when something moves, its markers on
``/collision_objects`` at every step (:mod:`dualarm_control.ros.obstacle_markers`): both
visualization_msgs/MarkerArray in the frame ``world``. :func:`read_obstacles` reads them into plain
values; :func:`log_obstacles` logs them to Rerun under ``obstacles/<name>``: a shape at the
entity's origin (a box, an ellipsoid, a cylinder, a mesh's file) and its pose as a transform, static
or, for a marker that moves, on the run's timeline (the markers' stamps, the clock of the joint states).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from dualarm_control.arrays import FloatArray

SCENE_TOPIC = "/dualarm/obstacles"
LIVE_TOPIC = "/collision_objects"
CUBE, SPHERE, CYLINDER, MESH_RESOURCE = 1, 2, 3, 10


@dataclass
class ObstacleTrack:
    """One obstacle's shape and poses.

    Attributes:
        name: the marker's ns (``<ns>_<id>`` for an id other than 0). kind: the marker type.
        scale: [m] (3,). colour: RGBA 0-1 (4,). mesh: a MESH_RESOURCE's file path ('' otherwise).
        stamps: the poses' stamps [ns], (k,). positions: [m], (k, 3). quaternions: (x, y, z, w), (k, 4).
    """

    name: str
    kind: int
    scale: FloatArray
    colour: FloatArray
    mesh: str = ""
    stamps: list[int] = field(default_factory=list)
    positions: list[FloatArray] = field(default_factory=list)
    quaternions: list[FloatArray] = field(default_factory=list)

    def add(self, stamp: int, marker: Any) -> None:
        p, o = marker.pose.position, marker.pose.orientation
        self.stamps.append(stamp)
        self.positions.append(np.array([p.x, p.y, p.z], dtype=float))
        self.quaternions.append(np.array([o.x, o.y, o.z, o.w], dtype=float))


def _name(marker: Any) -> str:
    ns = str(marker.ns) or "marker"
    return ns if marker.id == 0 else f"{ns}_{marker.id}"


def add_markers(tracks: dict[str, ObstacleTrack], message: Any, live: bool) -> None:
    """A MarkerArray's obstacles (ADD of CUBE, SPHERE, CYLINDER, MESH_RESOURCE; rosbags' or rclpy's message)
    into ``tracks`` by name: a new track for a new name, one more pose for a known one, stamped with the
    marker's stamp [ns] when ``live`` (the moving obstacles' topic), -1 for the latched scene."""
    for marker in message.markers:
        if marker.action != 0 or marker.type not in (CUBE, SPHERE, CYLINDER, MESH_RESOURCE):
            continue
        name = _name(marker)
        track = tracks.get(name)
        if track is None:
            s, c = marker.scale, marker.color
            track = tracks[name] = ObstacleTrack(
                name, int(marker.type), np.array([s.x, s.y, s.z], dtype=float),
                np.array([c.r, c.g, c.b, c.a if c.a > 0 else 1.0], dtype=float),
                str(marker.mesh_resource).removeprefix("file://"))
        stamp = marker.header.stamp.sec * 1_000_000_000 + marker.header.stamp.nanosec
        track.add(stamp if live else -1, marker)


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


def log_obstacles(tracks: dict[str, ObstacleTrack], start_ns: int, recording: Any = None, world: str = "world") -> None:
    """Each obstacle under ``obstacles/<name>``: its shape (static) in its own frame ``obstacle_<name>``
    and that frame's pose in the named frame ``world`` (the URDF's root link, where the URDF's links
    hang: the markers' frame), static when it has one pose from the scene only, else on the ``time``
    timeline at (stamp - ``start_ns``) [s]."""
    import rerun as rr

    from dualarm_control.app.view.rerun_view import TIMELINE

    for track in tracks.values():
        path = f"obstacles/{track.name}"
        half = track.scale / 2.0
        colour = (np.clip(track.colour, 0.0, 1.0) * 255).astype(np.uint8)
        if track.kind == CUBE:
            shape: Any = rr.Boxes3D(half_sizes=[half], colors=[colour], fill_mode="solid")
        elif track.kind == SPHERE:
            shape = rr.Ellipsoids3D(half_sizes=[half], colors=[colour], fill_mode="solid")
        elif track.kind == CYLINDER:
            shape = rr.Cylinders3D(lengths=[track.scale[2]], radii=[max(half[0], half[1])], colors=[colour],
                                   fill_mode="solid")
        elif track.mesh and Path(track.mesh).is_file():
            shape = rr.Asset3D(path=track.mesh)  # scaled: its vertices in the file's units times the marker's scale
            rr.log(path + "/shape", rr.InstancePoses3D(scales=[track.scale]), static=True, recording=recording)
        else:
            continue
        frame = f"obstacle_{track.name}"
        rr.log(path + "/shape", shape, rr.CoordinateFrame(frame), static=True, recording=recording)
        live = [i for i, s in enumerate(track.stamps) if s >= 0]
        if not live:  # static data wins over temporal data in Rerun: only for a still obstacle
            rr.log(path, rr.Transform3D(translation=track.positions[0], quaternion=rr.Quaternion(xyzw=track.quaternions[0]),
                                        parent_frame=world, child_frame=frame), static=True, recording=recording)
            continue
        stamps = (np.array([track.stamps[i] for i in live], dtype=np.int64) - start_ns) * 1e-9
        rr.send_columns(path, indexes=[rr.TimeColumn(TIMELINE, duration=stamps)],
                        columns=rr.Transform3D.columns(translation=np.array([track.positions[i] for i in live]),
                                                       quaternion=np.array([track.quaternions[i] for i in live]),
                                                       parent_frame=[world] * len(live), child_frame=[frame] * len(live)),
                        recording=recording)


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
        """Each moving obstacle at its last recorded pose at or before ``stamp_ns``."""
        for name, body in self.bodies.items():
            track = self.tracks[name]
            i = int(np.searchsorted(track.stamps, stamp_ns, side="right")) - 1  # stamps ascending (the scene's: -1)
            if i >= 0 and track.stamps[i] >= 0:
                self._p.resetBasePositionAndOrientation(body, track.positions[i].tolist(),
                                                        track.quaternions[i].tolist(), physicsClientId=self.client)
