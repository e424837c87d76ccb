"""``bag info`` and the bag report: reading rosbag2 bags with ``rosbags`` (no ROS needed).

Recording is :mod:`dualarm_control.ros.recorder` (rclpy). The report reads a bag with
``rosbags.highlevel.AnyReader`` and builds the same metrics record as an in-process
experiment (:func:`dualarm_control.app.record.report.summarize`).

Task bags (paper 001): A task run's bag holds ``/joint_states``, ``/velocity_controller/commands``, ``/diagnostics``
(``/wrench``, ``/clock``). The controller's per-cycle status names the scenario, the gain k,
the force variant, and gives the cycle's joint-state stamp, task time, normal offset f_F,
filtered force, solver status and cycle time. The task values f_i and bounds b_i are not
recorded: :func:`~dualarm_control.app.run.experiment.with_task_values` recomputes them from the
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

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np
import numpy.typing as npt
from rosbags.highlevel import AnyReader, AnyReaderError
from rosbags.typesys import Stores, get_typestore

from dualarm_control.errors import DualArmError
from dualarm_control.ros.convert import stamp_ns

if TYPE_CHECKING:
    from dualarm_control.app.run.experiment import RunRecord
    from dualarm_control.scenario import Scenario

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

COMMANDS_TOPIC = "/velocity_controller/commands"
JOINT_STATES_TOPIC = "/joint_states"
DIAGNOSTICS_TOPIC = "/diagnostics"
POSE_TOPIC = "/relative_pose"
TARGET_TOPIC = "/relative_target"
REPORT_TOPICS = (COMMANDS_TOPIC, JOINT_STATES_TOPIC, DIAGNOSTICS_TOPIC, POSE_TOPIC, TARGET_TOPIC)
"""Topics :func:`read_run` needs (each with at least one message)."""
CONTROLLER_STATUS = "controller_node"
"""``DiagnosticStatus.name`` of the controller's per-cycle status."""
DEFAULT_PERIOD_S = 0.005


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


@dataclass
class ControllerDiagnostics:
    """The controller's per-cycle status from ``/diagnostics`` (one entry per cycle)."""

    t: IntArray
    solver: list[str] = field(default_factory=list)
    status: list[str] = field(default_factory=list)
    cycle_time: list[float] = field(default_factory=list)
    position_error: list[float] = field(default_factory=list)
    orientation_error: list[float] = field(default_factory=list)
    period: list[float] = field(default_factory=list)
    stamp_ns: list[int | None] = field(default_factory=list)


@dataclass
class RunData:
    """What a report needs from a bag, joint vectors in the model's joint order."""

    commands: TimedSeries
    positions: TimedSeries
    velocities: FloatArray
    poses: TimedSeries
    targets: TimedSeries
    diagnostics: ControllerDiagnostics


def _float(text: str | None, default: float = float("nan")) -> float:
    try:
        return float(text) if text is not None else default
    except ValueError:
        return default


def _int_or_none(text: str | None) -> int | None:
    try:
        return int(text) if text is not None else None
    except ValueError:
        return None


def _pose_vector(translation: Any, rotation: Any) -> list[float]:
    return [float(translation.x), float(translation.y), float(translation.z),
            float(rotation.x), float(rotation.y), float(rotation.z), float(rotation.w)]


class _RunCollector:
    """Accumulates the messages of one bag pass, topic by topic."""

    def __init__(self, joint_names: Sequence[str]) -> None:
        self.joint_names = list(joint_names)
        self.rows: dict[str, list[tuple[int, Any]]] = {t: [] for t in REPORT_TOPICS}
        self.velocities: list[FloatArray] = []
        self.diag = ControllerDiagnostics(t=np.zeros(0, dtype=np.int64))
        self.diag_t: list[int] = []
        self._order: dict[tuple[str, ...], list[int]] = {}

    def add(self, topic: str, t: int, msg: Any) -> None:
        handler = {
            COMMANDS_TOPIC: lambda: self.rows[topic].append((t, np.asarray(msg.data, dtype=float))),
            JOINT_STATES_TOPIC: lambda: self._joint_state(t, msg),
            DIAGNOSTICS_TOPIC: lambda: self._diagnostics(t, msg),
            POSE_TOPIC: lambda: self.rows[topic].append((t, _pose_vector(msg.pose.position, msg.pose.orientation))),
            TARGET_TOPIC: lambda: self._target(t, msg),
        }[topic]
        handler()

    def _reorder(self, names: Sequence[str]) -> list[int]:
        key = tuple(names)
        if key not in self._order:
            missing = [j for j in self.joint_names if j not in key]
            if missing:
                raise BagError(f"{JOINT_STATES_TOPIC} lacks joints {', '.join(missing)} (has {', '.join(key)})")
            self._order[key] = [key.index(j) for j in self.joint_names]
        return self._order[key]

    def _joint_state(self, t: int, msg: Any) -> None:
        idx = self._reorder(list(msg.name))
        self.rows[JOINT_STATES_TOPIC].append((t, np.asarray(msg.position, dtype=float)[idx]))
        if len(msg.velocity) == len(msg.name):
            self.velocities.append(np.asarray(msg.velocity, dtype=float)[idx])

    def _target(self, t: int, msg: Any) -> None:
        if msg.points and msg.points[0].transforms:
            tf = msg.points[0].transforms[0]
            self.rows[TARGET_TOPIC].append((t, _pose_vector(tf.translation, tf.rotation)))

    def _diagnostics(self, t: int, msg: Any) -> None:
        for status in msg.status:
            if status.name != CONTROLLER_STATUS:
                continue
            values = {kv.key: kv.value for kv in status.values}
            self.diag_t.append(t)
            self.diag.solver.append(values.get("solver", "unknown"))
            self.diag.status.append(values.get("status", ""))
            self.diag.cycle_time.append(_float(values.get("cycle_time_s")))
            self.diag.position_error.append(_float(values.get("position_error_m")))
            self.diag.orientation_error.append(_float(values.get("orientation_error_rad")))
            self.diag.period.append(_float(values.get("control_period_s")))
            self.diag.stamp_ns.append(_int_or_none(values.get("stamp_ns")))

    def series(self, topic: str, width: int) -> TimedSeries:
        rows = self.rows[topic]
        t = np.array([r[0] for r in rows], dtype=np.int64)
        values = np.array([r[1] for r in rows], dtype=float).reshape(len(rows), width)
        return TimedSeries(t, values)

    def finish(self) -> RunData:
        n = len(self.joint_names)
        widths = {len(v) for _, v in self.rows[COMMANDS_TOPIC]}
        if widths != {n}:
            raise BagError(f"{COMMANDS_TOPIC} data must have {n} values (one per joint), got lengths {sorted(widths)}")
        if not self.diag_t:
            raise BagError(f"{DIAGNOSTICS_TOPIC} has no status named '{CONTROLLER_STATUS}'")
        self.diag.t = np.array(self.diag_t, dtype=np.int64)
        positions = self.series(JOINT_STATES_TOPIC, n)
        velocities = np.array(self.velocities, dtype=float).reshape(len(self.velocities), n)
        return RunData(self.series(COMMANDS_TOPIC, n), positions, velocities,
                       self.series(POSE_TOPIC, 7), self.series(TARGET_TOPIC, 7), self.diag)


def missing_topics(reader: AnyReader, needed: Iterable[str] = REPORT_TOPICS) -> list[str]:
    """Needed topics absent from the bag or without messages."""
    topics = reader.topics
    return [t for t in needed if t not in topics or topics[t].msgcount == 0]


def read_run(path: Path, joint_names: Sequence[str]) -> RunData:
    """Read the report topics of a bag; BagError naming the topics it lacks."""
    reader = open_reader(path)
    try:
        missing = missing_topics(reader)
        if missing:
            raise BagError(f"bag {path} lacks {', '.join(missing)} (the report needs {', '.join(REPORT_TOPICS)})")
        collector = _RunCollector(joint_names)
        connections = [c for c in reader.connections if c.topic in REPORT_TOPICS]
        for conn, t, raw in reader.messages(connections=connections):
            collector.add(conn.topic, t, reader.deserialize(raw, conn.msgtype))
        return collector.finish()
    finally:
        reader.close()


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


def nearest_labels(t: IntArray, ref_t: IntArray, labels: Sequence[str]) -> npt.NDArray[np.str_]:
    """For each time in ``t``, the label of the nearest time in ``ref_t`` (sorted, non-empty)."""
    lab = np.asarray(labels, dtype=str)
    if t.size == 0:
        return np.zeros(0, dtype=lab.dtype)
    right = np.clip(np.searchsorted(ref_t, t), 0, len(ref_t) - 1)
    left = np.clip(right - 1, 0, len(ref_t) - 1)
    use_left = np.abs(t - ref_t[left]) <= np.abs(ref_t[right] - t)
    return lab[np.where(use_left, left, right)]


@dataclass
class SolverRun:
    """One solver's slice of a bag: its metrics record and its command time series."""

    solver: str
    record: dict[str, float | int]
    time: FloatArray
    commands: FloatArray


def _last_in(series: TimedSeries, mask: npt.NDArray[np.bool_]) -> FloatArray:
    """The last value selected by ``mask`` (the last overall when the mask selects none)."""
    values = series.values[mask] if mask.any() else series.values
    return values[-1]


def _finite(values: Iterable[float]) -> FloatArray:
    arr = np.asarray(list(values), dtype=float)
    return arr[np.isfinite(arr)]


def summarize_solvers(run: RunData, model: Any) -> list[SolverRun]:
    """Per solver in the controller diagnostics, the metrics record and command series.

    Messages are attributed to the solver of the nearest controller diagnostics in
    receive time (a bag normally holds one solver). ``model`` gives joint limits
    (``q_min``, ``q_max``, ``qd_max``).
    """
    from dualarm_control.app.record.report import summarize

    diag = run.diagnostics
    solvers = list(dict.fromkeys(diag.solver))
    per_msg = {
        "commands": nearest_labels(run.commands.t, diag.t, diag.solver),
        "positions": nearest_labels(run.positions.t, diag.t, diag.solver),
        "poses": nearest_labels(run.poses.t, diag.t, diag.solver),
        "targets": nearest_labels(run.targets.t, diag.t, diag.solver),
    }
    velocity_labels = per_msg["positions"] if len(run.velocities) == len(run.positions.t) else None
    out = []
    for solver in solvers:
        in_diag = np.array([s == solver for s in diag.solver])
        commands = run.commands.values[per_msg["commands"] == solver]
        if commands.shape[0] == 0:
            continue
        periods = _finite(np.array(diag.period)[in_diag])
        period = float(np.median(periods)) if periods.size else DEFAULT_PERIOD_S
        velocities = (run.velocities[velocity_labels == solver] if velocity_labels is not None
                      else np.zeros((0, commands.shape[1])))
        record = summarize(
            commands=commands,
            positions=run.positions.values[per_msg["positions"] == solver],
            velocities=velocities,
            period=period,
            statuses=[s for s, keep in zip(diag.status, in_diag, strict=True) if keep],
            cycle_times=_finite(np.array(diag.cycle_time)[in_diag]),
            tracking_errors=(np.array(diag.position_error)[in_diag], np.array(diag.orientation_error)[in_diag]),
            final_errors=pose_error(_last_in(run.poses, per_msg["poses"] == solver),
                                    _last_in(run.targets, per_msg["targets"] == solver)),
            q_limits=(model.q_min, model.q_max),
            qd_max=model.qd_max,
        )
        stamps = [s for s, keep in zip(diag.stamp_ns, in_diag, strict=True) if keep]
        out.append(SolverRun(solver, record, _time_axis(stamps, commands.shape[0], period), commands))
    return out


def _time_axis(stamps: Sequence[int | None], n: int, period: float) -> FloatArray:
    """Seconds from the diagnostics' joint-state stamps when they match the commands, else k * period."""
    if len(stamps) == n and n > 0 and all(s is not None for s in stamps):
        arr = np.array(stamps, dtype=np.int64)
        return (arr - arr[0]).astype(float) * 1e-9
    return np.arange(n, dtype=float) * period


def report(path: Path, output: Path) -> dict[str, dict[str, float | int]]:
    """Summarise a recorded run: ``output/metrics.json`` and ``output/velocity_norms.png``.

    Returns ``{solver: record}``; BagError when the bag lacks needed topics.
    """
    from dualarm_control.app.record.report import plot_velocity_norms, write_metrics
    from dualarm_control.kinematics import DualArmModel

    model = DualArmModel()
    runs = summarize_solvers(read_run(Path(path), model.joint_names), model)
    if not runs:
        raise BagError(f"bag {path}: no {COMMANDS_TOPIC} message could be attributed to a solver")
    results = {r.solver: r.record for r in runs}
    output = Path(output)
    write_metrics(output / "metrics.json", results)
    plot_velocity_norms({r.solver: (r.time, r.commands) for r in runs}, output / "velocity_norms.png",
                        title=f"{Path(path).name}: |qd_i| and active joints")
    return results


# --- task bags (paper 001) ---------------------------------------------------------
TASK_KEY = "task_gain"
"""A controller status with this key is a task cycle (controller_node task mode)."""
SCENARIO_KEY = "scenario"
"""The task scenario's name or path in a task cycle's status."""
SIM_STATUS = "sim_node"
CONTACT_TOPIC = "/contact_force"


@dataclass
class _TaskBag:
    joint_states: dict[int, tuple[list[str], FloatArray]] = field(default_factory=dict)  # by header stamp
    commands: list[tuple[int, FloatArray]] = field(default_factory=list)  # (receive ns, data)
    cycles: list[tuple[int, dict[str, str]]] = field(default_factory=list)  # (receive ns, values)
    table_contacts: int = 0
    contact: dict[int, float] = field(default_factory=dict)  # /contact_force by header stamp


def holds_task_cycles(path: Path) -> bool:
    """Whether the bag holds controller task cycles (and no relative target)."""
    reader = open_reader(path)
    try:
        if "/relative_target" in reader.topics or DIAGNOSTICS_TOPIC not in reader.topics:
            return False
        connections = [c for c in reader.connections if c.topic == DIAGNOSTICS_TOPIC]
        for conn, _, raw in reader.messages(connections=connections):
            for status in cast(Any, reader.deserialize(raw, conn.msgtype)).status:
                if status.name == CONTROLLER_STATUS and any(kv.key == TASK_KEY for kv in status.values):
                    return True
        return False
    finally:
        reader.close()


def _read(path: Path) -> _TaskBag:
    reader = open_reader(path)
    out = _TaskBag()
    try:
        topics = (JOINT_STATES_TOPIC, COMMANDS_TOPIC, DIAGNOSTICS_TOPIC, CONTACT_TOPIC)
        connections = [c for c in reader.connections if c.topic in topics]
        for conn, t, raw in reader.messages(connections=connections):
            msg: Any = reader.deserialize(raw, conn.msgtype)
            if conn.topic == JOINT_STATES_TOPIC:  # a re-sent state (lockstep) has the same stamp and values
                out.joint_states.setdefault(stamp_ns(msg.header.stamp),
                                            (list(msg.name), np.array(msg.position, dtype=np.float64)))
            elif conn.topic == CONTACT_TOPIC:
                out.contact.setdefault(stamp_ns(msg.header.stamp), float(msg.vector.z))
            elif conn.topic == COMMANDS_TOPIC:
                out.commands.append((t, np.array(msg.data, dtype=np.float64)))
            else:
                for status in msg.status:
                    values = {kv.key: kv.value for kv in status.values}
                    if status.name == CONTROLLER_STATUS and TASK_KEY in values:
                        out.cycles.append((t, values))
                    elif status.name == SIM_STATUS and "table_contacts" in values:
                        out.table_contacts = max(out.table_contacts, int(values["table_contacts"]))
    finally:
        reader.close()
    return out


def read_task_run(path: Path) -> tuple[RunRecord, Scenario]:
    """The :class:`RunRecord` of a task-scenario bag and its scenario; BagError if it is not one."""
    from dualarm_control.app.run.experiment import (
        RunRecord,
        nan_column,
        with_task_values,
    )
    from dualarm_control.kinematics import DualArmModel
    from dualarm_control.scenario import load_scenario

    bag = _read(Path(path))
    if not bag.cycles:
        raise BagError(f"bag {path}: no controller task cycles on {DIAGNOSTICS_TOPIC} (key '{TASK_KEY}')")
    by_stamp: dict[int, tuple[int, dict[str, str]]] = {}
    for t, values in bag.cycles:
        by_stamp.setdefault(int(values["stamp_ns"]), (t, values))
    first = by_stamp[min(by_stamp)][1]
    # A real-time recording starts when the recorder's subscriptions are matched, which can be
    # a few states after the first cycle: cycles before the first recorded state are outside
    # the bag. From that state on, every cycle's state must be in the bag.
    covered_from = min(bag.joint_states, default=min(by_stamp))
    stamps = sorted(s for s in by_stamp if s >= covered_from)
    if not stamps:
        raise BagError(f"bag {path}: no controller task cycle at or after the first recorded {JOINT_STATES_TOPIC}")
    scenario = load_scenario(first[SCENARIO_KEY])
    model = DualArmModel(scenario.urdf_path)
    order: dict[tuple[str, ...], list[int]] = {}
    positions = np.zeros((len(stamps), model.nq))
    for k, stamp in enumerate(stamps):
        if stamp not in bag.joint_states:
            raise BagError(f"bag {path}: no {JOINT_STATES_TOPIC} with the stamp {stamp} of controller cycle {k}")
        names, q = bag.joint_states[stamp]
        idx = order.setdefault(tuple(names), [names.index(j) for j in model.joint_names])
        positions[k] = q[idx]
    cycles = [by_stamp[s] for s in stamps]
    received = np.array([t for t, _ in bag.commands], dtype=np.int64)
    nearest = np.clip(np.searchsorted(received, [t for t, _ in cycles]), 0, max(len(received) - 1, 0))
    commands = (np.array([bag.commands[i][1] for i in nearest]) if len(received)
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
    label = f"k={gain:g}" + (" force" if force else "")
    record = RunRecord(
        label=label, kind=scenario.reference.kind, period=float(first["control_period_s"]), time=column("task_time_s"),
        positions=positions, velocities=np.full(positions.shape, np.nan), commands=commands,
        status=[v["status"] for _, v in cycles], solve_time=nan_column(n), cycle_time=column("cycle_time_s"),
        position_error=nan_column(n), orientation_error=nan_column(n), final_positions=nan_column(model.nq),
        contact_force=contact, measured_force=column("measured_force_n"), normal_offset=column("normal_offset_m"),
        table_contacts=table)
    return with_task_values(record, scenario, model, gain, force), scenario


def report_tasks(path: Path, output: Path) -> dict[str, dict[str, Any]]:
    """``dualarm report`` on a task bag: ``output/metrics.json`` ({label: record}, the keys of
    ``dualarm experiment pan_cleaning``), the tool path, task values and joint velocity plots."""
    from dualarm_control.app.record.report import (
        summarize_run,
        write_figures,
        write_metrics,
    )

    log, scenario = read_task_run(path)
    results = {log.label: summarize_run(log, scenario)}
    output = Path(output)
    write_metrics(output / "metrics.json", results)
    write_figures(scenario, [log], output, Path(path).name, contact=False)
    return results
