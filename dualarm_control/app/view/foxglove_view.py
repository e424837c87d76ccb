"""``dualarm view --foxglove``: the cell for the Foxglove app, over the Foxglove WebSocket protocol.

A foxglove-sdk server (extra ``view``; clients offer the subprotocol ``foxglove.sdk.v1``)
streams a recorded run as ROS 2 messages (schema encoding ``ros2msg``, message encoding
``cdr``), so Foxglove's 3D panel shows the URDF posed by the frames as for a live ROS 2 robot:

- ``/robot_description`` (std_msgs/msg/String): the cell's URDF, sent again whenever a client
  subscribes (a WebSocket channel does not latch as a transient-local topic does);
- ``/tf_static`` and ``/tf`` (tf2_msgs/msg/TFMessage): the fixed joints (again on each subscribe),
  and per joint state the movable ones (:mod:`dualarm_control.link_frames`, pinocchio);
- ``/joint_states`` (sensor_msgs/msg/JointState) and the run's other signals, e.g. ``/diagnostics``,
  as recorded (:func:`bag_signals`).

The run is replayed at its own pace (``speed`` x real time), over and over when ``loop``.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

import numpy as np

from dualarm_control.app.record.bag import open_reader
from dualarm_control.app.view.options import DEFAULT_FOXGLOVE_PORT as DEFAULT_PORT
from dualarm_control.app.view.recording import JointRecording, read_joint_recording
from dualarm_control.errors import DualArmError
from dualarm_control.link_frames import STRING_TYPE, TF_TYPE, LinkFrames, TfSerializer

JOINT_STATE_TYPE: Final = "sensor_msgs/msg/JointState"
SIGNAL_TOPICS: Final = ("/diagnostics", "/velocity_controller/commands", "/relative_pose", "/relative_target",
                        "/wrench", "/contact_force", "/dualarm/obstacles", "/collision_objects")
"""Recorded topics replayed beside the 3D scene (those a bag has; the obstacles' MarkerArrays are drawn by
Foxglove's 3D panel in the frame ``world``, the scene's at the start of the replay)."""
LATCHED: Final = ("/robot_description", "/tf_static")
"""Sent once at start and again whenever a client subscribes to them."""


@dataclass(frozen=True)
class RawTopic:
    """A recorded topic: its type, the CDR messages and their times [ns] on the joint states' clock."""

    topic: str
    type_name: str
    stamps_ns: Sequence[int]
    messages: Sequence[bytes]


def bag_signals(bag: Path, recording: JointRecording, topics: Sequence[str] = SIGNAL_TOPICS) -> list[RawTopic]:
    """The ``topics`` a bag holds, as recorded (CDR), timed on the recording's clock: receive times
    shifted so that the first /joint_states received is at the recording's first stamp."""
    reader = open_reader(Path(bag))
    try:
        states = [c for c in reader.connections if c.topic == "/joint_states"]
        first = next((t for _, t, _ in reader.messages(connections=states)), 0) if states else 0
        offset = int(recording.stamps_ns[0]) - first
        out = []
        for topic in topics:
            conns = [c for c in reader.connections if c.topic == topic]
            if conns:
                rows = [(t + offset, bytes(raw)) for _, t, raw in reader.messages(connections=conns)]
                out.append(RawTopic(topic, conns[0].msgtype, [t for t, _ in rows], [m for _, m in rows]))
    finally:
        reader.close()
    return out


def _resend_listener(wanted: threading.Event) -> Any:
    """A foxglove ServerListener setting ``wanted`` when a client subscribes to a latched topic."""
    from foxglove.websocket import ServerListener

    class Resend(ServerListener):
        def on_subscribe(self, client: Any, channel: Any) -> None:
            if channel.topic in LATCHED or channel.topic == LIVE_SCENE[0]:
                wanted.set()

    return Resend()


class FoxgloveScene:
    """The channels of the scene on a started server and how to fill them."""

    def __init__(self, recording: JointRecording, signals: Sequence[RawTopic]) -> None:
        import foxglove

        self.recording = recording
        self.frames = LinkFrames(recording.urdf_text)
        self.serializer = TfSerializer()
        self._joint_state = self.serializer.store.types[JOINT_STATE_TYPE]
        self._header = self.serializer.store.types["std_msgs/msg/Header"]
        self._time = self.serializer.store.types["builtin_interfaces/msg/Time"]
        types = {"/robot_description": STRING_TYPE, "/tf_static": TF_TYPE, "/tf": TF_TYPE,
                 "/joint_states": JOINT_STATE_TYPE, **{s.topic: s.type_name for s in signals}}
        self.channels = {topic: foxglove.Channel(topic, message_encoding="cdr", schema=foxglove.Schema(
            name=type_name, encoding="ros2msg", data=self.serializer.msgdef(type_name).encode()))
            for topic, type_name in types.items()}
        self.signals = list(signals)
        self._description = self.serializer.string(recording.urdf_text)

    def send_latched(self) -> None:
        """/robot_description and /tf_static (at the first joint state)."""
        self.channels["/robot_description"].log(self._description, log_time=time.time_ns())
        q0 = self.recording.positions[0]
        self.channels["/tf_static"].log(self.serializer.tf_message(int(self.recording.stamps_ns[0]),
                                                                   self.frames.transforms(q0, fixed=True)),
                                        log_time=time.time_ns())

    def send_frames(self, stamp: int, q: np.ndarray) -> None:
        """/tf at joint positions q [rad] (the URDF's joint order), stamped ``stamp`` [ns]."""
        self.channels["/tf"].log(self.serializer.tf_message(stamp, self.frames.transforms(q)), log_time=time.time_ns())

    def send_state(self, k: int) -> None:
        """/tf and /joint_states of joint state ``k``."""
        stamp = int(self.recording.stamps_ns[k])
        q = self.recording.positions[k]
        now = time.time_ns()
        self.send_frames(stamp, q)
        sec, nsec = divmod(stamp, 1_000_000_000)
        msg = self._joint_state(header=self._header(stamp=self._time(sec=sec, nanosec=nsec), frame_id=""),
                                name=list(self.recording.joint_names), position=np.asarray(q, dtype=np.float64),
                                velocity=np.zeros(0), effort=np.zeros(0))
        self.channels["/joint_states"].log(bytes(self.serializer.store.serialize_cdr(msg, JOINT_STATE_TYPE)),
                                           log_time=now)


def serve_foxglove(recording: JointRecording, port: int = DEFAULT_PORT, host: str = "127.0.0.1", *,
                   signals: Sequence[RawTopic] = (), speed: float = 1.0, loop: bool = True,
                   stop: threading.Event | None = None, on_ready: Callable[[int], None] | None = None) -> None:
    """Serve ``recording`` over the Foxglove WebSocket protocol until ``stop`` is set (or Ctrl-C).

    Args:
        recording: joint states (stamps [ns], positions (N, n), joint names) and the URDF.
        port: TCP port (0: any free port; ``on_ready`` is told which).
        host: address to listen on (default loopback only).
        signals: recorded topics replayed on the same clock (:func:`bag_signals`).
        speed: replay speed, 1.0 = real time.
        loop: start over at the end (else stop serving after one pass).
        stop: set it to stop the server (from another thread).
        on_ready: called with the bound port once the server listens.
    """
    import foxglove

    stop = stop or threading.Event()
    resend = threading.Event()
    server = foxglove.start_server(host=host, port=port, server_listener=_resend_listener(resend))
    try:
        scene = FoxgloveScene(recording, signals)
        if on_ready is not None:
            on_ready(server.port)
        stamps = recording.stamps_ns - recording.stamps_ns[0]
        while not stop.is_set():
            scene.send_latched()
            _replay_once(scene, stamps, speed, stop, resend)
            if not loop:
                break
    finally:
        server.stop()


def _replay_once(scene: FoxgloveScene, stamps: np.ndarray, speed: float, stop: threading.Event,
                 resend: threading.Event) -> None:
    """One pass over the recording, paced on the wall clock."""
    start = time.monotonic()
    t0 = int(scene.recording.stamps_ns[0])
    cursors = [0] * len(scene.signals)
    k = 0
    while k < len(stamps) and not stop.is_set():
        if resend.is_set():
            resend.clear()
            scene.send_latched()
        due = (time.monotonic() - start) * speed * 1e9
        while k < len(stamps) and stamps[k] <= due:
            scene.send_state(k)
            k += 1
        for i, signal in enumerate(scene.signals):
            channel = scene.channels[signal.topic]
            while cursors[i] < len(signal.stamps_ns) and signal.stamps_ns[cursors[i]] - t0 <= due:
                channel.log(signal.messages[cursors[i]], log_time=time.time_ns())
                cursors[i] += 1
        stop.wait(0.01)


def serve_bag(bag: Path, port: int = DEFAULT_PORT, host: str = "127.0.0.1", **kwargs: Any) -> None:
    """:func:`serve_foxglove` of a recorded run (its joint states, URDF and signals)."""
    recording = read_joint_recording(Path(bag))
    serve_foxglove(recording, port, host, signals=bag_signals(Path(bag), recording), **kwargs)


LIVE_SIGNALS: Final = {"/diagnostics": "diagnostic_msgs/msg/DiagnosticArray",
                        "/velocity_controller/commands": "std_msgs/msg/Float64MultiArray",
                        "/collision_objects": "visualization_msgs/msg/MarkerArray"}
"""Topics of the running cell forwarded as received beside /joint_states and the frames."""
LIVE_SCENE: Final = ("/dualarm/obstacles", "visualization_msgs/msg/MarkerArray")
"""The obstacles' latched scene: forwarded when it comes and again whenever a client subscribes to it."""


def serve_live(port: int = DEFAULT_PORT, host: str = "127.0.0.1", *, stop: threading.Event | None = None,
               on_ready: Callable[[int], None] | None = None, wait_s: float = 30.0) -> None:
    """Serve the running cell (this ROS domain) over the Foxglove WebSocket protocol until ``stop``.

    Subscribes /robot_description (transient local; waits up to ``wait_s`` for it), /joint_states,
    :data:`LIVE_SIGNALS` and the obstacles' latched scene :data:`LIVE_SCENE`; each joint state is forwarded
    with its /tf (the movable joints), /robot_description, /tf_static and the scene are re-sent when a client
    subscribes to them.
    No signal handlers: runs in any thread (Ctrl-C in the main thread raises KeyboardInterrupt).
    """
    import foxglove

    from dualarm_control.ros.cdr import JointStateReader
    from dualarm_control.ros.computed_tf import string_data
    from dualarm_control.ros.listen import Topic, listen
    from dualarm_control.ros.qos import latched_qos

    stop = stop or threading.Event()
    description: list[str] = []

    def on_description(data: bytes) -> None:
        description.append(string_data(bytes(data)))

    latched = {"/robot_description": Topic(STRING_TYPE, on_description, latched_qos(), raw=True)}
    with listen("_dualarm_foxglove", latched, signals=False) as listener:
        end = time.monotonic() + wait_s
        while not description and not stop.is_set():
            if time.monotonic() > end:
                raise DualArmError(f"no /robot_description within {wait_s:.0f} s: is the cell (sim_node) running "
                                   "in this ROS_DOMAIN_ID?")
            listener.spin_once(0.1)
        if stop.is_set():
            return
        joint_names = tuple(LinkFrames(description[0]).joint_names)
        empty = JointRecording(np.zeros(1, dtype=np.int64), np.zeros((1, len(joint_names))), joint_names,
                               description[0])
        resend = threading.Event()
        server = foxglove.start_server(host=host, port=port, server_listener=_resend_listener(resend))
        try:
            scene = FoxgloveScene(empty, [RawTopic(t, n, (), ()) for t, n in (*LIVE_SIGNALS.items(), LIVE_SCENE)])
            obstacles: list[bytes] = []  # the latched scene, last one
            reader = JointStateReader()
            order: dict[tuple[str, ...], np.ndarray] = {}
            started: list[bool] = []

            def on_joint_state(data: bytes) -> None:
                stamp, names, position, _ = reader(data)
                index = order.get(names)
                if index is None:
                    where = {n: i for i, n in enumerate(names)}
                    index = order[names] = np.array([where[n] for n in joint_names])
                if not started:  # /tf_static at the first joint state
                    started.append(True)
                    scene.recording = JointRecording(np.array([stamp], dtype=np.int64), position[index][None, :],
                                                     joint_names, description[0])
                    scene.send_latched()
                scene.send_frames(stamp, position[index])
                scene.channels["/joint_states"].log(data, log_time=time.time_ns())

            def forward(topic: str) -> Callable[[bytes], None]:
                return lambda data: scene.channels[topic].log(data, log_time=time.time_ns())

            def on_scene(data: bytes) -> None:
                obstacles[:] = [data]
                forward(LIVE_SCENE[0])(data)

            listener.subscribe({"/joint_states": Topic(JOINT_STATE_TYPE, on_joint_state, raw=True),
                                **{t: Topic(n, forward(t), raw=True) for t, n in LIVE_SIGNALS.items()},
                                LIVE_SCENE[0]: Topic(LIVE_SCENE[1], on_scene, latched_qos(), raw=True)})
            if on_ready is not None:
                on_ready(server.port)
            while not stop.is_set():
                if resend.is_set() and started:
                    resend.clear()
                    scene.send_latched()
                    for data in obstacles:
                        forward(LIVE_SCENE[0])(data)
                listener.spin_once(0.05)
        finally:
            server.stop()


def foxglove_from_args(bag: str | None, args: Any) -> int:
    """Handle ``--foxglove`` (after :func:`dualarm_control.app.view.options.add_foxglove_arguments`): serve ``bag``, or the running cell
    when None, until Ctrl-C; 0."""
    def ready(port: int) -> None:
        what = f"replaying {bag} in a loop" if bag is not None else "the running cell"
        print(f"Foxglove WebSocket server on ws://127.0.0.1:{port} (Foxglove: Open connection > Foxglove "
              f"WebSocket); {what}; Ctrl-C stops", flush=True)

    try:
        if bag is None:
            serve_live(args.foxglove_port, on_ready=ready)
        else:
            serve_bag(Path(bag), args.foxglove_port, speed=args.speed, on_ready=ready)
    except KeyboardInterrupt:
        pass
    return 0
