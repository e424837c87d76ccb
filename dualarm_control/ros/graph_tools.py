"""``dualarm topic list|echo|hz|info``: ros2-like graph tools over Cyclone DDS.

The tools use their own DDS participant (same domain, same loopback default as the
nodes) and never write data.

Discovery. Reading Cyclone's builtin discovery topics (``DCPSPublication``...)
crashes the Python process with cyclonedds 11.0.1 (segmentation fault in
``DataReader.read``, checked in this environment). So the graph is learned in two ways:

- *probe* (always): for each known topic, a best-effort reader and a reliable,
  transient-local writer of its type (``IgnoreLocal`` so they do not see each
  other); their matched-publication / matched-subscription counts are the
  publisher / subscription counts. Only topic names known in advance
  (:data:`GRAPH_TOPICS`, or a name given on the command line) can be found; the
  type of a name not in the table is found by probing every message class of
  :mod:`dualarm_control.ros.msgs`.
- *builtin* (``auto`` mode, in a child process): the child reads the builtin
  topics and prints what it found; if it crashes, the probe result is used alone.
  When a later cyclonedds fixes the crash, ``topic list`` sees every topic.

Probing makes the tools visible as endpoints for a moment (like ``ros2 topic echo``
is a subscription); a node that waits for N subscribers may count them.
"""

from __future__ import annotations

import dataclasses
import itertools
import json
import math
import subprocess
import sys
import time
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any, Self, TextIO

import yaml
from cyclonedds.core import (
    DDSException,
    InstanceState,
    Policy,
    Qos,
    ReadCondition,
    SampleState,
    ViewState,
    WaitSet,
)
from cyclonedds.domain import DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic

from dualarm_control.errors import DualArmError
from dualarm_control.ros import dds_env, dds_runtime, msgs, names
from dualarm_control.ros.qos import (
    DurabilityPolicy,
    QoSProfile,
    ReliabilityPolicy,
    to_cyclone_qos,
)

#: The package's graph: topic -> ROS type name (the default set of ``bag record``).
GRAPH_TOPICS: dict[str, str] = {
    "/joint_states": "sensor_msgs/msg/JointState",
    "/velocity_controller/commands": "std_msgs/msg/Float64MultiArray",
    "/relative_target": "trajectory_msgs/msg/MultiDOFJointTrajectory",
    "/relative_pose": "geometry_msgs/msg/PoseStamped",
    "/diagnostics": "diagnostic_msgs/msg/DiagnosticArray",
    "/wrench": "geometry_msgs/msg/WrenchStamped",
}

DEFAULT_SPIN_TIME = 1.0
"""s: how long ``list``/``info`` wait for discovery before answering."""
DISCOVERY_MODES = ("auto", "probe", "builtin")
_WAIT_SLICE_NS = 100_000_000  # 0.1 s: Ctrl-C is handled at least this often
_TAKE_BATCH = 64
_ANY_STATE = SampleState.Any | ViewState.Any | InstanceState.Any


class GraphToolError(DualArmError):
    """A graph tool cannot do what was asked (unknown topic type, discovery failed...)."""


# ------------------------------------------------------------------------- participant


def create_participant() -> DomainParticipant:
    """A participant on ``ROS_DOMAIN_ID`` with the package's DDS defaults (loopback)."""
    dds_env.apply_loopback_default()
    dds_env.apply_discovery_range()
    return DomainParticipant(dds_env.domain_id())


delete_entity = dds_runtime.delete_entity


def _fq_topic(topic: str) -> str:
    """``joint_states`` -> ``/joint_states`` (validated)."""
    return names.expand_topic_name(topic, "dualarm_cli", "/")


def probe_reader_qos() -> Qos:
    """Best-effort, volatile: matches every writer whatever its reliability/durability."""
    base = to_cyclone_qos(QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT))
    return base + Qos(Policy.IgnoreLocal.Participant)


def probe_writer_qos() -> Qos:
    """Reliable, transient-local: matches every reader whatever it requests (never writes)."""
    base = to_cyclone_qos(QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL))
    return base + Qos(Policy.IgnoreLocal.Participant)


# ------------------------------------------------------------------------- probing


@dataclass(frozen=True)
class TopicEndpoints:
    """What is known about one topic: ROS type name and endpoint counts."""

    name: str
    type_name: str
    publishers: int
    subscriptions: int


@dataclass
class _Probe:
    topic: str
    msg_type: type[IdlStruct]
    reader: DataReader
    writer: DataWriter | None


class GraphProbe:
    """Probe readers/writers on a participant; their matched counts describe the graph."""

    def __init__(self, participant: DomainParticipant | None = None) -> None:
        self._own = participant is None
        self.participant = participant if participant is not None else create_participant()
        self._probes: list[_Probe] = []

    def watch(self, topic: str, msg_type: type[IdlStruct], *, subscriptions: bool = True) -> None:
        """Probe ``topic`` as ``msg_type`` (publishers; with ``subscriptions``, readers too)."""
        dds_topic = Topic(self.participant, names.dds_topic_name(topic), msg_type)
        reader = DataReader(self.participant, dds_topic, qos=probe_reader_qos())
        writer = DataWriter(self.participant, dds_topic, qos=probe_writer_qos()) if subscriptions else None
        self._probes.append(_Probe(topic, msg_type, reader, writer))

    def watch_all_types(self, topic: str, *, subscriptions: bool = True) -> None:
        """Probe ``topic`` with every message class (to find the type of an unknown name)."""
        for cls in msgs.ALL_TYPES:
            self.watch(topic, cls, subscriptions=subscriptions)

    def endpoints(self) -> list[TopicEndpoints]:
        """Current counts of every probed (topic, type) that has at least one endpoint."""
        found = []
        for p in self._probes:
            pubs = int(p.reader.get_subscription_matched_status().current_count)
            subs = int(p.writer.get_publication_matched_status().current_count) if p.writer else 0
            if pubs or subs:
                found.append(TopicEndpoints(p.topic, msgs.ROS_TYPE_NAMES[p.msg_type], pubs, subs))
        return found

    def publisher_qos(self, topic: str) -> list[Qos]:
        """QoS offered by the matched publishers of ``topic`` (from the probe readers)."""
        out = []
        for p in self._probes:
            if p.topic != topic:
                continue
            for handle in p.reader.get_matched_publications():
                data = p.reader.get_matched_publication_data(handle)
                if data is not None:
                    out.append(data.qos)
        return out

    def close(self) -> None:
        """Delete the probes (and the participant if this object created it)."""
        for p in self._probes:
            delete_entity(p.writer)
            delete_entity(p.reader)
        self._probes.clear()
        if self._own:
            delete_entity(self.participant)

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def wait(seconds: float, until: Callable[[], bool] | None = None, poll: float = 0.05) -> None:
    """Sleep ``seconds`` in small slices (Ctrl-C stays responsive); stop early when ``until()``."""
    deadline = time.monotonic() + seconds
    while (left := deadline - time.monotonic()) > 0:
        if until is not None and until():
            return
        time.sleep(min(poll, left))


def resolve_type(topic: str, spin_time: float = DEFAULT_SPIN_TIME,
                 participant: DomainParticipant | None = None) -> str:
    """ROS type name of ``topic``: from :data:`GRAPH_TOPICS`, else by probing all types."""
    fq = _fq_topic(topic)
    if fq in GRAPH_TOPICS:
        return GRAPH_TOPICS[fq]
    with GraphProbe(participant) as probe:
        probe.watch_all_types(fq)
        wait(spin_time, lambda: bool(probe.endpoints()))
        types = sorted({e.type_name for e in probe.endpoints()})
    if not types:
        raise GraphToolError(
            f"could not determine the type of '{fq}': no publisher or subscription of a known "
            f"message type seen within {spin_time:g} s"
        )
    if len(types) > 1:
        raise GraphToolError(f"topic '{fq}' is used with several types: {', '.join(types)}")
    return types[0]


# ------------------------------------------------------------------------- builtin discovery


def _builtin_child_command(spin_time: float, exclude: str = "") -> list[str]:
    return [sys.executable, "-m", "dualarm_control.ros.graph_tools", "--builtin-list", str(spin_time), exclude]


def _start_builtin_child(spin_time: float, exclude: str) -> subprocess.Popen[str]:
    return subprocess.Popen(
        _builtin_child_command(spin_time, exclude), stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True
    )


def _finish_builtin_child(child: subprocess.Popen[str], timeout: float) -> list[dict[str, str]] | None:
    """The child's endpoint list, or None when it crashed, failed or hung."""
    try:
        out, _ = child.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        child.kill()
        child.communicate()
        return None
    if child.returncode != 0:
        return None
    try:
        data = json.loads(out)
    except json.JSONDecodeError:
        return None
    return data if isinstance(data, list) else None


def builtin_discovery_works(timeout: float = 10.0) -> bool:
    """Whether reading the builtin discovery topics works here (checked in a child process)."""
    child = _start_builtin_child(0.2, "")
    return _finish_builtin_child(child, timeout) is not None


def _builtin_list_main(spin_time: float, exclude: str) -> int:
    """Child process: print the ROS endpoints from the builtin topics as JSON (may crash)."""
    import resource

    from cyclonedds.builtin import (
        BuiltinTopicDcpsPublication,
        BuiltinTopicDcpsSubscription,
    )

    resource.setrlimit(resource.RLIMIT_CORE, (0, 0))  # a crash here is expected: leave no core file

    dp = create_participant()
    readers = {
        "pub": DataReader(dp, BuiltinTopicDcpsPublication),
        "sub": DataReader(dp, BuiltinTopicDcpsSubscription),
    }
    time.sleep(spin_time)
    found = []
    for kind, reader in readers.items():
        for ep in reader.read(N=100_000):
            if str(getattr(ep, "participant_key", "")) == exclude or not ep.topic_name.startswith("rt/"):
                continue
            try:
                type_name = msgs.ros_type_name_from_dds(ep.type_name)
            except ValueError:
                continue
            found.append({"kind": kind, "topic": ep.topic_name[2:], "type": type_name})
    print(json.dumps(found))
    return 0


def _merge_builtin(found: list[dict[str, str]]) -> list[TopicEndpoints]:
    counts: dict[tuple[str, str], list[int]] = {}
    for ep in found:
        c = counts.setdefault((ep["topic"], ep["type"]), [0, 0])
        c[0 if ep["kind"] == "pub" else 1] += 1
    return [TopicEndpoints(t, ty, p, s) for (t, ty), (p, s) in counts.items()]


def list_topics(spin_time: float = DEFAULT_SPIN_TIME, discovery: str = "auto",
                extra: Iterable[str] = ()) -> list[TopicEndpoints]:
    """Topics with at least one publisher or subscription, sorted by name.

    ``discovery``: ``probe`` (known names only), ``builtin`` (builtin topics in a
    child process; error if that crashes) or ``auto`` (builtin if it works, else probe).
    ``extra``: more topic names to probe (their type is probed too).
    """
    if discovery not in DISCOVERY_MODES:
        raise GraphToolError(f"discovery must be one of {', '.join(DISCOVERY_MODES)}, got {discovery!r}")
    with GraphProbe() as probe:
        child = None
        if discovery != "probe":
            child = _start_builtin_child(spin_time, str(probe.participant.guid))
        for topic, type_name in GRAPH_TOPICS.items():
            probe.watch(topic, msgs.msg_type_by_name(type_name))
        for topic in extra:
            fq = _fq_topic(topic)
            if fq not in GRAPH_TOPICS:
                probe.watch_all_types(fq)
        wait(spin_time)
        probed = probe.endpoints()
        builtin = _finish_builtin_child(child, spin_time + 10.0) if child is not None else None
    if discovery == "builtin" and builtin is None:
        raise GraphToolError("reading the builtin discovery topics failed (cyclonedds crash); use --discovery probe")
    result = {(e.name, e.type_name): e for e in probed}
    if builtin is not None:
        result.update({(e.name, e.type_name): e for e in _merge_builtin(builtin)})
    return sorted(result.values(), key=lambda e: (e.name, e.type_name))


def format_topic_list(topics: Iterable[TopicEndpoints], show_types: bool = False) -> str:
    """``ros2 topic list`` output (``-t``: ``/name [pkg/msg/Type]``)."""
    lines = [f"{e.name} [{e.type_name}]" if show_types else e.name for e in topics]
    if not show_types:
        lines = list(dict.fromkeys(lines))
    return "\n".join(lines)


def topic_info(topic: str, spin_time: float = DEFAULT_SPIN_TIME) -> TopicEndpoints:
    """Type and endpoint counts of ``topic`` (counts 0 when nothing was discovered)."""
    fq = _fq_topic(topic)
    with GraphProbe() as probe:
        type_name = resolve_type(fq, spin_time, probe.participant)
        probe.watch(fq, msgs.msg_type_by_name(type_name))
        wait(spin_time)
        found = probe.endpoints()
    if not found:
        return TopicEndpoints(fq, type_name, 0, 0)
    return found[0]


def format_topic_info(info: TopicEndpoints) -> str:
    """``ros2 topic info`` output."""
    return f"Type: {info.type_name}\nPublisher count: {info.publishers}\nSubscription count: {info.subscriptions}"


@dataclass(frozen=True)
class OfferedQos:
    """A publisher's QoS in ROS terms, as ``rmw_cyclonedds_cpp`` reports it (history unknown)."""

    reliability: str
    durability: str
    liveliness: str
    deadline_ns: int
    lifespan_ns: int
    liveliness_lease_ns: int


def offered_qos(qos: Qos) -> OfferedQos:
    """ROS view of a discovered writer's Cyclone QoS (durations in ns, int64 max = infinite)."""
    infinite = 2**63 - 1
    rel = qos[Policy.Reliability]
    dur = qos[Policy.Durability]
    live = qos[Policy.Liveliness]
    deadline = qos[Policy.Deadline]
    lifespan = qos[Policy.Lifespan]
    liveliness = {"Automatic": "automatic", "ManualByParticipant": "manual_by_node",
                  "ManualByTopic": "manual_by_topic"}.get(type(live).__name__, "automatic")
    return OfferedQos(
        reliability="best_effort" if rel == Policy.Reliability.BestEffort else "reliable",
        durability="volatile" if dur in (None, Policy.Durability.Volatile) else "transient_local",
        liveliness=liveliness,
        deadline_ns=int(getattr(deadline, "deadline", infinite)),
        lifespan_ns=int(getattr(lifespan, "lifespan", infinite)),
        liveliness_lease_ns=int(getattr(live, "lease_duration", infinite)),
    )


def subscription_offered_qos(subscription: Any) -> list[OfferedQos]:
    """Offered QoS of the publishers matched with a :mod:`dualarm_control.ros` subscription.

    Empty for backends whose subscriptions do not expose a Cyclone DataReader.
    """
    reader = getattr(subscription, "handle", None)
    if not isinstance(reader, DataReader):
        return []
    out = []
    for handle in reader.get_matched_publications():
        data = reader.get_matched_publication_data(handle)
        if data is not None:
            out.append(offered_qos(data.qos))
    return out


# ------------------------------------------------------------------------- messages -> YAML


def message_to_dict(value: Any) -> Any:
    """A message as plain Python data (dicts in field order, lists, numbers, strings).

    Works for every dataclass message: the IdlStruct classes of
    :mod:`dualarm_control.ros.msgs` and the ``rosbags`` message classes (whose
    ``__msgtype__`` field is left out).
    """
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: message_to_dict(getattr(value, f.name))
                for f in dataclasses.fields(value) if not f.name.startswith("__")}
    if isinstance(value, (bytes, bytearray)):
        return list(value)
    if isinstance(value, (list, tuple)):
        return [message_to_dict(v) for v in value]
    if hasattr(value, "tolist"):  # numpy arrays and scalars
        return value.tolist()
    return value


def message_to_yaml(msg: Any) -> str:
    """The message as ``ros2 topic echo`` prints it (block style, arrays as lists)."""
    return yaml.safe_dump(
        message_to_dict(msg), default_flow_style=False, sort_keys=False, allow_unicode=True, width=sys.maxsize
    )


# ------------------------------------------------------------------------- subscribing


def adapted_profile(offered: Iterable[Qos]) -> QoSProfile:
    """QoS compatible with all ``offered`` publisher QoS, as ``ros2 topic echo`` adapts it.

    Reliable only if every publisher is reliable; transient-local only if every
    publisher is; rclpy's default (reliable, volatile) when there is none.
    """
    offered = list(offered)
    if not offered:
        return QoSProfile(depth=10)
    reliable = all(q[Policy.Reliability] != Policy.Reliability.BestEffort for q in offered)
    tl = all(q[Policy.Durability] in (Policy.Durability.TransientLocal, Policy.Durability.Transient,
                                      Policy.Durability.Persistent) for q in offered)
    return QoSProfile(
        depth=10,
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if tl else DurabilityPolicy.VOLATILE,
    )


class TopicReader:
    """A reader of one topic with a QoS adapted to its publishers; yields samples as they come."""

    def __init__(self, topic: str, *, raw: bool = False, spin_time: float = DEFAULT_SPIN_TIME) -> None:
        self.topic = _fq_topic(topic)
        self.raw = raw
        self.participant = create_participant()
        try:
            self.type_name = resolve_type(self.topic, spin_time, self.participant)
            self.msg_type = msgs.msg_type_by_name(self.type_name)
            with GraphProbe(self.participant) as probe:
                probe.watch(self.topic, self.msg_type, subscriptions=False)
                wait(spin_time, lambda: bool(probe.endpoints()))
                wait(0.1)  # let the other publishers of the topic be discovered too
                self.profile = adapted_profile(probe.publisher_qos(self.topic))
            dds_topic = Topic(self.participant, names.dds_topic_name(self.topic), self.msg_type)
            self.reader = DataReader(self.participant, dds_topic, qos=to_cyclone_qos(self.profile))
            self._condition = ReadCondition(self.reader, _ANY_STATE)
            self._waitset = WaitSet(self.participant)
            self._waitset.attach(self._condition)
        except BaseException:
            delete_entity(self.participant)
            raise

    def take(self) -> list[Any]:
        """Samples available now: messages, or CDR bytes when ``raw``."""
        out: list[Any] = []
        while True:
            if self.raw:
                from cyclonedds._clayer import ddspy_take

                got = ddspy_take(self.reader._ref, _ANY_STATE, _TAKE_BATCH)
                if isinstance(got, int):
                    raise DDSException(got, f"take on '{self.topic}'")
                out.extend(bytes(data) for data, info in got if info.valid_data)
            else:
                got = self.reader.take(N=_TAKE_BATCH)
                out.extend(s for s in got if isinstance(s, self.msg_type))
            if len(got) < _TAKE_BATCH:
                return out

    def wait(self, timeout_s: float) -> None:
        """Block until data may be available, at most ``timeout_s`` (in 0.1 s slices)."""
        self._waitset.wait(max(0, min(int(timeout_s * 1e9), _WAIT_SLICE_NS)))

    def close(self) -> None:
        """Delete the participant and everything in it."""
        if self._waitset is not None:
            self._waitset.attached = []
        delete_entity(self.participant)

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


@contextmanager
def _stdout_closed_ok() -> Iterator[None]:
    """Stop quietly when the output pipe closes (``dualarm topic echo X | head``)."""
    try:
        yield
    except BrokenPipeError:
        pass


def echo(topic: str, *, count: int | None = None, timeout: float | None = None,
         spin_time: float = DEFAULT_SPIN_TIME, out: TextIO = sys.stdout) -> int:
    """Print messages of ``topic`` as YAML documents separated by ``---`` (``ros2 topic echo``).

    Stops after ``count`` messages (None: until Ctrl-C) or, if ``timeout`` is set, when
    no message came for that long. Returns 0, or 1 on a timeout before ``count`` messages.
    """
    printed = 0
    with TopicReader(topic, spin_time=spin_time) as reader, _stdout_closed_ok():
        last = time.monotonic()
        while count is None or printed < count:
            for msg in reader.take():
                out.write(message_to_yaml(msg) + "---\n")
                out.flush()
                printed += 1
                last = time.monotonic()
                if count is not None and printed >= count:
                    return 0
            if timeout is not None and time.monotonic() - last > timeout:
                print(f"no message on '{reader.topic}' for {timeout:g} s", file=sys.stderr)
                return 1
            reader.wait(0.1 if timeout is None else max(timeout - (time.monotonic() - last), 0.0))
    return 0


# ------------------------------------------------------------------------- hz


@dataclass(frozen=True)
class RateStats:
    """Message rate over a window: ``rate`` [Hz] and period statistics [s]."""

    rate: float
    min_delta: float
    max_delta: float
    std_dev: float
    window: int


class RateMeter:
    """Arrival times in a sliding window; statistics as ``ros2 topic hz`` computes them."""

    def __init__(self, window: int = 10_000) -> None:
        if window < 2:
            raise GraphToolError(f"--window must be >= 2, got {window}")
        self._times: deque[float] = deque(maxlen=window)
        self.received = 0

    def add(self, t: float) -> None:
        """Record one arrival at time ``t`` [s]."""
        self._times.append(t)
        self.received += 1

    def stats(self) -> RateStats | None:
        """Rate from the mean period in the window (None before two messages)."""
        if len(self._times) < 2:
            return None
        times = list(self._times)
        deltas = [b - a for a, b in itertools.pairwise(times)]
        mean = sum(deltas) / len(deltas)
        std = math.sqrt(sum((d - mean) ** 2 for d in deltas) / len(deltas))
        return RateStats(1.0 / mean if mean > 0 else 0.0, min(deltas), max(deltas), std, len(times))


def format_rate(stats: RateStats) -> str:
    """``ros2 topic hz`` output for one report."""
    return (
        f"average rate: {stats.rate:.3f}\n\tmin: {stats.min_delta:.3f}s max: {stats.max_delta:.3f}s "
        f"std dev: {stats.std_dev:.5f}s window: {stats.window}"
    )


def hz(topic: str, *, window: int = 10_000, duration: float | None = None,
       spin_time: float = DEFAULT_SPIN_TIME, out: TextIO = sys.stdout) -> int:
    """Print the receive rate of ``topic`` every second until Ctrl-C or ``duration`` [s].

    Returns 0, or 1 if ``duration`` elapsed without two messages.
    """
    meter = RateMeter(window)
    with TopicReader(topic, raw=True, spin_time=spin_time) as reader, _stdout_closed_ok():
        end = None if duration is None else time.monotonic() + duration
        next_report = time.monotonic() + 1.0
        reported_at = 0
        while end is None or time.monotonic() < end:
            for _ in reader.take():
                meter.add(time.monotonic())
            now = time.monotonic()
            if now >= next_report:
                next_report += 1.0
                reported_at = _report_rate(meter, reported_at, out)
            deadline = min(next_report, end) if end is not None else next_report
            reader.wait(max(deadline - now, 0.0))
        if reported_at != meter.received:
            _report_rate(meter, reported_at, out)
    return 0 if meter.stats() is not None else 1


def _report_rate(meter: RateMeter, reported_at: int, out: TextIO) -> int:
    """Print the stats (or ``no new messages``); returns the message count reported."""
    stats = meter.stats()
    if stats is None or meter.received == reported_at:
        out.write("no new messages\n")
    else:
        out.write(format_rate(stats) + "\n")
    out.flush()
    return meter.received


if __name__ == "__main__":  # the builtin-discovery child of list_topics()
    if len(sys.argv) == 4 and sys.argv[1] == "--builtin-list":
        sys.exit(_builtin_list_main(float(sys.argv[2]), sys.argv[3]))
    print("usage: python -m dualarm_control.ros.graph_tools --builtin-list SPIN_TIME EXCLUDE_GUID", file=sys.stderr)
    sys.exit(2)
