"""``dualarm bag record``: rosbag2 recording on rclpy raw subscriptions, written with ``rosbags``.

The layout is what ``ros2 bag record -s mcap`` writes on Jazzy: ``DIR/metadata.yaml``
(version 9, ``ros_distro: jazzy``) and ``DIR/DIR_0.mcap``. Each topic gets a connection
when its first publisher is discovered, with the type, the message definition, the type
description hash and the offered QoS of its publishers, all from the graph; the CDR bytes
are stored as received (``raw=True``). Receive times come from the recorder node's clock,
so with ``use_sim_time`` a bag of a lockstep run is on the simulation clock.
Ctrl-C, SIGTERM or ``--duration`` close the bag with everything received so far.

For the viewers (Foxglove, Lichtblick, Rerun) and the report a bag also keeps ``/robot_description``
and ``/dualarm/cell`` (each node's parameters: robot, hardware profile, scenario) whenever a node
publishes them (subscribed transient local, so a recorder started later still gets them) and, unless ``--no-tf`` or a node publishes ``/tf``, the link frames computed from each
``/joint_states`` (:mod:`dualarm_control.ros.computed_tf`); ``metadata.yaml`` says so in its
``custom_data``.
"""

from __future__ import annotations

import signal
import sys
import time
from collections.abc import Callable, Sequence
from datetime import datetime
from pathlib import Path
from typing import Any, Final, TextIO

import yaml
from rosbags.interfaces import (
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosbags.rosbag2 import StoragePlugin, Writer, WriterError
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from dualarm_control.errors import DualArmError
from dualarm_control.ros.cell_topic import CELL_TOPIC
from dualarm_control.ros.computed_tf import (
    DESCRIPTION_TOPIC,
    JOINT_STATES_TOPIC,
    NOTE,
    NOTE_KEY,
    TF_STATIC_TOPIC,
    TF_TOPIC,
    ComputedTf,
)
from dualarm_control.ros.env import RECORDER_NODE
from dualarm_control.ros.graph import adapted_qos, fq_topic, message_class
from dualarm_control.ros.node import clock_ns, tool_node

BAG_VERSION: Final = 9
"""rosbag2 metadata version written by Jazzy."""
RECORD_DEPTH = 10000
"""Keep-last depth of the recording subscriptions."""
PROGRESS_INTERVAL_S = 2.0
POLL_INTERVAL_S = 0.25
READY_LINE = "bag: ready"
"""Printed on stdout once every named topic is subscribed (launchers wait for it)."""
EXCLUDED_BY_ALL = ("/rosout", "/parameter_events")


class BagError(DualArmError):
    """A bag cannot be written."""


def default_bag_path(now: datetime | None = None) -> Path:
    """``rosbag2_YYYY_MM_DD-HH_MM_SS`` in the current directory, as ``ros2 bag record`` names it."""
    return Path((now or datetime.now()).strftime("rosbag2_%Y_%m_%d-%H_%M_%S"))


def _qos_time(duration: Any) -> QosTime:
    ns = int(duration.nanoseconds)
    return QosTime(sec=ns // 1_000_000_000, nsec=ns % 1_000_000_000)


def to_bag_qos(profile: Any) -> Qos:
    """An rclpy QoSProfile (a publisher's offered QoS) as a rosbag2 metadata QoS profile."""
    return Qos(
        history=QosHistory[profile.history.name],
        depth=int(profile.depth),
        reliability=QosReliability[profile.reliability.name],
        durability=QosDurability[profile.durability.name],
        deadline=_qos_time(profile.deadline),
        lifespan=_qos_time(profile.lifespan),
        liveliness=QosLiveliness[profile.liveliness.name],
        liveliness_lease_duration=_qos_time(profile.liveliness_lease_duration),
        avoid_ros_namespace_conventions=bool(profile.avoid_ros_namespace_conventions),
    )


def type_hash_text(type_hash: Any) -> str:
    """``RIHS01_<hex>`` of an rclpy TypeHash."""
    return f"RIHS{int(type_hash.version):02d}_" + bytes(type_hash.value).hex()


def _msg_file(type_name: str) -> Path | None:
    """``share/<pkg>/msg/<Type>.msg`` of an installed message type (ament index)."""
    pkg, _, typ = type_name.split("/")
    try:
        from ament_index_python.packages import get_package_share_directory

        path = Path(get_package_share_directory(pkg)) / "msg" / f"{typ}.msg"
    except (ImportError, LookupError, ValueError):
        return None
    return path if path.is_file() else None


def typestore_with(type_name: str, store: Any) -> None:
    """Add ``type_name`` (and the types it uses) to ``store`` from the installed .msg files when
    the Jazzy store lacks it; BagError naming the type when no definition is installed."""
    pending = [type_name]
    while pending:
        name = pending.pop()
        if name in store.types:
            continue
        path = _msg_file(name)
        if path is None:
            raise BagError(f"no message definition for '{name}' (neither rosbags' Jazzy store nor an installed .msg)")
        types = get_types_from_msg(path.read_text(), name)
        store.register(types)
        for fields in types.values():
            for _, field in fields[1]:
                for part in str(field).replace("'", " ").replace(",", " ").replace("(", " ").split():
                    if part.count("/") == 2 and part not in store.types:
                        pending.append(part)


class BagWriter:
    """A rosbag2 directory (MCAP storage, version 9) receiving raw CDR messages per topic."""

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        self.counts: dict[str, int] = {}
        self._store = get_typestore(Stores.ROS2_JAZZY)
        self._connections: dict[str, Any] = {}
        try:
            self._writer = Writer(self.path, version=BAG_VERSION, storage_plugin=StoragePlugin.MCAP)
            self._writer.open()
        except WriterError as exc:
            raise BagError(str(exc)) from exc
        self._open = True

    def add_connection(self, topic: str, type_name: str, type_hash: str, offered: Sequence[Qos]) -> None:
        """Create the connection of ``topic`` (once)."""
        if topic in self._connections:
            return
        typestore_with(type_name, self._store)
        msgdef, _ = self._store.generate_msgdef(type_name, ros_version=2)
        self._connections[topic] = self._writer.add_connection(
            topic, type_name, msgdef=msgdef, rihs01=type_hash or self._store.hash_rihs01(type_name),
            serialization_format="cdr", offered_qos_profiles=list(offered))
        self.counts[topic] = 0

    def write(self, topic: str, data: bytes, stamp_ns: int) -> None:
        """Append one CDR message received at ``stamp_ns``."""
        self._writer.write(self._connections[topic], stamp_ns, data)
        self.counts[topic] += 1

    def note(self, key: str, value: str) -> None:
        """A ``custom_data`` entry of metadata.yaml."""
        self._writer.set_custom_data(key, value)

    @property
    def total(self) -> int:
        return sum(self.counts.values())

    def close(self) -> None:
        """Finish the MCAP file and write metadata.yaml as rosbag2 does (idempotent)."""
        if not self._open:
            return
        self._open = False
        self._writer.close()
        self._rosbag2_layout()

    def _rosbag2_layout(self) -> None:
        """``DIR_0.mcap`` and ``ros_distro: jazzy``, the names rosbag2 itself writes."""
        meta_file = self.path / "metadata.yaml"
        meta = yaml.safe_load(meta_file.read_text())
        info = meta["rosbag2_bagfile_information"]
        new_name = f"{self.path.name}_0.mcap"
        for i, rel in enumerate(info.get("relative_file_paths", [])):
            if rel != new_name:
                (self.path / rel).rename(self.path / new_name)
                info["relative_file_paths"][i] = new_name
                for entry in info.get("files", []):
                    if entry.get("path") == rel:
                        entry["path"] = new_name
        info["ros_distro"] = "jazzy"
        meta_file.write_text(yaml.safe_dump(meta, sort_keys=False))


ALWAYS_KEPT: Final = (DESCRIPTION_TOPIC, CELL_TOPIC, "/dualarm/obstacles")
"""Latched topics every bag keeps whenever a node publishes them: the robot's URDF, what each node
runs with (``ros/cell_topic.py``) and the scene's obstacles (``ros/obstacle_markers.py``), so that a
bag's reader knows the cell it was recorded on."""


class Recorder:
    """Subscribes topics as discovery finds them and writes every message to a :class:`BagWriter`."""

    def __init__(self, node: Any, bag: BagWriter, topics: Sequence[str], record_all: bool,
                 after_data: Sequence[str] = (), compute_tf: bool = True, log: TextIO = sys.stderr,
                 after_matched: Sequence[str] = ()) -> None:
        self.node, self.bag = node, bag
        self.log = log
        self.tf = ComputedTf(self._write_computed, self._say) if compute_tf else None
        """Writes /tf and /tf_static from /joint_states (None: ``--no-tf``)."""
        self.named = [fq_topic(t) for t in topics]
        self.later = [fq_topic(t) for t in after_data]
        """Named topics subscribed only once every other named topic has delivered a message."""
        self.last = [fq_topic(t) for t in after_matched]
        """Named topics subscribed only once every other named topic's subscription has matched every
        publisher the graph lists for it (a lockstep simulator waits for a reader on such a topic: it
        then starts with the recorder's other readers matched, not after a guessed delay)."""
        for option, given in (("--after-data", self.later), ("--after-matched", self.last)):
            unknown = [t for t in given if t not in self.named]
            if unknown:
                raise BagError(f"{option} {unknown[0]} is not one of the topics to record {self.named}")
        both = [t for t in self.later if t in self.last]
        if both:
            raise BagError(f"{both[0]} is given to both --after-data and --after-matched: choose one")
        self.record_all = record_all
        self.subscriptions: dict[str, Any] = {}

    def _say(self, text: str) -> None:
        print(text, file=self.log, flush=True)

    def _write_computed(self, topic: str, type_name: str, qos: Qos, data: bytes, stamp_ns: int) -> None:
        if topic not in self.bag.counts:
            self.bag.add_connection(topic, type_name, "", [qos])
            self.bag.note(NOTE_KEY, NOTE)
        self.bag.write(topic, data, stamp_ns)

    def _callback(self, topic: str) -> Callable[[bytes], None]:
        clock = self.node.get_clock()
        tf = self.tf

        if tf is not None and topic == JOINT_STATES_TOPIC:
            def on_joint_state(data: bytes) -> None:
                now = clock_ns(clock)
                self.bag.write(topic, data, now)
                tf.on_joint_state(data, now)

            return on_joint_state
        if tf is not None and topic == DESCRIPTION_TOPIC:
            def on_description(data: bytes) -> None:
                self.bag.write(topic, data, clock_ns(clock))
                tf.on_description(data)

            return on_description

        def on_message(data: bytes) -> None:
            self.bag.write(topic, data, clock_ns(clock))

        return on_message

    def _tf_poll(self, known: dict[str, list[str]]) -> None:
        """/robot_description, /dualarm/cell and /dualarm/obstacles (:data:`ALWAYS_KEPT`) kept whenever published; /tf
        computed only while no node publishes it."""
        for topic in ALWAYS_KEPT:
            if topic not in self.subscriptions and topic in known and self.node.count_publishers(topic):
                self._subscribe(topic, known[topic][0])
        if self.tf is not None and self.tf.enabled and self.node.count_publishers(TF_TOPIC):
            self.tf.disable("a node publishes it")

    def poll(self) -> None:
        """Subscribe the wanted topics that have a publisher now (named ones all at once; the
        ``after_data`` ones once each of the others has delivered a message: a node waiting for a
        reader on such a topic then starts with the others already flowing into the bag; the
        ``after_matched`` ones once each of the others has matched its publishers)."""
        known = dict(self.node.get_topic_names_and_types())
        self._tf_poll(known)
        first = [t for t in self.named if t not in self.later and t not in self.last]
        self._subscribe_all(known, first)
        if all(self.bag.counts.get(t, 0) for t in first):
            self._subscribe_all(known, self.later)
        if self.last and self._matched(first):
            self._subscribe_all(known, self.last)
        if self.record_all:
            for topic, types in known.items():
                if (topic not in self.subscriptions and topic not in EXCLUDED_BY_ALL
                        and not (self.tf is not None and self.tf.enabled and topic in (TF_TOPIC, TF_STATIC_TOPIC))
                        and self.node.count_publishers(topic) and not topic.startswith("/_")):
                    self._subscribe(topic, types[0])

    def _subscribe_all(self, known: dict[str, list[str]], topics: Sequence[str]) -> None:
        """Subscribe ``topics`` not subscribed yet, all at once when each has a publisher."""
        wanted = [t for t in topics if t not in self.subscriptions]
        if wanted and all(t in known and self.node.count_publishers(t) for t in wanted):
            for topic in wanted:
                self._subscribe(topic, known[topic][0])

    def _matched(self, topics: Sequence[str]) -> bool:
        """Whether each of ``topics`` is subscribed and its reader has matched every publisher the
        graph lists for it (the reader's side of discovery, ``get_publisher_count``)."""
        return all(t in self.subscriptions
                   and self.subscriptions[t].get_publisher_count() >= self.node.count_publishers(t) for t in topics)

    def publishing(self) -> bool:
        """Whether any subscribed topic still has a publisher."""
        return any(self.node.count_publishers(topic) for topic in self.subscriptions)

    @property
    def ready(self) -> bool:
        return all(t in self.subscriptions for t in self.named)

    def _subscribe(self, topic: str, type_name: str) -> None:
        infos = self.node.get_publishers_info_by_topic(topic)
        type_hash = type_hash_text(infos[0].topic_type_hash) if infos else ""
        self.bag.add_connection(topic, type_name, type_hash, [to_bag_qos(i.qos_profile) for i in infos])
        qos = adapted_qos(self.node, topic, RECORD_DEPTH)
        self.subscriptions[topic] = self.node.create_subscription(
            message_class(type_name), topic, self._callback(topic), qos, raw=True)


DRAIN_IDLE_S = 0.3
"""After a stop signal, messages are taken until none arrived for this long [s] ..."""
DRAIN_MAX_S = 5.0
"""... or, while a recorded topic still has a publisher (a live graph, Ctrl-C), for at most this long [s] ..."""
DRAIN_ENDED_MAX_S = 60.0
"""... or, once every publisher of the recorded topics has gone (``dualarm launch`` stops the recorder
after the nodes), for at most this long [s]: what is still queued then is the end of the run, and a
recorder starved on a busy machine can be seconds of processing behind (below the launcher's grace
for a recorder, ``app/run/launcher.py: RECORDER_STOP_GRACE_S``)."""


def drain(executor: Any, bag: BagWriter, publishing: Callable[[], bool] = lambda: True) -> None:
    """Take what is still queued after a stop signal: every message sent before the signal is
    kept even when the recorder lags behind a fast (lockstep) run. ``publishing()``: whether a
    recorded topic still has a publisher (checked every :data:`POLL_INTERVAL_S`)."""
    start = last = next_poll = time.monotonic()
    total = bag.total
    limit = DRAIN_MAX_S
    while (now := time.monotonic()) - last < DRAIN_IDLE_S and now - start < limit:
        if now >= next_poll:
            limit = DRAIN_MAX_S if publishing() else DRAIN_ENDED_MAX_S
            next_poll = now + POLL_INTERVAL_S
        executor.spin_once(timeout_sec=0.01)
        if bag.total != total:
            total, last = bag.total, time.monotonic()


def record(path: Path, topics: Sequence[str], *, record_all: bool = False, duration: float | None = None,
           use_sim_time: bool = False, after_data: Sequence[str] = (), compute_tf: bool = True,
           log: TextIO = sys.stderr, after_matched: Sequence[str] = ()) -> int:
    """Record into the bag directory ``path`` until SIGINT/SIGTERM or ``duration`` [s]; return 0.

    ``topics`` are recorded as soon as all of them have a publisher; ``record_all`` adds every
    topic discovery finds (but /rosout and /parameter_events); ``after_data`` topics (among
    ``topics``) are subscribed once every other named topic has delivered a message, ``after_matched``
    topics once every other named topic's reader has matched its publishers. Prints :data:`READY_LINE` on
    stdout once the named topics are subscribed, progress on stderr. ``compute_tf``: write /tf and
    /tf_static computed from /joint_states where no node publishes /tf (module docstring).
    """
    if not topics and not record_all:
        raise BagError("name the topics to record, or use -a/--all")
    from rclpy.parameter import Parameter

    bag = BagWriter(path)
    recorder: Recorder | None = None
    stopped_by = ""
    try:
        with tool_node(RECORDER_NODE) as (node, executor, stop):
            if use_sim_time:
                node.set_parameters([Parameter("use_sim_time", value=True)])
            recorder = Recorder(node, bag, topics, record_all, after_data, compute_tf, log, after_matched)
            print(f"recording to {path} ({', '.join(recorder.named) or 'all topics'})", file=log, flush=True)
            start = time.monotonic()
            next_poll = next_progress = start
            announced = False
            while stop.signal is None and (duration is None or time.monotonic() - start < duration):
                now = time.monotonic()
                if now >= next_poll:
                    recorder.poll()
                    next_poll = now + POLL_INTERVAL_S
                    if recorder.ready and not announced:
                        announced = True
                        print(READY_LINE, flush=True)
                if now >= next_progress:
                    per_topic = ", ".join(f"{t} {n}" for t, n in bag.counts.items())
                    print(f"recorded {bag.total} messages in {now - start:.1f} s ({per_topic})", file=log, flush=True)
                    next_progress = now + PROGRESS_INTERVAL_S
                executor.spin_once(timeout_sec=0.02)
            if stop.signal is not None:
                stopped_by = f" (signal {signal.Signals(stop.signal).name})"
                drain(executor, bag, recorder.publishing)
        if recorder is not None and recorder.tf is not None and recorder.tf.enabled:
            start = time.monotonic()
            count = recorder.tf.finish()
            print(f"{TF_TOPIC}: {count} messages computed from {JOINT_STATES_TOPIC} in "
                  f"{time.monotonic() - start:.2f} s", file=log, flush=True)
    finally:
        bag.close()
    print(f"bag closed{stopped_by}: {path}, {bag.total} messages", file=log, flush=True)
    return 0
