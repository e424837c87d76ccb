"""Live obstacles from topics (issue 42, parts 2-3; docs/obstacles.md): visualization_msgs/MarkerArray
on ``/collision_objects`` and a sensor_msgs/PointCloud2 topic, taken in off the control thread.

The subscriptions are raw (CDR bytes): their callbacks, on the executor's thread, only append the
bytes to a bounded queue (markers: the 64 latest; a cloud: the latest only). A worker thread
deserializes, checks and converts them, updates the :class:`~dualarm_control.collision.live_feed.LiveScene`
and publishes a finished snapshot that the control thread swaps in (one attribute read per cycle).

Markers (``ns`` and ``id`` name the obstacle: ``<ns>`` for id 0, else ``<ns>_<id>``): CUBE (a box of ``scale``), SPHERE
(``scale`` the diameters: a sphere, or an ellipsoid when they differ), CYLINDER (diameters x, y:
the larger one, height z), MESH_RESOURCE (``file://`` .obj/.stl, its convex hull, scaled); actions
ADD/MODIFY, DELETE, DELETEALL; ``lifetime`` honoured (0: forever); ``frame_id`` a frame of the robot
that no arm joint moves (the world, the torso, the arm mounts: :func:`fixed_frames`). The velocity
comes from successive poses (header stamps). Refused with a reason, throttled in the log: NaN or
inf in the pose, a zero quaternion, a size <= 0, an unknown frame or type, a mesh that is not a
readable file, more obstacles than ``collision.live_obstacles``. A cloud of more points than
``obstacles.cloud_max_points`` is decimated (said once per second).
"""

from __future__ import annotations

import collections
import math
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import coal
import numpy as np
import pinocchio as pin

from dualarm_control.arrays import FloatArray
from dualarm_control.collision.cloud import (
    DEFAULT_MAX_POINTS,
    DEFAULT_VOXEL,
    voxel_octree,
    voxel_sphere,
    voxelise,
)
from dualarm_control.collision.live import LiveObstacle, shape_sphere
from dualarm_control.collision.live_feed import LiveObstacleFeed, LiveScene
from dualarm_control.errors import InputRejected
from dualarm_control.params import ParamSpec, non_negative, positive
from dualarm_control.ros.convert import rotation_xyzw
from dualarm_control.ros.inputs import DESERIALIZE_ERRORS, Throttle
from dualarm_control.ros.marker_kinds import (
    CUBE,
    CYLINDER,
    DELETE,
    DELETEALL,
    SPHERE,
    TYPES,
    marker_name,
)
from dualarm_control.ros.point_cloud import cloud_message, cloud_points

MARKER_QUEUE = 64
"""Marker arrays waiting for the worker; an older one is dropped when a new one comes (counted)."""

OBSTACLE_PARAMETERS = (
    ParamSpec("obstacles.topic", "/collision_objects", "live obstacles: visualization_msgs/MarkerArray topic "
              "('' = none; used when collision.live_obstacles > 0)", read_only=True),
    ParamSpec("obstacles.cloud_topic", "", "live obstacles: sensor_msgs/PointCloud2 topic of a depth camera "
              "('' = none)", read_only=True),
    ParamSpec("obstacles.cloud_voxel", DEFAULT_VOXEL, "point cloud voxel side [m] (the octree's resolution)",
              check=positive, read_only=True),
    ParamSpec("obstacles.cloud_max_points", DEFAULT_MAX_POINTS, "a larger cloud is decimated to at most this many "
              "points first", check=positive, read_only=True),
    ParamSpec("obstacles.cloud_lifetime", 1.0, "a cloud is dropped this long [s] after it came (0 = kept until "
              "the next)", check=non_negative, read_only=True),
)
"""controller_node's parameters of the live obstacles' topics."""


def fixed_frames(model: pin.Model) -> dict[str, tuple[FloatArray, FloatArray]]:
    """The frames of ``model`` that no joint moves (on the universe joint), by name: (R (3, 3), p [m] (3,))
    in the world. ``world`` and the model's root are the identity."""
    frames = {"world": (np.eye(3), np.zeros(3))}
    for frame in model.frames:
        if frame.parentJoint == 0:
            frames[frame.name] = (np.array(frame.placement.rotation), np.array(frame.placement.translation))
    return frames


def _finite(*values: float) -> bool:
    return all(math.isfinite(v) for v in values)


def marker_shape(marker: Any) -> coal.CollisionGeometry:
    """The coal shape of a CUBE, SPHERE, CYLINDER or MESH_RESOURCE marker (InputRejected otherwise)."""
    s = marker.scale
    size = (float(s.x), float(s.y), float(s.z))
    name = marker_name(marker)
    if marker.type not in TYPES:
        raise InputRejected(f"marker {name!r}: type {marker.type} is not one of "
                            + ", ".join(f"{v} ({k})" for k, v in TYPES.items()), "type", marker.type)
    if not (_finite(*size) and min(size) > 0.0):
        raise InputRejected(f"marker {name!r}: scale {size} must be finite and > 0 [m]", "scale", size)
    if marker.type == CUBE:
        return coal.Box(*size)
    if marker.type == SPHERE:
        return coal.Sphere(size[0] / 2) if size[0] == size[1] == size[2] else coal.Ellipsoid(*(v / 2 for v in size))
    if marker.type == CYLINDER:
        return coal.Cylinder(max(size[0], size[1]) / 2, size[2])
    resource = str(marker.mesh_resource)
    path = Path(resource.removeprefix("file://"))
    if not resource.startswith("file://") or path.suffix.lower() not in (".obj", ".stl") or not path.is_file():
        raise InputRejected(f"marker {name!r}: mesh_resource {resource!r} is not a file:// .obj or .stl file",
                            "mesh_resource", resource)
    try:
        mesh = coal.MeshLoader().load(str(path), np.array(size))
        mesh.buildConvexHull(True, "Qt")
    except Exception as exc:  # assimp's and qhull's errors are many; the reason is logged
        raise InputRejected(f"marker {name!r}: mesh {resource!r} unreadable: {exc}", "mesh_resource", resource) from exc
    return mesh.convex


ShapeCache = dict[tuple[Any, ...], tuple[coal.CollisionGeometry, tuple[FloatArray, float]]]
"""Marker shapes already built, with their bounding spheres, by (type, scale, mesh_resource)."""

SHAPES_KEPT = 256
"""Entries a :data:`ShapeCache` holds at most (emptied past this many)."""


def cached_marker_shape(marker: Any, shapes: ShapeCache) -> tuple[coal.CollisionGeometry, tuple[FloatArray, float]]:
    """:func:`marker_shape` and its bounding sphere, built once per (type, scale, mesh_resource): a marker that only
    moves keeps its shape object, so the controller's live obstacle limit keeps its table entries and known bounds
    (:class:`~dualarm_control.collision.live.LiveDistances`), and a mesh is read once per path and scale."""
    s = marker.scale
    key = (int(marker.type), float(s.x), float(s.y), float(s.z), str(marker.mesh_resource))
    found = shapes.get(key)
    if found is None:  # a NaN scale never matches: marker_shape refuses it
        shape = marker_shape(marker)
        found = (shape, shape_sphere(shape))
        if len(shapes) >= SHAPES_KEPT:
            shapes.clear()
        shapes[key] = found
    return found


def marker_obstacle(marker: Any, frames: dict[str, tuple[FloatArray, FloatArray]], now: float,
                    shapes: ShapeCache | None = None) -> LiveObstacle:
    """A marker (ADD) as a live obstacle in the world, expiring ``lifetime`` after ``now`` [s, the
    feed's clock]; InputRejected naming the marker and the bad field. ``shapes``: the shapes already built
    (:func:`cached_marker_shape`), None to build this one."""
    name = marker_name(marker)
    frame = frames.get(str(marker.header.frame_id))
    if frame is None:
        raise InputRejected(f"marker {name!r}: frame_id {marker.header.frame_id!r} is not a fixed frame of the robot "
                            f"(one of: {', '.join(sorted(frames))})", "frame_id", marker.header.frame_id)
    p, o = marker.pose.position, marker.pose.orientation
    position = (float(p.x), float(p.y), float(p.z))
    if not _finite(*position):
        raise InputRejected(f"marker {name!r}: position {position} is not finite", "pose", position)
    rotation = rotation_xyzw(np.array([o.x, o.y, o.z, o.w], dtype=float))
    if not np.isfinite(rotation).all():
        raise InputRejected(f"marker {name!r}: orientation ({o.x}, {o.y}, {o.z}, {o.w}) is not a rotation",
                            "pose", (o.x, o.y, o.z, o.w))
    shape, sphere = cached_marker_shape(marker, {} if shapes is None else shapes)
    lifetime = marker.lifetime.sec + marker.lifetime.nanosec * 1e-9
    base_r, base_p = frame
    return LiveObstacle.make(name, shape, base_r @ rotation, base_r @ np.array(position) + base_p,
                             expires=now + lifetime if lifetime > 0.0 else math.inf, sphere=sphere)


class ObstacleIntake:
    """The worker that turns marker arrays and clouds (CDR bytes) into the feed's snapshots (module docstring).

    Args:
        feed: the controller's live obstacle feed (its slots and clock).
        frames: :func:`fixed_frames` of the robot.
        log: warns ``reason`` (throttled: one line per second per kind, with the count suppressed).
        voxel, max_points, cloud_lifetime: the cloud's settings (:data:`OBSTACLE_PARAMETERS`).
        deserialize: bytes -> message (``rclpy.serialization.deserialize_message`` with the type).
    """

    def __init__(self, feed: LiveObstacleFeed, frames: dict[str, tuple[FloatArray, FloatArray]],
                 log: Callable[[str], None], deserialize: Callable[[bytes, str], Any], voxel: float = DEFAULT_VOXEL,
                 max_points: int = DEFAULT_MAX_POINTS, cloud_lifetime: float = 1.0) -> None:
        self.scene = LiveScene(feed)
        self.shapes: ShapeCache = {}
        self.frames, self.log, self.deserialize = frames, log, deserialize
        self.voxel, self.max_points, self.cloud_lifetime = voxel, max_points, cloud_lifetime
        self._markers: collections.deque[bytes] = collections.deque(maxlen=MARKER_QUEUE)
        self._cloud: collections.deque[bytes] = collections.deque(maxlen=1)
        self._wake = threading.Event()
        self._stop = threading.Event()
        self._throttles: dict[str, Throttle] = collections.defaultdict(Throttle)
        self.count = collections.Counter[str]()
        self.cloud_seconds: list[float] = []  # each cloud's intake [s]: its bytes to the snapshot holding it
        self.cloud_cpu_seconds: list[float] = []  # the worker thread's CPU time of each [s]
        self._thread = threading.Thread(target=self._run, name="obstacle_intake", daemon=True)

    # ---- the executor's side: append and return ------------------------------------------------
    def on_markers(self, data: bytes) -> None:
        if len(self._markers) == MARKER_QUEUE:
            self.count["markers_dropped"] += 1
        self._markers.append(data)
        self._wake.set()

    def on_cloud(self, data: bytes) -> None:
        if self._cloud:
            self.count["clouds_dropped"] += 1
        self._cloud.append(data)
        self._wake.set()

    # ---- the worker ------------------------------------------------------------------------------
    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self._wake.set()
        if self._thread.is_alive():
            self._thread.join(timeout=2.0)

    def _run(self) -> None:
        while not self._stop.is_set():
            self._wake.wait(timeout=0.05)
            self._wake.clear()
            self.process()

    def process(self) -> None:
        """Everything queued, then one snapshot (also called directly by tests and benchmarks); a cloud's
        intake time runs from its bytes to the snapshot that holds it (:attr:`cloud_seconds`; the worker thread's
        CPU time meanwhile in :attr:`cloud_cpu_seconds`: without the waits for a core or the interpreter's lock)."""
        changed = False
        while self._markers:
            self.take_markers(self._markers.popleft())
            changed = True
        cloud_start = cpu_start = None
        if self._cloud:
            cloud_start, cpu_start = time.perf_counter(), time.thread_time()
            if self.take_cloud(self._cloud.popleft()):
                changed = True
            else:
                cloud_start = None
        if changed or self.scene.obstacles:
            previous = self.scene.publish()
            if cloud_start is not None and cpu_start is not None:
                self.cloud_seconds.append(time.perf_counter() - cloud_start)
                self.cloud_cpu_seconds.append(time.thread_time() - cpu_start)
            del previous  # the replaced snapshot (an old cloud's octree) is freed after the swap

    def warn(self, kind: str, reason: str) -> None:
        self.count[kind] += 1
        text = self._throttles[kind].text(reason)
        if text is not None:
            self.log(text)

    def take_markers(self, data: bytes) -> None:
        try:
            msg = self.deserialize(data, "markers")
        except DESERIALIZE_ERRORS as exc:
            self.warn("markers_malformed", f"malformed MarkerArray ({len(data)} bytes): {exc}")
            return
        now = self.scene.feed.clock()
        for marker in msg.markers:
            if marker.action == DELETEALL:
                self.scene.clear()
                continue
            name = marker_name(marker)
            if marker.action == DELETE:
                self.scene.delete(name)
                continue
            try:
                obstacle = marker_obstacle(marker, self.frames, now, self.shapes)
            except InputRejected as exc:
                self.warn("markers_refused", "live obstacle refused: " + exc.reason)
                continue
            stamp = marker.header.stamp.sec + marker.header.stamp.nanosec * 1e-9
            reason = self.scene.add(obstacle, stamp)
            if reason is None:
                self.count["markers"] += 1
            else:
                self.warn("markers_refused", reason)

    def take_cloud(self, data: bytes) -> bool:
        """A cloud's bytes into the scene (not yet published); False when it was refused."""
        try:
            msg = cloud_message(data, lambda payload: self.deserialize(payload, "cloud"))
            points = cloud_points(msg)
        except InputRejected as exc:
            self.warn("clouds_refused", "point cloud refused: " + exc.reason)
            return False
        except DESERIALIZE_ERRORS as exc:
            self.warn("clouds_refused", f"malformed PointCloud2 ({len(data)} bytes): {exc}")
            return False
        frame = self.frames.get(str(msg.header.frame_id))
        if frame is None:
            self.warn("clouds_refused", f"point cloud refused: frame_id {msg.header.frame_id!r} is not a fixed frame "
                                        f"of the robot (one of: {', '.join(sorted(self.frames))})")
            return False
        try:
            voxels = voxelise(points, self.voxel, self.max_points)
        except ValueError as exc:  # a point beyond the voxel grid (a corrupt cloud)
            self.warn("clouds_refused", f"point cloud refused: {exc}")
            return False
        if voxels.note():
            self.warn("clouds_reduced", voxels.note())
        if not len(voxels.centres):
            self.scene.delete("cloud")
        else:  # replaces the last cloud in the scene; its octree is freed once the new snapshot is out
            now = self.scene.feed.clock()
            expires = now + self.cloud_lifetime if self.cloud_lifetime > 0.0 else math.inf
            obstacle = LiveObstacle.make("cloud", voxel_octree(voxels), frame[0], frame[1], expires=expires,
                                         sphere=voxel_sphere(voxels))
            reason = self.scene.add(obstacle, now, velocity_given=True)
            if reason is not None:
                self.warn("clouds_refused", reason)
        self.count["clouds"] += 1
        return True


def start_intake(node: Any, feed: LiveObstacleFeed, model: pin.Model, values: dict[str, Any]) -> ObstacleIntake:
    """The intake of ``node`` (an rclpy node) for ``feed``: raw subscriptions on ``obstacles.topic`` and
    ``obstacles.cloud_topic`` (those not ''), the worker started; ``stop()`` it when the node closes."""
    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import PointCloud2
    from visualization_msgs.msg import MarkerArray

    types = {"markers": MarkerArray, "cloud": PointCloud2}
    logger = node.get_logger()
    intake = ObstacleIntake(feed, fixed_frames(model), logger.warning,
                            lambda data, kind: deserialize_message(data, types[kind]),
                            float(values["obstacles.cloud_voxel"]), int(values["obstacles.cloud_max_points"]),
                            float(values["obstacles.cloud_lifetime"]))
    if values["obstacles.topic"]:
        node.create_subscription(MarkerArray, values["obstacles.topic"], intake.on_markers, 10, raw=True)
    if values["obstacles.cloud_topic"]:
        node.create_subscription(PointCloud2, values["obstacles.cloud_topic"], intake.on_cloud, 1, raw=True)
    intake.start()
    logger.info(f"live obstacles: up to {feed.slots} from {values['obstacles.topic'] or 'no marker topic'}"
                f" and {values['obstacles.cloud_topic'] or 'no point cloud'}")
    return intake


def obstacle_intake(node: Any, controller: Any, values: dict[str, Any]) -> ObstacleIntake | None:
    """:func:`start_intake` for ``controller``'s live obstacle limit, None when it has none
    (``collision.live_obstacles`` 0 or the collision limit off)."""
    limit = controller.limit("live_obstacles")
    if limit is None or controller.collision_model is None:
        return None
    return start_intake(node, limit.feed, controller.collision_model.model, values)
