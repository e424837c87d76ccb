"""The viewers draw a bag's obstacles (docs/obstacles.md): the scene latched on /dualarm/obstacles and a moving
marker on /collision_objects, read back (app/view/obstacles_view.py), logged to Rerun under obstacles/<name>
(static shape, the moving one's pose on the run's timeline) and drawn in the video's camera where it was."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from rclpy.serialization import serialize_message
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from dualarm_control.app.view.obstacles_view import (
    CameraObstacles,
    log_obstacles,
    read_obstacles,
)
from dualarm_control.obstacles import Box, Cylinder, Sphere
from dualarm_control.ros.obstacle_markers import obstacle_marker, scene_markers


def write_scene_bag(path: Path) -> None:
    """A bag with the scene (a table, a post) and a hand moving down 0.5 m in 1 s (11 markers, 0.1 s apart)."""
    from visualization_msgs.msg import MarkerArray

    store = get_typestore(Stores.ROS2_JAZZY)
    hand = Sphere("hand", position=(0.5, 0.2, 1.9), radius=0.05)
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        scene = writer.add_connection("/dualarm/obstacles", "visualization_msgs/msg/MarkerArray", typestore=store)
        live = writer.add_connection("/collision_objects", "visualization_msgs/msg/MarkerArray", typestore=store)
        msg = scene_markers((Box("table", size=(1.2, 1.6, 0.05), position=(0.9, 0.0, 0.775)),
                             Cylinder("post", radius=0.04, length=0.8, position=(1.1, 0.0, 1.2))), ())
        writer.write(scene, 0, serialize_message(msg))
        for k in range(11):
            stamp = 1_000_000_000 + k * 100_000_000
            moving = MarkerArray()
            moving.markers = [obstacle_marker(hand, stamp, position=(0.5, 0.2, 1.9 - 0.05 * k))]
            writer.write(live, stamp, serialize_message(moving))


def test_a_bags_obstacles_are_read_back(tmp_path: Path) -> None:
    write_scene_bag(tmp_path / "bag")
    tracks = read_obstacles(tmp_path / "bag")
    assert list(tracks) == ["table", "post", "hand"]
    assert np.allclose(tracks["table"].scale, [1.2, 1.6, 0.05]) and tracks["table"].stamps == [-1]
    hand = tracks["hand"]
    assert len(hand.stamps) == 11 and np.allclose(hand.positions[-1], [0.5, 0.2, 1.4])
    assert np.allclose(hand.scale, 0.1)


def test_rerun_logs_them_static_and_on_the_timeline(tmp_path: Path) -> None:
    import rerun as rr

    write_scene_bag(tmp_path / "bag")
    rec = rr.RecordingStream("dualarm_test_obstacles")
    rec.save(str(tmp_path / "scene.rrd"))
    log_obstacles(read_obstacles(tmp_path / "bag"), start_ns=1_000_000_000, recording=rec)
    rec.flush()
    rec.disconnect()
    import subprocess
    import sys

    stats = subprocess.run([str(Path(sys.executable).parent / "rerun"), "rrd", "stats", str(tmp_path / "scene.rrd")],
                           check=False, capture_output=True, text=True, timeout=120)
    for entity in ("/obstacles/table/shape", "/obstacles/post", "/obstacles/hand", "/obstacles/hand/shape"):
        assert entity in stats.stdout + stats.stderr, (entity, stats.stdout[-2000:], stats.stderr[-2000:])


def test_the_video_camera_places_the_hand_where_it_was(tmp_path: Path) -> None:
    import pybullet as p

    write_scene_bag(tmp_path / "bag")
    client = p.connect(p.DIRECT)
    try:
        camera = CameraObstacles(read_obstacles(tmp_path / "bag"), client)
        assert set(camera.bodies) == {"table", "post", "hand"}
        camera.place(1_000_000_000 + 520_000_000)  # the marker of 1.5 s: k = 5
        position, _ = p.getBasePositionAndOrientation(camera.bodies["hand"], physicsClientId=client)
        assert np.allclose(position, [0.5, 0.2, 1.65])
    finally:
        p.disconnect(client)


def test_foxglove_replays_them(tmp_path: Path) -> None:
    """The Foxglove replay of a bag sends its obstacles' MarkerArrays (both topics) with their schema."""
    import foxglove

    from dualarm_control.app.view.foxglove_view import FoxgloveScene, bag_signals
    from dualarm_control.app.view.recording import JointRecording
    from dualarm_control.paths import urdf_path

    write_scene_bag(tmp_path / "bag")
    recording = JointRecording(np.array([1_000_000_000, 2_000_000_000]), np.zeros((2, 14)), (), urdf_path().read_text())
    signals = bag_signals(tmp_path / "bag", recording)
    assert {s.topic: len(s.messages) for s in signals} == {"/dualarm/obstacles": 1, "/collision_objects": 11}
    server = foxglove.start_server(host="127.0.0.1", port=0)
    try:
        scene = FoxgloveScene(recording, signals)
        schema = scene.channels["/collision_objects"].schema()
        assert schema is not None and schema.name == "visualization_msgs/msg/MarkerArray"
    finally:
        server.stop()


def test_the_live_view_draws_the_running_cells_obstacles(tmp_path: Path) -> None:
    """``dualarm view --save`` without a bag, as a person runs it beside a cell (the session's domain): the scene
    latched on /dualarm/obstacles and a hand moving on /collision_objects, published by a node of this process,
    are in the recording it writes when stopped (Ctrl-C): the table's shape, the hand's poses on the timeline."""
    import signal
    import subprocess
    import sys

    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from test_view import read_rrd
    from visualization_msgs.msg import MarkerArray
    from waiting import wait_until

    from dualarm_control.ros.qos import latched_qos

    rrd = tmp_path / "live.rrd"
    view = subprocess.Popen([sys.executable, "-m", "dualarm_control.app.cli", "view", "--save", str(rrd)],
                            cwd=Path(__file__).resolve().parents[1], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True)
    context = Context()
    rclpy.init(context=context)
    node = rclpy.create_node("obstacle_publisher_test", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    sent = 0
    try:
        scene = node.create_publisher(MarkerArray, "/dualarm/obstacles", latched_qos())
        scene.publish(scene_markers((Box("table", size=(1.2, 1.6, 0.05), position=(0.9, 0.0, 0.775)),), ()))
        live = node.create_publisher(MarkerArray, "/collision_objects", 10)
        hand = Sphere("hand", position=(0.5, 0.2, 1.9), radius=0.05)
        wait_until(lambda: live.get_subscription_count() > 0 and scene.get_subscription_count() > 0,
                   lambda: "no subscription from the view", what="dualarm view subscribed to the obstacles",
                   timeout=120.0, step=lambda: executor.spin_once(timeout_sec=0.1),
                   gone=lambda: None if view.poll() is None else f"view exited: {view.communicate()[0][-2000:]}")
        for k in range(40):  # 2 s of a hand coming down at 0.25 m/s
            moving = MarkerArray()
            moving.markers = [obstacle_marker(hand, 1_000_000_000 + k * 50_000_000, position=(0.5, 0.2, 1.9 - 0.0125 * k))]
            live.publish(moving)
            sent += 1
            executor.spin_once(timeout_sec=0.05)
        delete = MarkerArray()
        delete.markers = [obstacle_marker(hand, 0)]
        delete.markers[0].action = delete.markers[0].DELETE  # a zero stamp: at the latest one the view saw
        for _ in range(5):  # best effort: sent a few times (a repeat changes nothing)
            live.publish(delete)
            executor.spin_once(timeout_sec=0.05)
    finally:
        view.send_signal(signal.SIGINT)
        out = view.communicate(timeout=120)[0]
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    assert view.returncode == 0, out[-2000:]
    rows, _ = read_rrd(rrd)
    print(f"{sent} hand markers sent; rows: table {rows['/obstacles/table/shape']}, hand {rows['/obstacles/hand']}")
    assert rows["/obstacles/table/shape"] >= 1 and rows["/obstacles/table"] >= 1, (dict(rows), out[-2000:])
    assert rows["/obstacles/hand"] >= sent // 2, (dict(rows), out[-2000:])
    # its timeline's 0 is the first marker's stamp (1 s), the last marker at 1.95 s; the DELETE took that stamp
    assert shown_in_rrd(rrd, "/obstacles/hand", 1.0) and not shown_in_rrd(rrd, "/obstacles/hand", 1.96), out[-2000:]


# ----------------------------------------------------------------------------- DELETE, DELETEALL, lifetime

S = 1_000_000_000
LIFECYCLE = {"hand": [(1.0 * S, 1.2 * S), (1.5 * S, 1.8 * S)], "cup": [(2.0 * S, 2.3 * S)], "table": [(-1, None)]}
"""The spans of :func:`write_lifecycle_bag`'s obstacles [ns]."""


def write_lifecycle_bag(path: Path) -> None:
    """A bag whose live markers come and go as a user's would: the hand ADDed at 1.0, 1.1, 1.2 s, DELETEd with a
    zero stamp (RViz's habit: the latest stamp seen, 1.2 s), ADDed again at 1.5 and 1.6 s, gone with a DELETEALL
    stamped 1.8 s; a cup ADDed once at 2.0 s with a 0.3 s lifetime. The latched table stays throughout."""
    from visualization_msgs.msg import Marker, MarkerArray

    store = get_typestore(Stores.ROS2_JAZZY)
    hand, cup = Sphere("hand", position=(0.5, 0.2, 1.6), radius=0.08), Box("cup", size=(0.1, 0.1, 0.12), position=(0.5, -0.2, 1.6))

    def action(kind: int, stamp_ns: int, name: str = "") -> Marker:
        m = Marker()
        m.ns, m.action = name, kind
        m.header.stamp.sec, m.header.stamp.nanosec = divmod(stamp_ns, S)
        return m

    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        scene = writer.add_connection("/dualarm/obstacles", "visualization_msgs/msg/MarkerArray", typestore=store)
        live = writer.add_connection("/collision_objects", "visualization_msgs/msg/MarkerArray", typestore=store)
        writer.write(scene, 0, serialize_message(scene_markers((Box("table", size=(1.2, 1.6, 0.05), position=(0.9, 0.0, 0.775)),), ())))
        cup_marker = obstacle_marker(cup, 2 * S)
        cup_marker.lifetime.nanosec = 300_000_000
        events = [*(obstacle_marker(hand, int(t * S)) for t in (1.0, 1.1, 1.2)), action(Marker.DELETE, 0, "hand"),
                  *(obstacle_marker(hand, int(t * S)) for t in (1.5, 1.6)), action(Marker.DELETEALL, int(1.8 * S)), cup_marker]
        for k, marker in enumerate(events):
            message = MarkerArray()
            message.markers = [marker]
            writer.write(live, S + k, serialize_message(message))


def test_delete_deleteall_and_lifetime_end_an_obstacles_spans(tmp_path: Path) -> None:
    write_lifecycle_bag(tmp_path / "bag")
    tracks = read_obstacles(tmp_path / "bag")
    assert {name: track.spans for name, track in tracks.items()} == LIFECYCLE
    hand = tracks["hand"]
    assert [hand.shown(int(t * S)) for t in (0.9, 1.0, 1.19, 1.2, 1.4, 1.5, 1.79, 1.8, 5.0)] == \
        [False, True, True, False, False, True, True, False, False]
    assert tracks["table"].shown(int(5.0 * S)) and tracks["cup"].shown(int(2.29 * S)) and not tracks["cup"].shown(int(2.3 * S))


def shown_in_rrd(path: Path, entity: str, seconds: float) -> bool:
    """Whether the saved recording shows ``entity``'s shape at ``seconds`` on the ``time`` timeline, by Rerun's
    rule: its latest shape row at or before then is newer than the latest recursive Clear of it or of a parent."""
    import datetime

    from rerun.chunk import RrdReader

    at = datetime.timedelta(seconds=seconds)
    shape: list[datetime.timedelta] = []
    cleared: list[datetime.timedelta] = []
    for chunk in RrdReader(str(path)).stream():
        batch = chunk.to_record_batch()
        if "time" not in batch.schema.names:
            continue
        times = [t for t in batch.column("time").to_pylist() if t <= at]
        if chunk.entity_path == entity + "/shape" and any(n.endswith(("half_sizes", "radii", "blob")) for n in batch.schema.names):
            shape += times
        if "Clear:is_recursive" in batch.schema.names and (entity + "/").startswith(chunk.entity_path + "/"):
            cleared += times
    return bool(shape) and (not cleared or max(shape) > max(cleared))


def test_rerun_clears_a_deleted_or_expired_obstacle(tmp_path: Path) -> None:
    """The recording ``dualarm view`` would save: the hand and the cup shown exactly in their spans (start_ns 1 s:
    the timeline's 0 is the hand's first ADD); the latched table at any time."""
    import rerun as rr

    write_lifecycle_bag(tmp_path / "bag")
    rec = rr.RecordingStream("dualarm_test_obstacles")
    rec.save(str(tmp_path / "scene.rrd"))
    log_obstacles(read_obstacles(tmp_path / "bag"), start_ns=S, recording=rec)
    rec.flush()
    rec.disconnect()
    rrd = tmp_path / "scene.rrd"
    times = (0.05, 0.15, 0.25, 0.45, 0.65, 0.85, 1.1, 1.25, 1.35)  # [s] after 1 s
    seen = {name: [shown_in_rrd(rrd, f"/obstacles/{name}", t) for t in times] for name in ("hand", "cup")}
    assert seen == {name: [read_obstacles(tmp_path / "bag")[name].shown(int((1 + t) * S)) for t in times]
                    for name in ("hand", "cup")}, seen
    assert seen["hand"] == [True, True, False, False, True, False, False, False, False], seen
    assert seen["cup"] == [False] * 6 + [True, True, False], seen


def test_the_video_camera_shows_an_obstacle_only_in_its_spans(tmp_path: Path) -> None:
    """Rendered as the video's frames are (pybullet's camera, its segmentation mask): the hand's and the cup's
    pixels in the frame at each time, none after a DELETE, a DELETEALL or the cup's lifetime."""
    import pybullet as p

    write_lifecycle_bag(tmp_path / "bag")
    client = p.connect(p.DIRECT)
    try:
        camera = CameraObstacles(read_obstacles(tmp_path / "bag"), client)
        view = p.computeViewMatrix((2.0, 0.0, 1.8), (0.5, 0.0, 1.6), (0.0, 0.0, 1.0))
        projection = p.computeProjectionMatrixFOV(50.0, 1.0, 0.05, 10.0)

        def pixels(seconds: float) -> dict[str, int]:
            camera.place(int(seconds * S))
            mask = np.array(p.getCameraImage(96, 96, view, projection, renderer=p.ER_TINY_RENDERER,
                                             physicsClientId=client)[4]).reshape(96, 96)
            return {name: int((mask == camera.bodies[name]).sum()) for name in ("hand", "cup")}

        frames = {t: pixels(t) for t in (0.9, 1.1, 1.3, 1.55, 1.9, 2.1, 2.4)}
        print(frames)
        assert all(frames[t]["hand"] > 20 for t in (1.1, 1.55)), frames
        assert all(frames[t]["hand"] == 0 for t in (0.9, 1.3, 1.9, 2.1, 2.4)), frames
        assert frames[2.1]["cup"] > 20 and all(frames[t]["cup"] == 0 for t in (0.9, 1.1, 1.3, 1.55, 1.9, 2.4)), frames
    finally:
        p.disconnect(client)
