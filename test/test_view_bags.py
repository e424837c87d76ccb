"""Bags that open in a viewer: ``/robot_description`` from sim_node, ``/tf`` written by the recorder.

Real processes over loopback DDS (this session's ROS_DOMAIN_ID): sim_node, a late-joining
rclpy subscriber, ``dualarm bag record`` and a lockstep ``dualarm launch --record`` of the
short scenario; the bag is read back with ``rosbags`` and every recorded link frame is checked
against pinocchio's forward kinematics of the recorded joint state.
"""

from __future__ import annotations

import os
import re
import signal
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin
import pytest
from waiting import DEADLINE_S, exited, tail, wait_for_line, wait_until

from dualarm_control.app import cli
from dualarm_control.app.record.bag import format_notes
from dualarm_control.app.run.launcher import Launch, Process, launch_scenario
from dualarm_control.errors import DualArmError
from dualarm_control.kinematics import DualArmModel
from dualarm_control.link_frames import urdf_joints
from dualarm_control.robot_params import DEFAULT_ROBOT, load_robot
from dualarm_control.ros.computed_tf import NOTE

SHORT = Path(__file__).parent / "data" / "short.yaml"
TOLERANCE = 1e-9


def cell_urdf() -> str:
    """The URDF sim_node publishes for the default robot: the resolved one (the cell's file, its tool bodies added)."""
    return load_robot(DEFAULT_ROBOT).urdf_xml


def read_bag(bag: Path) -> dict[str, list[tuple[int, object]]]:
    """topic -> [(receive time ns, message)] in log-time order."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    out: dict[str, list[tuple[int, object]]] = {}
    with AnyReader([bag], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        for conn, t, raw in reader.messages():
            out.setdefault(conn.topic, []).append((t, reader.deserialize(raw, conn.msgtype)))
    return out


def se3(tf: object) -> pin.SE3:
    t, r = tf.transform.translation, tf.transform.rotation  # type: ignore[attr-defined]
    quat = pin.Quaternion(r.w, r.x, r.y, r.z)
    return pin.SE3(quat.toRotationMatrix(), np.array([t.x, t.y, t.z]))


@pytest.fixture(scope="module")
def demo_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A recorded lockstep launch of the short scenario, as ``dualarm demo`` records each solver."""
    bag = tmp_path_factory.mktemp("viewbag") / "bag"
    assert launch_scenario(str(SHORT), [], [], True, bag, timeout=240.0) == 0
    return bag


def test_demo_bag_holds_robot_description_and_tf_of_pinocchio(demo_bag: Path) -> None:
    """/robot_description is the cell's URDF; one /tf per /joint_states (same header stamp, same
    receive time), one /tf_static; frame names are the URDF's links (parent -> child of each joint)
    and every link's world pose, composed along the chain from /tf_static and /tf, equals
    pinocchio's oMf of the recorded joint state to 1e-9."""
    topics = read_bag(demo_bag)
    urdf_text = cell_urdf()
    assert [m.data for _, m in topics["/robot_description"]] == [urdf_text]  # type: ignore[attr-defined]
    joints = urdf_joints(urdf_text)
    moving = {(j.parent, j.child) for j in joints if not j.fixed}
    fixed = {(j.parent, j.child) for j in joints if j.fixed}
    [(_, static)] = topics["/tf_static"]
    assert {(t.header.frame_id, t.child_frame_id) for t in static.transforms} == fixed  # type: ignore[attr-defined]
    states = topics["/joint_states"]
    tfs = topics["/tf"]
    assert len(tfs) == len(states) > 100
    model = DualArmModel()
    links = sorted({j.child for j in joints} | {j.parent for j in joints})
    frame_ids = {link: model.frame_id(link) for link in links}
    root = "world"
    worst = 0.0
    for (t_state, state), (t_tf, tf) in zip(states, tfs, strict=True):
        assert t_tf == t_state
        assert {(t.header.frame_id, t.child_frame_id) for t in tf.transforms} == moving  # type: ignore[attr-defined]
        stamp = state.header.stamp  # type: ignore[attr-defined]
        assert all(t.header.stamp.sec == stamp.sec and t.header.stamp.nanosec == stamp.nanosec
                   for t in tf.transforms)  # type: ignore[attr-defined]
        where = {n: i for i, n in enumerate(state.name)}  # type: ignore[attr-defined]
        q = np.array([state.position[where[n]] for n in model.joint_names])  # type: ignore[attr-defined]
        pin.framesForwardKinematics(model.model, model.data, q)
        edges = {t.child_frame_id: (t.header.frame_id, se3(t))
                 for t in [*static.transforms, *tf.transforms]}  # type: ignore[attr-defined]
        for link in links:
            pose, frame = pin.SE3.Identity(), link
            while frame != root:
                parent, rel = edges[frame]
                pose, frame = rel * pose, parent
            expected = model.data.oMf[frame_ids[link]]
            worst = max(worst, float(np.max(np.abs(pose.homogeneous - expected.homogeneous))))
    assert worst < TOLERANCE, worst


def test_bag_info_says_tf_is_computed(demo_bag: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["bag", "info", str(demo_bag)]) == 0
    info = capsys.readouterr().out
    assert NOTE in info
    assert "Topic: /tf | Type: tf2_msgs/msg/TFMessage" in info
    assert "Topic: /robot_description | Type: std_msgs/msg/String" in info


@pytest.fixture(scope="module")
def sim_node() -> Iterator[Process]:
    """sim_node in real time on the default scenario (no controller: it holds the arms), once it has
    logged its scenario: the end of its ``__init__``, after it published /robot_description. One for
    the module: the tests only read from it (the latched description, the joint states)."""
    launch = Launch(echo=False)
    try:
        proc = launch.start("sim_node", [sys.executable, "-m", "dualarm_control.app.cli", "run", "sim_node"])
        wait_for_line(proc.lines, "scenario 'assembly'", proc.popen, name="sim_node")
        yield proc
    finally:
        launch.stop()


def late_description(wait_s: float) -> str:
    """Subscribe /robot_description (transient local, as a viewer does) in a fresh rclpy context
    and return the first message; fail if none arrives within ``wait_s`` [s]."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from std_msgs.msg import String

    context = rclpy.Context()
    rclpy.init(context=context)
    received: list[str] = []
    try:
        node = rclpy.create_node("late_viewer", context=context)
        qos = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        node.create_subscription(String, "/robot_description", lambda m: received.append(m.data), qos)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        wait_until(lambda: received, lambda: "nothing", what="/robot_description", timeout=wait_s,
                   step=lambda: executor.spin_once(timeout_sec=0.1))
        node.destroy_node()
    finally:
        context.try_shutdown()
    return received[0]


def test_late_subscriber_gets_robot_description(sim_node: Process) -> None:
    """A subscriber created after sim_node published /robot_description (once, before it logged its
    scenario: the fixture waits for that line) gets it."""
    assert late_description(DEADLINE_S) == cell_urdf()


STATES = 10
"""Joint states a recorder reports before it is stopped."""


def recorded_states(rec: Process) -> int:
    """The joint states a recorder reported, from its progress lines (every 2 s: "recorded N messages
    in T s (/joint_states n, ...)")."""
    counts = [int(m) for line in rec.lines for m in re.findall(r"/joint_states (\d+)", line)]
    return max(counts, default=0)


def wait_for_states(rec: Process) -> None:
    """Until the recorder ``rec`` has reported more than :data:`STATES` joint states."""
    wait_until(lambda: recorded_states(rec) > STATES, lambda: tail(rec.lines), what=f"{STATES} joint states recorded",
               gone=exited(rec.popen, rec.name))


def _record(*bags: tuple[Path, tuple[str, ...]]) -> None:
    """One recorder per (bag, extra arguments), side by side: each records /joint_states (and what
    sim_node latches) until it reports more than :data:`STATES` of them, then Ctrl-C."""
    launch = Launch(echo=False)
    try:
        recs = [launch.start(f"bag {bag.name}", [sys.executable, "-m", "dualarm_control.app.cli", "bag", "record",
                                                  "-o", str(bag), "/joint_states", *extra]) for bag, extra in bags]
        for rec in recs:
            wait_for_states(rec)
            os.killpg(rec.popen.pid, signal.SIGINT)
        for rec in recs:
            assert rec.popen.wait(timeout=DEADLINE_S) == 0, tail(rec.lines)
    finally:
        launch.stop()


def test_late_recorder_keeps_description_and_no_tf_turns_tf_off(sim_node: Process, tmp_path: Path) -> None:
    """A recorder started after sim_node keeps /robot_description (not named) and writes /tf from
    /joint_states; with --no-tf it writes no /tf and bag info says nothing about it (the two recorders
    side by side)."""
    with_tf, without = tmp_path / "with_tf", tmp_path / "no_tf"
    _record((with_tf, ()), (without, ("--no-tf",)))
    topics = read_bag(with_tf)
    assert [m.data for _, m in topics["/robot_description"]] == [cell_urdf()]  # type: ignore[attr-defined]
    assert len(topics["/tf"]) == len(topics["/joint_states"]) > STATES
    topics = read_bag(without)
    assert "/robot_description" in topics and len(topics["/joint_states"]) > STATES
    assert "/tf" not in topics and "/tf_static" not in topics
    assert NOTE not in format_notes(without)


# ----------------------------------------------------------------------------- video


def _decoded_frames(path: Path) -> list[np.ndarray]:
    import imageio_ffmpeg

    reader = imageio_ffmpeg.read_frames(str(path))
    meta = reader.__next__()
    width, height = meta["size"]
    return [np.frombuffer(f, dtype=np.uint8).reshape(height, width, 3) for f in reader]


def _changed_pixels(a: np.ndarray, b: np.ndarray) -> int:
    """Pixels whose colour differs by more than codec noise (any channel > 40 of 255)."""
    return int(np.count_nonzero(np.abs(a.astype(int) - b.astype(int)).max(axis=2) > 40))


def test_video_of_the_demo_bag(demo_bag: Path, tmp_path: Path) -> None:
    """``dualarm view BAG --video``: floor(duration x fps) + 1 frames (read back with ffmpeg); the
    first and last frames differ where the arms moved, by far more pixels than a run that holds still."""
    from dataclasses import replace

    from dualarm_control.app.view.recording import read_joint_recording
    from dualarm_control.app.view.video import render_recording

    assert cli.main(["view", str(demo_bag), "--video", str(tmp_path / "run.mp4"), "--fps", "25",
                     "--size", "320x240"]) == 0
    recording = read_joint_recording(demo_bag)
    assert recording.duration_s > 1.0
    frames = _decoded_frames(tmp_path / "run.mp4")
    assert len(frames) == int(recording.duration_s * 25.0 + 1e-9) + 1
    assert frames[0].shape == (240, 320, 3)
    moved = _changed_pixels(frames[0], frames[-1])
    still = replace(recording, positions=np.repeat(recording.positions[:1], len(recording.stamps_ns), axis=0))
    render_recording(still, tmp_path / "still.mp4", fps=25.0, size=(320, 240), log=None)
    held = _decoded_frames(tmp_path / "still.mp4")
    noise = _changed_pixels(held[0], held[-1])  # H.264 key frame vs predicted frames of one picture
    assert noise < 100 and moved > 10 * max(noise, 20), (moved, noise)
    background = np.all(frames[0] > 250, axis=2).mean()
    assert 0.3 < background < 0.99  # the cell is in the picture, not filling it


@pytest.mark.parametrize("argv, message", [
    (["--video", "x.mp4"], "name the BAG"),
    (["BAG", "--video", "x.mp4", "--foxglove"], "separate modes"),
    (["BAG", "--video", "x.mp4", "--web"], "--web belong to the Rerun mode"),
    (["--foxglove", "--save", "x.rrd"], "--save belong to the Rerun mode"),
])
def test_view_modes_refuse_mixed_options(argv: list[str], message: str, capsys: pytest.CaptureFixture[str]) -> None:
    """``dualarm view``'s modes (Rerun, --video, --foxglove) take their own options only; a usage error saying why."""
    assert cli.main(["view", *argv]) == cli.EXIT_USAGE
    assert message in capsys.readouterr().err


# ----------------------------------------------------------------------------- foxglove


def _foxglove_tf_and_description(serve: Any, **kwargs: Any) -> tuple[dict[str, dict[str, Any]], bytes, bytes]:
    """Run ``serve(port=0, stop=..., on_ready=...)`` in a thread; as a websocket client (subprotocol
    foxglove.sdk.v1) wait for /tf and /robot_description to be advertised, subscribe to both and
    return (the advertised channels by topic, the first /robot_description payload, the first /tf payload)."""
    import json
    import struct
    import threading

    import websocket

    stop, ports, errors = threading.Event(), [], []

    def run() -> None:
        try:
            serve(port=0, stop=stop, on_ready=ports.append, **kwargs)
        except (DualArmError, OSError, RuntimeError) as exc:  # reported below
            errors.append(exc)

    server = threading.Thread(target=run, daemon=True)
    server.start()
    try:
        wait_until(lambda: ports, lambda: errors, what="the server's port",
                   gone=lambda: None if server.is_alive() or ports else "the server thread ended")
        ws = websocket.create_connection(f"ws://127.0.0.1:{ports[0]}", subprotocols=["foxglove.sdk.v1"], timeout=10)
        channels: dict[str, dict[str, Any]] = {}

        def advertised() -> bool:  # one message a poll (each recv waits up to the socket's 10 s)
            text = ws.recv()
            if isinstance(text, str) and json.loads(text)["op"] == "advertise":
                channels.update({c["topic"]: c for c in json.loads(text)["channels"]})
            return {"/tf", "/robot_description"} <= channels.keys()

        wait_until(advertised, lambda: sorted(channels), what="/tf and /robot_description advertised", interval=0.0)
        ws.send(json.dumps({"op": "subscribe", "subscriptions": [
            {"id": 1, "channelId": channels["/robot_description"]["id"]}, {"id": 2, "channelId": channels["/tf"]["id"]}]}))
        payloads: dict[int, bytes] = {}

        def both() -> bool:
            data = ws.recv()
            if isinstance(data, bytes):
                opcode, subscription, _ = struct.unpack_from("<BIQ", data)
                assert opcode == 1
                payloads.setdefault(subscription, data[13:])
            return len(payloads) == 2

        wait_until(both, lambda: sorted(payloads), what="a message of each subscription", interval=0.0)
        ws.close()
    finally:
        stop.set()
        server.join(timeout=10)
    return channels, payloads[1], payloads[2]


def _check_description_and_tf(description: bytes, tf_payload: bytes) -> None:
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    urdf_text = cell_urdf()
    assert store.deserialize_cdr(description, "std_msgs/msg/String").data == urdf_text
    tf = store.deserialize_cdr(tf_payload, "tf2_msgs/msg/TFMessage")
    assert {(t.header.frame_id, t.child_frame_id) for t in tf.transforms} == {
        (j.parent, j.child) for j in urdf_joints(urdf_text) if not j.fixed}


def test_foxglove_server_sends_tf_and_robot_description(demo_bag: Path) -> None:
    """A recorded run served over the Foxglove WebSocket protocol: /tf and /robot_description are
    advertised as ROS 2 CDR channels beside the signals; a subscriber decodes the URDF and the link
    frames named as the URDF's links."""
    from dualarm_control.app.view.foxglove_view import serve_bag

    channels, description, tf = _foxglove_tf_and_description(serve_bag, bag=demo_bag)
    assert channels["/tf"]["schemaName"] == "tf2_msgs/msg/TFMessage"
    assert channels["/robot_description"]["schemaName"] == "std_msgs/msg/String"
    assert {c["encoding"] for c in channels.values()} == {"cdr"}
    assert {c["schemaEncoding"] for c in channels.values()} == {"ros2msg"}
    assert {"/joint_states", "/diagnostics", "/tf_static"} <= channels.keys()
    _check_description_and_tf(description, tf)


LIVE_STATES = 200
"""Joint states the live view logs before the test stops it with Ctrl-C (one second at 200 Hz)."""


def test_live_view_logs_the_running_cell(sim_node: Process, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``dualarm view`` on the running cell (run_live, subscriptions of ros/listen.py), stopped by Ctrl-C
    once it has logged 200 joint states (its duration, 60 s, only a deadline): each joint state it
    counts is one row of every joint's transform in the recording, none rejected."""
    import rerun as rr
    from test_view import read_rrd

    from dualarm_control.app.view import live
    from dualarm_control.app.view import rerun_view as rv

    logged_states = live.LiveLog.joint_state

    def joint_state(log: live.LiveLog, value: Any) -> None:
        logged_states(log, value)
        if log.counts["/joint_states"] == LIVE_STATES:
            signal.raise_signal(signal.SIGINT)  # Ctrl-C: run_live's loop ends at its next check

    monkeypatch.setattr(live.LiveLog, "joint_state", joint_state)
    path = tmp_path / "live.rrd"
    rec = rr.RecordingStream(rv.APPLICATION_ID)
    rec.save(str(path))
    said: list[str] = []
    assert live.run_live(DualArmModel(), rec, duration=DEADLINE_S, report=said.append) == 0
    rec.flush()
    rec.disconnect()
    logged = re.fullmatch(r"dualarm view: logged /joint_states (\d+), .* (\d+) samples rejected", said[-1])
    assert logged is not None, said
    states = int(logged.group(1))
    assert states >= LIVE_STATES and int(logged.group(2)) == 0, said  # stopped by the Ctrl-C, not at 60 s
    rows, _ = read_rrd(path)
    assert rows["/joint_tf/right_joint_7"] == rows["/joint_tf/left_joint_1"] == states


def test_foxglove_server_of_the_running_cell(sim_node: Process) -> None:
    """The live feed: the server reads the running sim_node's /robot_description and /joint_states, and offers the
    obstacles' topics."""
    from dualarm_control.app.view.foxglove_view import serve_live

    channels, description, tf = _foxglove_tf_and_description(serve_live)
    _check_description_and_tf(description, tf)
    assert {"/dualarm/obstacles", "/collision_objects"} <= channels.keys()  # the obstacles' MarkerArrays, for the 3D panel
