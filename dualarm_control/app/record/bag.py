"""``bag info`` and the bag report: reading rosbag2 bags with ``rosbags`` (no ROS needed).

Recording is :mod:`dualarm_control.ros.recorder` (rclpy). :func:`read_run` reads a bag (one
pass, ``rosbags.highlevel.AnyReader``) into the run records of the in-process runner
(:class:`~dualarm_control.app.record.run_record.RunRecord`: one per solver of a relative-motion
run, the one of a task run); :func:`report` summarises them with the same
:func:`~dualarm_control.app.record.report.summarize_run` and draws the figures of their kind.

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
    from dualarm_control.app.record.run_record import RunRecord
    from dualarm_control.robot import RobotDescription
    from dualarm_control.scenario import Scenario

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


def read_run(path: Path, bag: Bag | None = None) -> tuple[list[RunRecord], Scenario | None]:
    """The run records of a bag (``bag``: its messages if already read) and, for a task run, its
    scenario: one record per solver of a relative-motion run (:func:`_relative_records`), the one
    record of a task run (:func:`_task_record`); BagError naming what the bag lacks."""
    bag = bag or read_bag(Path(path))
    if bag.task_cycles:
        return _task_record(Path(path), bag)
    bag.require_report_topics(path)
    return _relative_records(bag), None


def _joint_order(names: Sequence[str], joint_names: Sequence[str], cache: dict[tuple[str, ...], list[int]]) -> list[int]:
    key = tuple(names)
    if key not in cache:
        missing = [j for j in joint_names if j not in key]
        if missing:
            raise BagError(f"{JOINT_STATES_TOPIC} lacks joints {', '.join(missing)} (has {', '.join(key)})")
        cache[key] = [key.index(j) for j in joint_names]
    return cache[key]


def _relative_records(bag: Bag) -> list[RunRecord]:
    """One :class:`RunRecord` per solver of the controller's statuses (a bag normally holds one).

    Messages are attributed to the solver of the nearest controller status in receive time.
    The final error is the last /relative_pose against the last /relative_target of the solver.
    """
    from dualarm_control.app.record.run_record import (
        RunRecord,
        absolute_columns,
        nan_column,
    )

    joint_names = bag.robot.joint_names
    n = len(joint_names)
    if not bag.cycles:
        raise BagError(f"{DIAGNOSTICS_TOPIC} has no status named '{CONTROLLER_STATUS}'")
    states, velocities = bag.joint_states(joint_names)
    diag_t = np.array([t for t, _ in bag.cycles], dtype=np.int64)
    solvers = [v.get("solver", "unknown") for _, v in bag.cycles]
    series = {JOINT_STATES_TOPIC: states, COMMANDS_TOPIC: bag.series(COMMANDS_TOPIC, n),
              POSE_TOPIC: bag.series(POSE_TOPIC, 7), TARGET_TOPIC: bag.series(TARGET_TOPIC, 7)}
    labels = {topic: nearest_labels(s.t, diag_t, solvers) for topic, s in series.items()}
    by_state = len(velocities) == len(states.t)
    out = []
    for solver in dict.fromkeys(solvers):
        mine = {topic: labels[topic] == solver for topic in series}
        commands = series[COMMANDS_TOPIC].values[mine[COMMANDS_TOPIC]]
        if commands.shape[0] == 0:
            continue
        cycles = [v for (_, v), s in zip(bag.cycles, solvers, strict=True) if s == solver]

        def column(key: str, cycles: list[dict[str, str]] = cycles) -> FloatArray:
            return np.array([parse_float(v.get(key)) for v in cycles])

        periods = column("control_period_s")
        period = float(np.median(periods[np.isfinite(periods)])) if np.isfinite(periods).any() else DEFAULT_PERIOD_S
        q = states.values[mine[JOINT_STATES_TOPIC]]
        k = commands.shape[0]
        out.append(RunRecord(
            label=solver, kind="segments", period=period,
            time=_time_axis([parse_int(v.get("stamp_ns")) for v in cycles], k, period),
            positions=q[:-1], velocities=velocities[mine[JOINT_STATES_TOPIC]] if by_state else np.zeros((0, n)),
            commands=commands, status=[v.get("status", "") for v in cycles], solve_time=nan_column(k),
            cycle_time=column("cycle_time_s"), position_error=column("position_error_m"),
            orientation_error=column("orientation_error_rad"),
            final_positions=q[-1] if len(q) else nan_column(n), contact_force=nan_column(k),
            measured_force=nan_column(k), normal_offset=nan_column(k), table_contacts=nan_column(k),
            final_errors=pose_error(_last_in(series[POSE_TOPIC], mine[POSE_TOPIC]),
                                    _last_in(series[TARGET_TOPIC], mine[TARGET_TOPIC])),
            absolute_error=absolute_columns(column("absolute_position_error_m"),
                                            column("absolute_orientation_error_rad"))))
    return out


# ===================================================================== summarising a run


def quaternion_angle(q_a: npt.ArrayLike, q_b: npt.ArrayLike) -> float:
    """Rotation angle [rad] between two (x, y, z, w) quaternions, in [0, pi] (robust near 0)."""
    a = np.asarray(q_a, dtype=float)
    b = np.asarray(q_b, dtype=float)
    a, b = a / np.linalg.norm(a), b / np.linalg.norm(b)
    if float(a @ b) < 0.0:
        b = -b
    return float(4.0 * np.arctan2(np.linalg.norm(a - b), np.linalg.norm(a + b)))


def pose_error(pose: npt.ArrayLike, target: npt.ArrayLike) -> tuple[float, float]:
    """(position [m], orientation [rad]) distance of two ``[x, y, z, qx, qy, qz, qw]`` poses."""
    p, q = np.asarray(pose, dtype=float), np.asarray(target, dtype=float)
    return float(np.linalg.norm(p[:3] - q[:3])), quaternion_angle(p[3:], q[3:])


def nearest_index(t: IntArray, ref_t: IntArray) -> IntArray:
    """For each time in ``t``, the index of the nearest time in ``ref_t`` (sorted, non-empty)."""
    right = np.clip(np.searchsorted(ref_t, t), 0, len(ref_t) - 1)
    left = np.clip(right - 1, 0, len(ref_t) - 1)
    return np.where(np.abs(t - ref_t[left]) <= np.abs(ref_t[right] - t), left, right)


def nearest_labels(t: IntArray, ref_t: IntArray, labels: Sequence[str]) -> npt.NDArray[np.str_]:
    """For each time in ``t``, the label of the nearest time in ``ref_t`` (sorted, non-empty)."""
    return np.asarray(labels, dtype=str)[nearest_index(t, ref_t)]


def _last_in(series: TimedSeries, mask: npt.NDArray[np.bool_]) -> FloatArray:
    """The last value selected by ``mask`` (the last overall when the mask selects none)."""
    values = series.values[mask] if mask.any() else series.values
    return values[-1]


def _time_axis(stamps: Sequence[int | None], n: int, period: float) -> FloatArray:
    """Seconds from the diagnostics' joint-state stamps when they match the commands, else k * period."""
    if len(stamps) == n and n > 0 and all(s is not None for s in stamps):
        arr = np.array(stamps, dtype=np.int64)
        return (arr - arr[0]).astype(float) * 1e-9
    return np.arange(n, dtype=float) * period


def _task_record(path: Path, bag: Bag) -> tuple[list[RunRecord], Scenario]:
    """The :class:`RunRecord` of a task-scenario bag (see the module docstring) and its scenario."""
    from dualarm_control.app.record.run_record import (
        RunRecord,
        nan_column,
        with_task_values,
    )
    from dualarm_control.kinematics import DualArmModel
    from dualarm_control.scenario import load_scenario

    by_stamp: dict[int, tuple[int, dict[str, str]]] = {}
    for t, values in bag.task_cycles:
        by_stamp.setdefault(int(values["stamp_ns"]), (t, values))
    first = by_stamp[min(by_stamp)][1]
    joint_states: dict[int, tuple[list[str], Any]] = {}  # by stamp: a re-sent state (lockstep) is the same
    for _, stamp, names, msg in bag.states:
        joint_states.setdefault(stamp, (names, msg.position))
    # A real-time recording starts when the recorder's subscriptions are matched, which can be
    # a few states after the first cycle: cycles before the first recorded state are outside
    # the bag. From that state on, every cycle's state must be in the bag.
    covered_from = min(joint_states, default=min(by_stamp))
    stamps = sorted(s for s in by_stamp if s >= covered_from)
    if not stamps:
        raise BagError(f"bag {path}: no controller task cycle at or after the first recorded {JOINT_STATES_TOPIC}")
    scenario = load_scenario(first[SCENARIO_KEY])
    model = DualArmModel(scenario.robot)
    order: dict[tuple[str, ...], list[int]] = {}
    positions = np.zeros((len(stamps), model.nq))
    for k, stamp in enumerate(stamps):
        if stamp not in joint_states:
            raise BagError(f"bag {path}: no {JOINT_STATES_TOPIC} with the stamp {stamp} of controller cycle {k}")
        names, q = joint_states[stamp]
        idx = order.setdefault(tuple(names), [names.index(j) for j in model.joint_names])
        positions[k] = np.asarray(q, dtype=np.float64)[idx]
    cycles = [by_stamp[s] for s in stamps]
    sent = bag.commands
    received = np.array([t for t, _ in sent], dtype=np.int64)
    nearest = np.clip(np.searchsorted(received, [t for t, _ in cycles]), 0, max(len(received) - 1, 0))
    commands = (np.array([sent[i][1] for i in nearest]) if len(received)
                else np.full((len(stamps), model.nq), np.nan))

    def column(key: str) -> FloatArray:
        return np.array([float(v[key]) for _, v in cycles])

    table = np.zeros(len(stamps))
    table[-1] = bag.table_contacts
    contact = np.full(len(stamps), np.nan)
    if bag.contact:  # cycle k's contact is the one after its step: the first sample stamped after it
        contact_stamps = np.array(sorted(bag.contact), dtype=np.int64)
        after = np.searchsorted(contact_stamps, np.array(stamps, dtype=np.int64), side="right")
        for k, i in enumerate(after):
            if i < len(contact_stamps):
                contact[k] = bag.contact[int(contact_stamps[i])]
    n, gain, force = len(stamps), float(first["task_gain"]), first["force"] == "1"
    label = f"k={gain:g}" + ((" internal on" if force else " internal off") if "internal_wrench" in first
                             else " force" if force else "")
    record = RunRecord(
        label=label, kind=scenario.reference.kind, period=float(first["control_period_s"]), time=column("task_time_s"),
        positions=positions, velocities=np.full(positions.shape, np.nan), commands=commands,
        status=[v["status"] for _, v in cycles], solve_time=nan_column(n), cycle_time=column("cycle_time_s"),
        position_error=nan_column(n), orientation_error=nan_column(n), final_positions=nan_column(model.nq),
        contact_force=contact, measured_force=column("measured_force_n"), normal_offset=column("normal_offset_m"),
        table_contacts=table, internal_wrench=(np.array([[float(x) for x in v["internal_wrench"].split()]
                                                         for _, v in cycles]) if "internal_wrench" in first else None),
        identified_mass=float(cycles[-1][1].get("identified_mass_kg", "nan")),
        object_pose=(np.array([bag.object_poses.get(s, np.full(7, np.nan)) for s in stamps]) if bag.object_poses
                     else None))
    return [with_task_values(record, scenario, model, gain, force)], scenario


def judged_scenario(bag: Bag) -> Scenario | None:
    """The scenario a relative-motion bag ran, when its run has verdicts (scripted goals, or segments: issue
    40): the controller's ``scenario`` on /diagnostics, on the bag's robot. None for another kind, or when
    the scenario cannot be loaded here (a file of another machine)."""
    from dualarm_control.errors import DualArmError
    from dualarm_control.references.segments import SegmentsSource
    from dualarm_control.scenario import load_scenario

    name = next((v[SCENARIO_KEY] for _, v in bag.cycles if v.get(SCENARIO_KEY)), "")
    if not name or bag.cell.get(CONTROLLER_STATUS, {}).get("plan") or PLAN_TOPIC in bag.recorded:
        return None  # a plan's run tracks its joint trajectory, not the scenario's reference
    try:
        scenario = load_scenario(name, bag.robot)
    except DualArmError:
        return None
    judged = getattr(scenario.reference, "commands", None) or isinstance(scenario.reference, SegmentsSource)
    return scenario if judged else None


def report(path: Path, output: Path) -> tuple[dict[str, dict[str, Any]], str, list[str]]:
    """``dualarm report``: ``output/metrics.json`` ({label: record}, the keys of ``dualarm
    experiment``) and the figures of the run's kind. Returns the records, the kind and the
    figures' file names; BagError when the bag lacks what the report needs.
    """
    from dualarm_control.app.record.report import (
        DEFAULT_ALPHA,
        prepare_output,
        summarize_run,
        write_figures,
        write_json,
    )
    from dualarm_control.kinematics import DualArmModel

    bag = read_bag(Path(path))
    runs, scenario = read_run(Path(path), bag)
    if not runs:
        raise BagError(f"bag {path}: no {COMMANDS_TOPIC} message could be attributed to a solver")
    model = DualArmModel(scenario.robot if scenario is not None else bag.robot)  # the run's limits
    if scenario is None:
        scenario = judged_scenario(bag)
    alpha = bag.cell.get(CONTROLLER_STATUS, {}).get("alpha", DEFAULT_ALPHA)  # the run's eq (24) share, if recorded
    results = {r.label: summarize_run(r, scenario, model, float(alpha)) for r in runs}
    prepare_output(Path(output))
    write_json(Path(output) / "metrics.json", results)
    return results, runs[0].kind, write_figures(runs[0].kind, Path(output), Path(path).name, runs, scenario)
