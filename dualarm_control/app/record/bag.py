"""``bag info`` and reading rosbag2 bags with ``rosbags`` (no ROS needed): :func:`read_bag` reads a
bag in one pass (``rosbags.highlevel.AnyReader``) into a :class:`Bag`; the run records and the report
made from it are :mod:`dualarm_control.app.record.bag_runs`.

Recording is :mod:`dualarm_control.ros.recorder` (rclpy).

Task bags (paper 001): A task run's bag holds ``/joint_states``, ``/velocity_controller/commands``, ``/diagnostics``
(``/wrench``, ``/clock``). The controller's per-cycle status names the scenario, the gain k,
the force variant, and gives the cycle's joint-state stamp, task time, normal offset f_F,
filtered force, solver status and cycle time. The task values f_i and bounds b_i are not
recorded: :func:`~dualarm_control.app.record.run_record.with_task_values` recomputes them from the
joint state of each cycle's stamp and its task time -- the code the in-process runner uses --
and :func:`~dualarm_control.app.record.report.summarize_run` gives the metrics. In
lockstep the joint states, times and offsets are bit-identical to the in-process run, so are
the metrics (except the cycle times, which are wall-clock measurements).

The force variant's bag also holds ``/contact_force`` (pybullet's brush-pan normal force, the
ground truth the force metrics use; cycle k takes the sample stamped after its step, as the
in-process runner measures after ``cell.step()``). Not in the bag: the per-step table
contacts; ``table_contacts`` is the simulator's running total from its last 1 Hz status.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from datetime import datetime
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt
from rosbags.highlevel import AnyReader, AnyReaderError
from rosbags.typesys import Stores, get_typestore

from dualarm_control.app.record.cell import (
    ProfileStreams,
    cell_parameters,
    recorded_topics,
)
from dualarm_control.arrays import FloatArray
from dualarm_control.errors import DualArmError
from dualarm_control.references.base import HELD_OBJECT_POSE
from dualarm_control.ros.cell_topic import CELL_TOPIC
from dualarm_control.ros.convert import stamp_ns

if TYPE_CHECKING:
    from dualarm_control.robot import RobotDescription

IntArray = npt.NDArray[np.int64]

COMMANDS_TOPIC = "/velocity_controller/commands"
JOINT_STATES_TOPIC = "/joint_states"
DIAGNOSTICS_TOPIC = "/diagnostics"
POSE_TOPIC = "/relative_pose"
TARGET_TOPIC = "/relative_target"
REPORT_TOPICS = (COMMANDS_TOPIC, JOINT_STATES_TOPIC, DIAGNOSTICS_TOPIC, POSE_TOPIC, TARGET_TOPIC)
"""Topics :func:`read_run` needs (each with at least one message) on the default hardware profile; a bag
recorded on another profile needs that profile's joint-state and command topics instead (its
``/dualarm/cell``: :mod:`dualarm_control.app.record.cell`)."""
CONTROLLER_STATUS = "controller_node"
"""``DiagnosticStatus.name`` of the controller's per-cycle status."""
DEFAULT_PERIOD_S = 0.005
TASK_KEY = "task_gain"
"""A controller status with this key is a task cycle (controller_node task mode)."""
SCENARIO_KEY = "scenario"
"""The task scenario's name or path in a task cycle's status."""
SIM_STATUS = "sim_node"
CONTACT_TOPIC = "/contact_force"
DESCRIPTION_TOPIC = "/robot_description"
PLAN_TOPIC = "/joint_reference"
"""A plan's joint trajectory (``dualarm launch --plan``): its bag is no run of the scenario's reference."""


class BagError(DualArmError):
    """A bag cannot be written, read or summarised (missing topics, bad content...)."""


def jazzy_typestore() -> Any:
    """The ``rosbags`` typestore with ROS 2 Jazzy's message definitions."""
    return get_typestore(Stores.ROS2_JAZZY)


# ===================================================================== bag info


def _format_stamp(ns: int) -> str:
    secs, rest = divmod(ns, 1_000_000_000)
    human = datetime.fromtimestamp(secs).strftime("%b %e %Y %H:%M:%S")
    return f"{human}.{rest:09d} ({secs}.{rest:09d})"


def _format_size(n: int) -> str:
    size = float(n)
    for unit in ("B", "KiB", "MiB", "GiB"):
        if size < 1024 or unit == "GiB":
            return f"{size:.1f} {unit}" if unit != "B" else f"{n} B"
        size /= 1024
    return f"{n} B"


def _bag_metadata(path: Path) -> dict[str, Any]:
    """``rosbag2_bagfile_information`` of a bag directory ({} for a bare file)."""
    import yaml

    meta_file = path / "metadata.yaml"
    if not meta_file.is_file():
        return {}
    data = yaml.safe_load(meta_file.read_text()) or {}
    info = data.get("rosbag2_bagfile_information", {})
    return info if isinstance(info, dict) else {}


NOTE_PREFIX = "dualarm."
"""``custom_data`` keys of metadata.yaml that are the package recorder's notes (e.g. that /tf was
computed from /joint_states, ``ros/computed_tf.NOTE``); ``dualarm bag info`` prints them."""


def format_notes(path: Path) -> str:
    """``bag info``'s lines for the recorder's notes, sorted by key, in its column layout ('' without any)."""
    custom = _bag_metadata(Path(path)).get("custom_data") or {}
    notes = [note for key, note in sorted(custom.items()) if str(key).startswith(NOTE_PREFIX)]
    return "\n".join(f"{'Note:':<19}{note}" for note in notes)


def open_reader(path: Path) -> AnyReader:
    """An opened AnyReader on a rosbag2 directory (Jazzy typestore as fallback); BagError if unreadable."""
    path = Path(path)
    if not path.exists():
        raise BagError(f"no bag at {path}")
    try:
        reader = AnyReader([path], default_typestore=jazzy_typestore())
        reader.open()
    except (AnyReaderError, FileNotFoundError) as exc:
        raise BagError(f"cannot read bag {path}: {exc}") from exc
    return reader


def bag_info(path: Path) -> str:
    """``ros2 bag info``-style summary of a bag directory."""
    path = Path(path)
    meta = _bag_metadata(path)
    reader = open_reader(path)
    try:
        files = meta.get("relative_file_paths", []) or [path.name]
        size = sum(f.stat().st_size for f in (path.iterdir() if path.is_dir() else [path]) if f.is_file())
        count = reader.message_count
        start, end = (reader.start_time, reader.end_time) if count else (0, 0)
        if count:
            end = max(start, end - 1)  # rosbags: end_time is one ns after the last message
        duration = end - start
        topics = [
            (name, info.msgtype or "?", info.msgcount, _serialization_format(info.connections))
            for name, info in sorted(reader.topics.items())
        ]
    finally:
        reader.close()
    label = [
        ("Files:", "\n".join(f"{'':19}{f}" if i else str(f) for i, f in enumerate(files))),
        ("Bag size:", _format_size(size)),
        ("Storage id:", str(meta.get("storage_identifier", "?"))),
        ("ROS Distro:", str(meta.get("ros_distro", "?"))),
        ("Version:", str(meta.get("version", "?"))),
        ("Duration:", f"{duration / 1e9:.9f}s"),
        ("Start:", _format_stamp(start)),
        ("End:", _format_stamp(end)),
        ("Messages:", str(count)),
    ]
    lines = [f"{k:<19}{v}" for k, v in label]
    for i, (name, typ, n, fmt) in enumerate(topics):
        head = "Topic information:" if i == 0 else ""
        lines.append(f"{head:<19}Topic: {name} | Type: {typ} | Count: {n} | Serialization Format: {fmt}")
    if not topics:
        lines.append("Topic information:")
    return "\n".join(lines)


def _serialization_format(connections: Iterable[Any]) -> str:
    formats = {getattr(c.ext, "serialization_format", "?") for c in connections}
    return ",".join(sorted(formats)) or "?"


# ===================================================================== reading a run


@dataclass
class TimedSeries:
    """Samples of one topic: receive times ``t`` [ns] (N,) and ``values`` (N, ...)."""

    t: IntArray
    values: FloatArray


def parse_float(text: str | None, default: float = float("nan")) -> float:
    try:
        return float(text) if text is not None else default
    except ValueError:
        return default


def parse_int(text: str | None) -> int | None:
    try:
        return int(text) if text is not None else None
    except ValueError:
        return None


def _pose_vector(translation: Any, rotation: Any) -> list[float]:
    return [float(translation.x), float(translation.y), float(translation.z),
            float(rotation.x), float(rotation.y), float(rotation.z), float(rotation.w)]


@dataclass(frozen=True)
class Status:
    """One /diagnostics status: receive time [ns], node name, level, message and values."""

    t: int
    name: str
    level: int
    message: str
    values: dict[str, str]

    @property
    def is_cycle(self) -> bool:
        """A controller cycle (not a safe command): it carries the per-cycle timing."""
        return "state_interval_s" in self.values


def _joint_order(names: Sequence[str], joint_names: Sequence[str], cache: dict[tuple[str, ...], list[int]]) -> list[int]:
    key = tuple(names)
    if key not in cache:
        missing = [j for j in joint_names if j not in key]
        if missing:
            raise BagError(f"{JOINT_STATES_TOPIC} lacks joints {', '.join(missing)} (has {', '.join(key)})")
        cache[key] = [key.index(j) for j in joint_names]
    return cache[key]


@dataclass
class Bag:
    """The messages of one pass over a bag (:func:`read_bag`): what a run record of either kind,
    and the fault matrix's graph streams (:mod:`dualarm_control.app.faults.episodes`), are built from."""

    streams: ProfileStreams = field(default_factory=lambda: ProfileStreams(recorded_topics({})))
    """the hardware profile's joint states and commands (the recorded profile's; else the default)"""
    cell: dict[str, dict[str, Any]] = field(default_factory=dict)  # node -> its parameters (/dualarm/cell)
    rows: dict[str, list[tuple[int, Any]]] = field(  # (receive ns, values) of poses, targets
        default_factory=lambda: {t: [] for t in (POSE_TOPIC, TARGET_TOPIC)})
    statuses: list[Status] = field(default_factory=list)  # every node's, in receive order
    pose_stamps: list[int] = field(default_factory=list)  # /relative_pose header stamps
    contact: dict[int, float] = field(default_factory=dict)  # /contact_force by header stamp
    wrists: dict[str, dict[int, FloatArray]] = field(default_factory=dict)  # a held object's wrist readings by stamp
    object_poses: dict[int, FloatArray] = field(default_factory=dict)  # the held box's world pose (7,) by stamp
    missing: list[str] = field(default_factory=list)  # the relative report's topics the bag lacks
    description: str | None = None  # the first /robot_description (the cell's URDF)
    recorded: frozenset[str] = frozenset()  # every topic of the bag

    def add(self, topic: str, t: int, msg: Any) -> None:
        if self.streams.add(topic, t, msg):
            return
        if topic == DESCRIPTION_TOPIC:
            self.description = self.description if self.description is not None else msg.data
        elif topic == CONTACT_TOPIC:
            self.contact.setdefault(stamp_ns(msg.header.stamp), float(msg.vector.z))
        elif topic in WRIST_TOPICS:
            f, m = msg.wrench.force, msg.wrench.torque
            self.wrists.setdefault(topic, {}).setdefault(stamp_ns(msg.header.stamp),
                                                         np.array((f.x, f.y, f.z, m.x, m.y, m.z)))
        elif topic == HELD_OBJECT_POSE:
            self.object_poses.setdefault(stamp_ns(msg.header.stamp),
                                         np.array(_pose_vector(msg.pose.position, msg.pose.orientation)))
        elif topic == POSE_TOPIC:
            self.rows[topic].append((t, _pose_vector(msg.pose.position, msg.pose.orientation)))
            self.pose_stamps.append(stamp_ns(msg.header.stamp))
        elif topic == TARGET_TOPIC:
            if msg.points and msg.points[0].transforms:
                tf = msg.points[0].transforms[0]
                self.rows[topic].append((t, _pose_vector(tf.translation, tf.rotation)))
        elif topic == DIAGNOSTICS_TOPIC:
            for s in msg.status:
                level = s.level[0] if isinstance(s.level, (bytes, bytearray)) else int(s.level)
                self.statuses.append(Status(t, s.name, int(level), s.message, {kv.key: kv.value for kv in s.values}))

    @property
    def states(self) -> list[tuple[int, int, list[str], Any]]:
        """(receive ns, stamp, names, message) of the joint states (several topics' assembled in the
        robot's joint order)."""
        return self.streams.states(self.robot.joint_names)

    @property
    def commands(self) -> list[tuple[int, FloatArray]]:
        """(receive ns, joint velocities [rad/s] in the robot's joint order) of each cycle's command, from
        the profile's outputs; BagError when they do not fit the robot."""
        try:
            return self.streams.commands(self.robot.joint_names)
        except DualArmError as exc:
            raise BagError(str(exc)) from None

    @property
    def needed(self) -> tuple[str, ...]:
        """The topics a relative-motion report needs on this bag's profile."""
        return (*self.streams.topics.outputs, *self.streams.topics.joint_states, DIAGNOSTICS_TOPIC, POSE_TOPIC,
                TARGET_TOPIC)

    @property
    def cycles(self) -> list[tuple[int, dict[str, str]]]:
        """(receive ns, values) of the controller's statuses."""
        return [(s.t, s.values) for s in self.statuses if s.name == CONTROLLER_STATUS]

    @cached_property
    def robot(self) -> RobotDescription:
        """The robot of the run: the controller's ``robot`` on /diagnostics (a bag recorded before
        robots were data: the LWR4 cell)."""
        from dualarm_control.robot_params import DEFAULT_ROBOT, load_robot

        return load_robot(next((v["robot"] for _, v in self.cycles if v.get("robot")), DEFAULT_ROBOT))

    @property
    def table_contacts(self) -> int:
        """The simulator's running total of table contacts (its last 1 Hz status)."""
        return max((int(s.values["table_contacts"]) for s in self.statuses
                    if s.name == SIM_STATUS and "table_contacts" in s.values), default=0)

    @property
    def task_cycles(self) -> list[tuple[int, dict[str, str]]]:
        """The controller's task cycles (none in a bag with relative targets)."""
        return [] if self.rows[TARGET_TOPIC] else [(t, v) for t, v in self.cycles if TASK_KEY in v]

    def require_report_topics(self, path: Path) -> None:
        """BagError naming the topics a relative-motion report needs and the bag lacks."""
        if self.missing:
            raise BagError(f"bag {path} lacks {', '.join(self.missing)} (the report needs {', '.join(self.needed)})")

    def joint_states(self, joint_names: Sequence[str]) -> tuple[TimedSeries, FloatArray]:
        """/joint_states in the order of ``joint_names``: positions by receive time, and the
        velocities (as many rows as states carry them)."""
        order: dict[tuple[str, ...], list[int]] = {}
        q_rows, qd_rows = [], []
        for _, _, names, msg in self.states:
            idx = _joint_order(names, joint_names, order)
            q_rows.append(np.asarray(msg.position, dtype=float)[idx])
            if len(msg.velocity) == len(names):
                qd_rows.append(np.asarray(msg.velocity, dtype=float)[idx])
        n = len(joint_names)
        return (TimedSeries(np.array([s[0] for s in self.states], dtype=np.int64),
                            np.array(q_rows, dtype=float).reshape(len(q_rows), n)),
                np.array(qd_rows, dtype=float).reshape(len(qd_rows), n))

    def series(self, topic: str, width: int) -> TimedSeries:
        """Receive times and values of ``topic``'s rows (:data:`COMMANDS_TOPIC`: :attr:`commands`)."""
        rows = self.commands if topic == COMMANDS_TOPIC else self.rows[topic]
        t = np.array([r[0] for r in rows], dtype=np.int64)
        values = np.array([r[1] for r in rows], dtype=float).reshape(len(rows), width)
        return TimedSeries(t, values)


def read_cell(path: Path) -> dict[str, dict[str, Any]]:
    """Per node, the parameters it published on ``/dualarm/cell`` first ({} when the bag has none)."""
    reader = open_reader(path)
    try:
        return _cell(reader, path)
    finally:
        reader.close()


def _cell(reader: AnyReader, path: Path) -> dict[str, dict[str, Any]]:
    cells = [c for c in reader.connections if c.topic == CELL_TOPIC]
    return cell_parameters((msg.data for _, _, msg in _decoded(reader, cells, path)), f"{path}: {CELL_TOPIC}")


WRIST_TOPICS = ("/left/wrench", "/right/wrench")
"""A held object's wrist F/T sensors (sim_node, issue 41): read for the viewer's wrench arrows."""


def read_bag(path: Path) -> Bag:
    """Every message a report, a viewer or a fault analysis reads: the nodes' parameters first
    (``/dualarm/cell``: the hardware profile's topics), then the rest in one pass."""
    reader = open_reader(path)
    try:
        cell = _cell(reader, path)
        try:
            topics = recorded_topics(cell.get(CONTROLLER_STATUS, {}))
        except DualArmError as exc:
            raise BagError(f"bag {path}: the controller's hardware profile on {CELL_TOPIC}: {exc}") from None
        bag = Bag(streams=ProfileStreams(topics), cell=cell, recorded=frozenset(reader.topics))
        bag.missing = missing_topics(reader, bag.needed)
        wanted = (*bag.needed, CONTACT_TOPIC, DESCRIPTION_TOPIC, *WRIST_TOPICS, HELD_OBJECT_POSE)
        connections = [c for c in reader.connections if c.topic in wanted]
        for topic, t, msg in _decoded(reader, connections, path):
            bag.add(topic, t, msg)
    finally:
        reader.close()
    return bag


def _decoded(reader: AnyReader, connections: list[Any], path: Path) -> Iterator[tuple[str, int, Any]]:
    """(topic, time, message) of ``connections``; BagError naming the bag, the topic and what failed when the
    storage or a message cannot be decoded (a corrupt or truncated file: rosbags raises anything from
    ``OverflowError`` to ``struct.error`` then). No connections: nothing (rosbags would read them all)."""
    if not connections:
        return
    messages = reader.messages(connections=connections)
    count = 0
    while True:
        try:
            item = next(messages, None)
            if item is None:
                return
            conn, t, raw = item
            msg = reader.deserialize(raw, conn.msgtype)
        except Exception as exc:  # noqa: BLE001 - any failure to decode the file is a bad bag
            raise BagError(f"cannot read bag {path}: corrupt data after {count} messages "
                           f"({type(exc).__name__}: {exc})") from None
        count += 1
        yield conn.topic, t, msg


def missing_topics(reader: AnyReader, needed: Iterable[str] = REPORT_TOPICS) -> list[str]:
    """Needed topics absent from the bag or without messages."""
    topics = reader.topics
    return [t for t in needed if t not in topics or topics[t].msgcount == 0]
