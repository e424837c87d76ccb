"""``dualarm topic list|echo|hz|info`` on rclpy's graph API, for any installed message type.

Output follows ``ros2 topic``: ``list`` prints fully qualified names (``-t`` adds types),
``echo`` prints YAML documents separated by ``---``, ``hz`` prints ``average rate`` blocks
once a second, ``info`` prints the type and endpoint counts.
"""

from __future__ import annotations

import dataclasses
import importlib
import itertools
import math
import sys
import time
from collections import deque
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any, TextIO

import yaml

from dualarm_control.errors import DualArmError
from dualarm_control.ros.node import DISCOVERY_TIMEOUT_S, tool_node

DEFAULT_SPIN_TIME = 3.0
"""Seconds ``list`` collects what discovery finds before answering (``ros2 topic --spin-time``).
The verbs that look for one topic (echo, hz, info) wait up to
:data:`~dualarm_control.ros.node.DISCOVERY_TIMEOUT_S` instead and answer as soon as it is found."""


class GraphToolError(DualArmError):
    """A topic is unknown, has no type, or its type is not installed."""


def fq_topic(topic: str) -> str:
    """``/name`` for ``name``."""
    return topic if topic.startswith("/") else "/" + topic


def message_class(type_name: str) -> type:
    """The installed message class of ``pkg/msg/Type`` (GraphToolError naming it if absent)."""
    parts = type_name.split("/")
    if len(parts) != 3 or parts[1] != "msg":
        raise GraphToolError(f"'{type_name}' is not a message type name (pkg/msg/Type)")
    try:
        cls: type = getattr(importlib.import_module(f"{parts[0]}.msg"), parts[2])
    except (ImportError, AttributeError):
        raise GraphToolError(f"message type '{type_name}' is not installed") from None
    return cls


# ------------------------------------------------------------------------- discovery


@dataclass(frozen=True)
class TopicEndpoints:
    """A topic seen in the graph: name, type names, publisher and subscription counts."""

    name: str
    types: tuple[str, ...]
    publishers: int
    subscriptions: int


def spin_for(executor: Any, seconds: float, stop: Any) -> None:
    """Process callbacks (and discovery) for ``seconds`` or until a signal."""
    end = time.monotonic() + seconds
    while stop.signal is None and time.monotonic() < end:
        executor.spin_once(timeout_sec=min(0.05, max(end - time.monotonic(), 0.0)))


def graph_topics(node: Any, include_hidden: bool = False) -> list[TopicEndpoints]:
    """The topics the node's graph knows now, sorted by name."""
    return [
        TopicEndpoints(name, tuple(types), node.count_publishers(name), node.count_subscribers(name))
        for name, types in sorted(node.get_topic_names_and_types(), key=lambda x: x[0])
        if include_hidden or not any(part.startswith("_") for part in name.split("/"))
    ]


def list_topics(spin_time: float = DEFAULT_SPIN_TIME) -> list[TopicEndpoints]:
    """``ros2 topic list``: every topic discovery finds within ``spin_time``."""
    with tool_node("_dualarm_topic_list") as (node, executor, stop):
        spin_for(executor, spin_time, stop)
        return [t for t in graph_topics(node) if t.name not in ("/rosout", "/parameter_events")
                or t.publishers + t.subscriptions > 1]


def format_topic_list(topics: Iterable[TopicEndpoints], show_types: bool = False) -> str:
    return "\n".join(f"{t.name} [{', '.join(t.types)}]" if show_types else t.name for t in topics)


def topic_info(topic: str, spin_time: float = DISCOVERY_TIMEOUT_S) -> TopicEndpoints:
    """Type and endpoint counts of ``topic`` (zero counts when nobody uses it)."""
    name = fq_topic(topic)
    with tool_node("_dualarm_topic_info") as (node, executor, stop):
        end = time.monotonic() + spin_time
        while True:
            types = dict(node.get_topic_names_and_types()).get(name, [])
            if (types and node.count_publishers(name) + node.count_subscribers(name)) or time.monotonic() > end:
                spin_for(executor, 0.2, stop)  # the topic's other endpoints, discovered with it
                types = dict(node.get_topic_names_and_types()).get(name, [])
                return TopicEndpoints(name, tuple(types), node.count_publishers(name), node.count_subscribers(name))
            spin_for(executor, 0.05, stop)


def format_topic_info(info: TopicEndpoints) -> str:
    return (f"Type: {', '.join(info.types)}\nPublisher count: {info.publishers}\n"
            f"Subscription count: {info.subscriptions}")


def wait_for_type(node: Any, executor: Any, stop: Any, topic: str, spin_time: float) -> str:
    """The type of ``topic`` once discovery shows a publisher (GraphToolError after ``spin_time``)."""
    end = time.monotonic() + spin_time
    while stop.signal is None:
        types = dict(node.get_topic_names_and_types()).get(topic, [])
        if types and node.count_publishers(topic) > 0:
            return str(types[0])
        if time.monotonic() > end:
            break
        executor.spin_once(timeout_sec=0.05)
    raise GraphToolError(f"no publisher of '{topic}' found within {spin_time:g} s (try a longer --spin-time)")


def adapted_qos(node: Any, topic: str, depth: int = 10) -> Any:
    """A QoS compatible with every publisher of ``topic``, as ``ros2 topic echo`` adapts it:
    reliable only if all publishers are, transient-local only if all are."""
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    offered = [info.qos_profile for info in node.get_publishers_info_by_topic(topic)]
    reliable = all(q.reliability == ReliabilityPolicy.RELIABLE for q in offered)
    transient = bool(offered) and all(q.durability == DurabilityPolicy.TRANSIENT_LOCAL for q in offered)
    return QoSProfile(depth=depth,
                      reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL if transient else DurabilityPolicy.VOLATILE)


# ------------------------------------------------------------------------- messages -> YAML


def message_to_dict(value: Any) -> Any:
    """A message as plain data in field order: rclpy messages and ``rosbags`` dataclasses alike."""
    fields = getattr(value, "get_fields_and_field_types", None)
    if fields is not None and not isinstance(value, type):
        return {name: message_to_dict(getattr(value, name)) for name in fields()}
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: message_to_dict(getattr(value, f.name))
                for f in dataclasses.fields(value) if not f.name.startswith("__")}
    if isinstance(value, (bytes, bytearray)):
        return value[0] if len(value) == 1 else list(value)
    if isinstance(value, (list, tuple)):
        return [message_to_dict(v) for v in value]
    if hasattr(value, "tolist"):  # numpy and array.array
        return value.tolist()
    return value


def message_to_yaml(msg: Any) -> str:
    """The message as ``ros2 topic echo`` prints it (block style, arrays as lists)."""
    return yaml.safe_dump(message_to_dict(msg), default_flow_style=False, sort_keys=False,
                          allow_unicode=True, width=sys.maxsize)


@contextmanager
def _stdout_closed_ok() -> Iterator[None]:
    """Stop quietly when the output pipe closes (``dualarm topic echo X | head``)."""
    try:
        yield
    except BrokenPipeError:
        pass


def echo(topic: str, *, count: int | None = None, timeout: float | None = None,
         spin_time: float = DISCOVERY_TIMEOUT_S, out: TextIO = sys.stdout) -> int:
    """Print messages of ``topic`` as YAML documents separated by ``---`` (``ros2 topic echo``).

    Stops after ``count`` messages (None: until Ctrl-C) or, with ``timeout``, when no message
    came for that long. Returns 0, or 1 on such a timeout.
    """
    name = fq_topic(topic)
    received: deque[Any] = deque()
    with tool_node("_dualarm_topic_echo") as (node, executor, stop), _stdout_closed_ok():
        cls = message_class(wait_for_type(node, executor, stop, name, spin_time))
        node.create_subscription(cls, name, lambda msg: received.append(msg), adapted_qos(node, name))
        printed, last = 0, time.monotonic()
        while stop.signal is None and (count is None or printed < count):
            executor.spin_once(timeout_sec=0.1)
            while received and (count is None or printed < count):
                out.write(message_to_yaml(received.popleft()) + "---\n")
                out.flush()
                printed, last = printed + 1, time.monotonic()
            if timeout is not None and time.monotonic() - last > timeout:
                print(f"no message on '{name}' for {timeout:g} s", file=sys.stderr)
                return 1
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
        deltas = [b - a for a, b in itertools.pairwise(self._times)]
        mean = sum(deltas) / len(deltas)
        std = math.sqrt(sum((d - mean) ** 2 for d in deltas) / len(deltas))
        return RateStats(1.0 / mean if mean > 0 else 0.0, min(deltas), max(deltas), std, len(self._times))


def format_rate(stats: RateStats) -> str:
    """``ros2 topic hz`` output for one report."""
    return (f"average rate: {stats.rate:.3f}\n\tmin: {stats.min_delta:.3f}s max: {stats.max_delta:.3f}s "
            f"std dev: {stats.std_dev:.5f}s window: {stats.window}")


def hz(topic: str, *, window: int = 10_000, duration: float | None = None,
       spin_time: float = DISCOVERY_TIMEOUT_S, out: TextIO = sys.stdout) -> int:
    """Print the receive rate of ``topic`` every second until Ctrl-C or ``duration`` [s].

    Subscribes raw (no deserialisation). Returns 0, or 1 if fewer than two messages came.
    """
    name = fq_topic(topic)
    meter = RateMeter(window)
    with tool_node("_dualarm_topic_hz") as (node, executor, stop), _stdout_closed_ok():
        cls = message_class(wait_for_type(node, executor, stop, name, spin_time))
        node.create_subscription(cls, name, lambda _: meter.add(time.monotonic()), adapted_qos(node, name), raw=True)
        end = None if duration is None else time.monotonic() + duration
        next_report, reported_at = time.monotonic() + 1.0, 0
        while stop.signal is None and (end is None or time.monotonic() < end):
            executor.spin_once(timeout_sec=0.05)
            if time.monotonic() >= next_report:
                next_report += 1.0
                reported_at = _report_rate(meter, reported_at, out)
        if reported_at != meter.received:
            _report_rate(meter, reported_at, out)
    return 0 if meter.stats() is not None else 1


def _report_rate(meter: RateMeter, reported_at: int, out: TextIO) -> int:
    stats = meter.stats()
    out.write("no new messages\n" if stats is None or meter.received == reported_at else format_rate(stats) + "\n")
    out.flush()
    return meter.received
