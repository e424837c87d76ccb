"""Live obstacles from topics (issue 42, parts 2-3; docs/obstacles.md), the intake without a ROS graph:
marker arrays and point clouds serialized as a subscription hands them over (CDR bytes), taken in by
:class:`~dualarm_control.ros.obstacle_io.ObstacleIntake` (its worker's step called directly).

* Markers: every type and action, lifetimes, velocity from successive stamps.
* Bad input refused with a reason naming the marker and the value, throttled in the log; the slots.
* A cloud: the same scene as markers and as points on the shapes' surfaces gives the same minimum
  distances to the arm links within a voxel's diagonal; a 1M-point cloud is decimated, said once.
* The executor's side only appends (its cost per message bounded, whatever the cloud's size).
"""

from __future__ import annotations

import functools
import math
import time
from pathlib import Path

import coal
import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import PointCloud2, PointField
from visualization_msgs.msg import Marker, MarkerArray

from dualarm_control.collision import CollisionModel
from dualarm_control.collision.live import LiveDistances, LiveObstacle
from dualarm_control.collision.live_feed import LiveObstacleFeed
from dualarm_control.kinematics import DualArmModel
from dualarm_control.ros.obstacle_io import ObstacleIntake, fixed_frames

TYPES = {"markers": MarkerArray, "cloud": PointCloud2}


@functools.cache
def collision() -> CollisionModel:
    m = DualArmModel("lwr4_cell")
    return CollisionModel(m, allowed=m.description.collision_allowed)


def intake(slots: int = 8, now: list[float] | None = None, voxel: float = 0.02,
           max_points: int = 200_000) -> tuple[ObstacleIntake, list[str]]:
    clock = [0.0] if now is None else now
    logged: list[str] = []
    feed = LiveObstacleFeed(slots, clock=lambda: clock[0])
    return ObstacleIntake(feed, fixed_frames(collision().model), logged.append,
                          lambda data, kind: deserialize_message(data, TYPES[kind]), voxel, max_points), logged


def marker(ns: str, kind: int, scale: tuple[float, float, float], position: tuple[float, float, float],
           action: int = Marker.ADD, frame: str = "world", stamp: float = 0.0, lifetime: float = 0.0,
           quaternion: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0), mesh: str = "") -> Marker:
    m = Marker()
    m.header.frame_id = frame
    m.header.stamp.sec, m.header.stamp.nanosec = int(stamp), round((stamp - int(stamp)) * 1e9)
    m.ns, m.id, m.type, m.action = ns, 0, kind, action
    m.pose.position.x, m.pose.position.y, m.pose.position.z = position
    m.pose.orientation.x, m.pose.orientation.y, m.pose.orientation.z, m.pose.orientation.w = quaternion
    m.scale.x, m.scale.y, m.scale.z = scale
    m.lifetime.sec, m.lifetime.nanosec = int(lifetime), round((lifetime - int(lifetime)) * 1e9)
    m.mesh_resource = mesh
    return m


def send(target: ObstacleIntake, *markers: Marker) -> None:
    msg = MarkerArray()
    msg.markers = list(markers)
    target.on_markers(serialize_message(msg))
    target.process()


def cloud_message(points: np.ndarray, frame: str = "world") -> bytes:
    msg = PointCloud2()
    msg.header.frame_id = frame
    msg.height, msg.width = 1, len(points)
    msg.fields = [PointField(name=c, offset=4 * i, datatype=PointField.FLOAT32, count=1) for i, c in enumerate("xyz")]
    msg.point_step, msg.row_step, msg.is_dense = 16, 16 * len(points), True
    data = np.zeros((len(points), 4), dtype=np.float32)
    data[:, :3] = points
    msg.data = data.tobytes()
    return serialize_message(msg)


def names(target: ObstacleIntake) -> list[str]:
    return sorted(o.name for o in target.scene.feed.snapshot())


def test_every_marker_type_and_action(tmp_path: Path) -> None:
    from test_obstacles import OCTAHEDRON

    mesh = tmp_path / "part.obj"
    mesh.write_text(OCTAHEDRON)
    now = [100.0]
    target, logged = intake(now=now)
    send(target, marker("box", Marker.CUBE, (0.1, 0.2, 0.3), (0.9, 0.3, 1.2)),
         marker("ball", Marker.SPHERE, (0.1, 0.1, 0.1), (0.5, -0.35, 1.15), frame="torso"),
         marker("egg", Marker.SPHERE, (0.1, 0.2, 0.1), (0.5, 0.0, 2.0)),
         marker("post", Marker.CYLINDER, (0.08, 0.08, 0.5), (1.1, 0.0, 1.2), lifetime=0.5),
         marker("part", Marker.MESH_RESOURCE, (0.05, 0.05, 0.05), (0.6, 0.0, 1.3), mesh=f"file://{mesh}"))
    assert not logged, logged
    assert names(target) == ["ball", "box", "egg", "part", "post"]
    torso = fixed_frames(collision().model)["torso"]
    ball = next(o for o in target.scene.feed.snapshot() if o.name == "ball")
    assert np.allclose(ball.position, torso[0] @ [0.5, -0.35, 1.15] + torso[1])  # in the torso's frame
    now[0] = 100.6  # the post's lifetime is over: gone without a message
    assert "post" not in names(target)
    # moved 2 cm along y in 0.05 s: 0.4 m/s
    send(target, marker("box", Marker.CUBE, (0.1, 0.2, 0.3), (0.9, 0.3, 1.2), stamp=1.0))
    send(target, marker("box", Marker.CUBE, (0.1, 0.2, 0.3), (0.9, 0.32, 1.2), stamp=1.05))
    box = next(o for o in target.scene.feed.snapshot() if o.name == "box")
    assert np.allclose(box.velocity, [0.0, 0.4, 0.0])
    send(target, marker("box", 0, (1, 1, 1), (0, 0, 0), action=Marker.DELETE))
    assert "box" not in names(target)
    send(target, marker("", 0, (1, 1, 1), (0, 0, 0), action=Marker.DELETEALL))
    assert names(target) == []


def test_a_marker_that_only_moves_keeps_its_shape_object(tmp_path: Path) -> None:
    """The intake builds a marker's shape once per (type, scale, mesh): a moved marker's obstacle holds the same coal
    shape object, so the controller's limit keeps its table entries and known bounds (LiveDistances); another scale,
    type or mesh builds another."""
    from test_obstacles import OCTAHEDRON

    mesh = tmp_path / "part.obj"
    mesh.write_text(OCTAHEDRON)
    target, logged = intake()

    def shape_of(name: str) -> object:
        return next(o for o in target.scene.feed.snapshot() if o.name == name).shape

    send(target, marker("box", Marker.CUBE, (0.1, 0.2, 0.3), (0.9, 0.3, 1.2)),
         marker("part", Marker.MESH_RESOURCE, (0.05, 0.05, 0.05), (0.6, 0.0, 1.3), mesh=f"file://{mesh}"))
    box, part = shape_of("box"), shape_of("part")
    send(target, marker("box", Marker.CUBE, (0.1, 0.2, 0.3), (0.9, 0.32, 1.2)),
         marker("part", Marker.MESH_RESOURCE, (0.05, 0.05, 0.05), (0.6, 0.05, 1.3), mesh=f"file://{mesh}"))
    assert shape_of("box") is box and shape_of("part") is part
    assert np.allclose(next(o for o in target.scene.feed.snapshot() if o.name == "box").position[1], 0.32)
    send(target, marker("box", Marker.CUBE, (0.1, 0.2, 0.4), (0.9, 0.32, 1.2)))
    assert shape_of("box") is not box and shape_of("box").halfSide[2] == pytest.approx(0.2)
    send(target, marker("box", Marker.SPHERE, (0.1, 0.2, 0.4), (0.9, 0.32, 1.2)))
    assert isinstance(shape_of("box"), coal.Ellipsoid)
    assert not logged, logged


@pytest.mark.parametrize(("bad", "words"), [
    ({"position": (math.nan, 0.0, 1.0)}, "position (nan, 0.0, 1.0) is not finite"),
    ({"quaternion": (0.0, 0.0, 0.0, 0.0)}, "is not a rotation"),
    ({"frame": "left_link_3"}, "frame_id 'left_link_3' is not a fixed frame of the robot"),
    ({"frame": "camera"}, "frame_id 'camera' is not a fixed frame"),
    ({"scale": (0.0, 0.1, 0.1)}, "scale (0.0, 0.1, 0.1) must be finite and > 0"),
    ({"scale": (-0.1, 0.1, 0.1)}, "must be finite and > 0"),
    ({"kind": Marker.ARROW}, "type 0 is not one of CUBE (1), SPHERE (2), CYLINDER (3), MESH_RESOURCE (10)"),
    ({"kind": Marker.MESH_RESOURCE, "mesh": "package://robot/meshes/hand.stl"}, "is not a file:// .obj or .stl"),
])
def test_bad_markers_are_refused_naming_them(bad: dict[str, object], words: str) -> None:
    target, logged = intake()
    args: dict[str, object] = {"ns": "bad", "kind": Marker.CUBE, "scale": (0.1, 0.1, 0.1), "position": (0.5, 0.0, 1.0)}
    args.update(bad)
    send(target, marker(**args), marker("good", Marker.SPHERE, (0.1, 0.1, 0.1), (0.5, 0.0, 2.0)))  # type: ignore[arg-type]
    assert names(target) == ["good"]  # the good one of the same array is kept
    assert len(logged) == 1 and "'bad'" in logged[0] and words in logged[0], logged


def test_more_obstacles_than_slots_and_throttled_reasons() -> None:
    target, logged = intake(slots=3)
    start = time.monotonic()
    for _ in range(50):
        send(target, *[marker(f"m{i}", Marker.SPHERE, (0.1, 0.1, 0.1), (0.5, 0.1 * i, 2.0)) for i in range(5)])
    elapsed = time.monotonic() - start
    assert names(target) == ["m0", "m1", "m2"]
    assert target.count["markers_refused"] == 100
    assert 1 <= len(logged) <= 1 + int(elapsed), (len(logged), elapsed)  # one line a second
    assert "all 3 live obstacle slots are taken" in logged[0]
    before = len(logged)
    time.sleep(1.05)  # the throttle's interval, to see the count of what it held back (not a verdict's wait)
    send(target, marker("m4", Marker.SPHERE, (0.1, 0.1, 0.1), (0.5, 0.0, 2.0)))
    assert len(logged) == before + 1 and "similar messages suppressed)" in logged[-1]
    held_back = sum(int(line.split("(")[-1].split(" ")[0]) for line in logged if "suppressed" in line)
    assert held_back + len(logged) == 101  # every refusal logged or counted


def surface_points(rng: np.random.Generator, spacing: float) -> np.ndarray:
    """Points on the surfaces of SCENE_MARKERS' box (0.1 x 0.2 x 0.3 at (0.9, 0.3, 1.2)) and sphere (r 0.06 at
    (0.5, -0.35, 1.15)), about ``spacing`` apart."""
    half = np.array([0.05, 0.1, 0.15])
    faces = []
    for axis in range(3):
        a, b = [i for i in range(3) if i != axis]
        u = np.arange(-half[a], half[a] + 1e-9, spacing)
        v = np.arange(-half[b], half[b] + 1e-9, spacing)
        grid = np.stack(np.meshgrid(u, v, indexing="ij"), axis=-1).reshape(-1, 2)
        for sign in (-1.0, 1.0):
            face = np.zeros((len(grid), 3))
            face[:, a], face[:, b], face[:, axis] = grid[:, 0], grid[:, 1], sign * half[axis]
            faces.append(face + [0.9, 0.3, 1.2])
    count = int(4 * math.pi * 0.06 ** 2 / spacing ** 2 * 2)
    directions = rng.standard_normal((count, 3))
    sphere = 0.06 * directions / np.linalg.norm(directions, axis=1)[:, None] + [0.5, -0.35, 1.15]
    return np.concatenate(faces + [sphere])


@pytest.mark.parametrize("voxel", [0.01, 0.02])
def test_markers_and_a_cloud_of_the_same_shapes_give_the_same_distances(voxel: float) -> None:
    """Each arm link's distance to the scene (min over its obstacles), markers vs cloud, random configurations
    with a link within 0.1 m: cloud <= markers + 1e-9 (the voxels hold the surface points) and >= markers - the
    voxel's diagonal s sqrt(3) (a voxel reaches at most that far beyond its point; the gaps beyond one side are at
    cells' corners and edges on the ball, where the surface's normal is not along a grid axis; one side cannot be
    promised: test_a_voxel_reaches_almost_its_diagonal_beyond_its_point)."""
    rng = np.random.default_rng(3)
    markers, _ = intake()
    send(markers, marker("box", Marker.CUBE, (0.1, 0.2, 0.3), (0.9, 0.3, 1.2)),
         marker("ball", Marker.SPHERE, (0.12, 0.12, 0.12), (0.5, -0.35, 1.15)))
    cloud, _ = intake(voxel=voxel)
    cloud.on_cloud(cloud_message(surface_points(rng, voxel / 3)))
    cloud.process()
    assert names(cloud) == ["cloud"]
    live = LiveDistances(collision().model, collision().geometry)
    m = collision().kinematics
    gaps: list[float] = []
    while len(gaps) < 60:
        q = rng.uniform(m.q_min, m.q_max)
        a = live.near(q, markers.scene.feed.snapshot(), 0.1)
        b = live.near(q, cloud.scene.feed.snapshot(), 0.12)
        shapes = {}
        for link, d in zip(a.links, a.distance.tolist(), strict=True):
            shapes[link[0]] = min(d, shapes.get(link[0], math.inf))
        points = {link[0]: d for link, d in zip(b.links, b.distance.tolist(), strict=True)}
        for link, d in shapes.items():
            if d > 0.0:  # apart (inside, an octree's depth is a voxel's)
                gaps.append(d - points[link])
    gap = np.array(gaps) / voxel
    print(f"voxel {voxel * 1e3:.0f} mm: marker - cloud distance {gap.min():.2f} to {gap.max():.2f} voxel sides "
          f"(median {np.median(gap):.2f}), {len(gap)} (link, configuration) samples")
    assert gap.min() >= -1e-9 / voxel and gap.max() <= math.sqrt(3)


@pytest.mark.parametrize("side", [0.01, 0.02])
def test_a_voxel_reaches_almost_its_diagonal_beyond_its_point(side: float) -> None:
    """Why one voxel side cannot be promised (docs/obstacles.md): a voxel holds its points wherever they are in it,
    so the octree must hold the whole cell; a surface point near the cell's corner with the surface's normal along
    the cell's diagonal (a ball's surface there) leaves the opposite corner (s - e) sqrt(3) beyond the surface.
    A ball coming along that normal sees the cloud that much closer than the surface point: 1.65 sides here."""
    from dualarm_control.collision.cloud import voxel_octree, voxelise

    e = side / 20
    point = np.full(3, e)  # in the cell [0, s]^3, e from its corner at the origin
    octree = voxel_octree(voxelise(point[None, :].astype(np.float32), side))
    normal = np.ones(3) / math.sqrt(3.0)
    radius, gap_to_point = 0.05, 0.1
    centre = point + (gap_to_point + radius) * normal
    request, result = coal.DistanceRequest(), coal.DistanceResult()
    d = coal.distance(octree, coal.Transform3s(), coal.Sphere(radius), coal.Transform3s(np.eye(3), centre), request,
                      result)
    expected = gap_to_point - (side - e) * math.sqrt(3.0)  # to the cell's far corner (s, s, s)
    print(f"voxel {side * 1e3:.0f} mm: the cloud {(gap_to_point - d) / side:.2f} sides closer than its point")
    assert d == pytest.approx(expected, abs=1e-9)
    assert gap_to_point - d > 1.6 * side


def test_a_million_point_cloud_is_decimated_and_the_executor_only_appends() -> None:
    """1M points: decimated to every 5th (200k), said once; the executor's callback costs < 1 ms per cloud
    (a deque append), the worker's intake is timed."""
    rng = np.random.default_rng(4)
    points = rng.uniform([0.3, -0.5, 0.8], [1.3, 0.5, 0.85], (1_000_000, 3))
    points[::1000] = np.nan  # some invalid points
    data = cloud_message(points)
    target, logged = intake()
    start = time.perf_counter()
    for _ in range(20):
        target.on_cloud(data)
    append = (time.perf_counter() - start) / 20
    assert target.count["clouds_dropped"] == 19  # only the latest waits
    target.process()
    assert names(target) == ["cloud"] and target.count["clouds"] == 1
    assert len(logged) == 1 and "cloud of 1000000 points: decimated to every 5th point" in logged[0], logged
    assert "non-finite points dropped" in logged[0]
    print(f"executor: {append * 1e6:.1f} us per cloud; worker: {target.cloud_seconds[-1] * 1e3:.1f} ms for 1M points")
    assert append < 1e-3


def test_bad_clouds_are_refused() -> None:
    target, logged = intake()
    target.on_cloud(cloud_message(np.zeros((10, 3)), frame="camera_link"))
    target.process()
    msg = PointCloud2()
    msg.fields = [PointField(name="x", offset=0, datatype=PointField.FLOAT64, count=1)]
    target.on_cloud(serialize_message(msg))
    target.process()
    target.on_cloud(cloud_message(np.array([[0.5, 0.0, 1.0], [3e10, 0.0, 1.0]])))  # beyond the voxel grid
    target.process()
    target.on_cloud(b"\x00\x01\x00\x00garbage")
    time.sleep(1.05)  # past the throttle, so that each reason is logged
    target.process()
    assert names(target) == []
    assert "frame_id 'camera_link' is not a fixed frame" in logged[0]
    assert target.count["clouds_refused"] == 4, (target.count, logged)


def test_a_live_obstacle_is_what_the_limit_sees() -> None:
    """The feed the intake fills is the one the controller's limit reads (the node passes the limit's feed)."""
    from dualarm_control.collision import CollisionParams
    from dualarm_control.controller import ControllerParams, RelativeController

    controller = RelativeController(collision().kinematics, ControllerParams(collision=CollisionParams(live_obstacles=2)))
    limit = controller.limit("live_obstacles")
    assert limit is not None
    target = ObstacleIntake(limit.feed, fixed_frames(collision().model), print,  # type: ignore[attr-defined]
                            lambda data, kind: deserialize_message(data, TYPES[kind]))
    send(target, marker("hand", Marker.SPHERE, (0.1, 0.1, 0.1), (0.5, 0.0, 2.0)))
    assert [o.name for o in limit.feed.snapshot()] == ["hand"]  # type: ignore[attr-defined]
    assert isinstance(limit.feed.snapshot()[0], LiveObstacle)  # type: ignore[attr-defined]


def test_the_intake_subscribes_on_a_live_graph() -> None:
    """start_intake on an rclpy node (its own context, the session's domain): a MarkerArray on the markers topic
    and a PointCloud2 on the cloud topic, published by another node of the process, reach the feed through the
    raw subscriptions and the worker thread. Waits for them with a deadline, failing with what it saw."""
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor

    from dualarm_control.ros.obstacle_io import start_intake

    context = Context()
    rclpy.init(context=context)
    node = rclpy.create_node("obstacle_intake_test", context=context)
    sender = rclpy.create_node("obstacle_sender_test", context=context)
    feed = LiveObstacleFeed(4)
    values = {"obstacles.topic": "/test_intake_markers", "obstacles.cloud_topic": "/test_intake_cloud",
              "obstacles.cloud_voxel": 0.02, "obstacles.cloud_max_points": 200_000, "obstacles.cloud_lifetime": 0.0}
    target = start_intake(node, feed, collision().model, values)
    markers = sender.create_publisher(MarkerArray, "/test_intake_markers", 10)
    clouds = sender.create_publisher(PointCloud2, "/test_intake_cloud", 1)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    executor.add_node(sender)
    msg = MarkerArray()
    msg.markers = [marker("hand", Marker.SPHERE, (0.1, 0.1, 0.1), (0.5, 0.0, 2.0))]
    cloud = deserialize_message(cloud_message(np.random.default_rng(5).uniform(0.0, 0.3, (1000, 3))), PointCloud2)
    seen: list[str] = []
    try:
        deadline = time.monotonic() + 30.0
        while time.monotonic() < deadline:
            markers.publish(msg)
            clouds.publish(cloud)
            executor.spin_once(timeout_sec=0.1)
            seen = sorted(o.name for o in feed.snapshot())
            if seen == ["cloud", "hand"]:
                break
        assert seen == ["cloud", "hand"], (seen, dict(target.count))
    finally:
        target.stop()
        executor.shutdown()
        node.destroy_node()
        sender.destroy_node()
        rclpy.try_shutdown(context=context)
