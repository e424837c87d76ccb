"""The Cyclone DDS backend: an rclpy-like Node, timers and a single-threaded executor.

One process context = one DDS DomainParticipant (domain ``ROS_DOMAIN_ID``, USER_DATA
``enclave=/;``) shared by all nodes, as rmw_cyclonedds_cpp does since Galactic.
Topics are ``rt/<fully qualified name>`` with the ``pkg::msg::dds_::Type_`` type
names of :mod:`dualarm_control.ros.msgs`; the graph goes on ``ros_discovery_info``.

Executor: callbacks run on the thread calling ``spin``/``spin_once``, one at a
time: due timers first, then the received samples of each subscription in
arrival order. The wait uses a DDS WaitSet (subscription read conditions + a
guard condition) with a timeout up to the next timer deadline, in slices of at
most 0.1 s so Python signal handlers run promptly.

Signals: Ctrl-C raises ``KeyboardInterrupt`` out of ``spin`` (Python's default
SIGINT handler, as with rclpy). SIGTERM (installed by :func:`init` when called in
the main thread) marks the context as externally shut down: ``ok()`` turns False and
``spin``/``spin_once`` raise :class:`ExternalShutdownException` at their next
iteration, so a node's ``except (KeyboardInterrupt, ExternalShutdownException)``
path can close files. Call ``try_shutdown()`` afterwards.
"""

from __future__ import annotations

import dataclasses
import signal
import sys
import threading
import time
from collections import deque
from collections.abc import Callable
from types import FrameType
from typing import Any

from cyclonedds._clayer import ddspy_take
from cyclonedds.core import (
    DDSException,
    Entity,
    GuardCondition,
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
from cyclonedds.internal import InvalidSample
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic

from dualarm_control.ros import dds_env, log, names
from dualarm_control.ros.args import RosArgs, parse_ros_args
from dualarm_control.ros.clock import Clock
from dualarm_control.ros.discovery import GraphPublisher, NodeEntities
from dualarm_control.ros.msgs import dds_type_name
from dualarm_control.ros.parameters import Parameter, ParameterStore, declare_many
from dualarm_control.ros.qos import QoSProfile, as_profile, to_cyclone_qos

_WAIT_SLICE_NS = 100_000_000  # longest single DDS wait, so signals are handled within 0.1 s
_TAKE_BATCH = 64


class ExternalShutdownException(Exception):
    """The context was shut down from outside the spinning code (SIGTERM), as in rclpy."""


class NotInitializedError(RuntimeError):
    """A node or executor was used before ``init()`` or after ``shutdown()``."""


def delete_entity(entity: Entity | None) -> None:
    """Delete a DDS entity now instead of at garbage collection (errors ignored)."""
    if entity is None:
        return
    try:
        Entity.__del__(entity)
    except DDSException:
        pass


# ------------------------------------------------------------------------- context


class Context:
    """The process-wide DDS participant, the parsed ROS arguments and the node list."""

    def __init__(self, args: RosArgs, domain_id: int) -> None:
        self.args = args
        self.domain_id = domain_id
        self.participant = DomainParticipant(domain_id, qos=Qos(Policy.Userdata(b"enclave=/;")))
        self.guard = GuardCondition(self.participant)
        self.graph = GraphPublisher(self.participant)
        self.nodes: list[Node] = []
        self.generation = 0  # bumped when readers come or go, so executors rebuild their WaitSet
        self.external_shutdown = False
        self._shut = False
        self._topics: dict[str, Topic] = {}
        self.executor: SingleThreadedExecutor | None = None
        self._previous_sigterm: Any = None
        self._lock = threading.RLock()

    def ok(self) -> bool:
        """Neither ``shutdown()`` nor SIGTERM happened."""
        return not self._shut and not self.external_shutdown

    @property
    def is_shut_down(self) -> bool:
        """``shutdown()`` completed (DDS entities deleted)."""
        return self._shut

    def topic(self, fq_name: str, msg_type: type) -> Topic:
        """The DDS topic for ``fq_name`` (one per name; a second type is an error)."""
        dds_name = names.dds_topic_name(fq_name)
        with self._lock:
            topic = self._topics.get(dds_name)
            if topic is None:
                topic = Topic(self.participant, dds_name, msg_type)
                self._topics[dds_name] = topic
            elif topic.data_type is not msg_type:
                raise TypeError(
                    f"topic '{fq_name}' is already used in this process with type "
                    f"{dds_type_name(topic.data_type)}, not {dds_type_name(msg_type)}"
                )
            return topic

    def graph_changed(self, readers_changed: bool) -> None:
        """Republish ``ros_discovery_info`` and wake executors."""
        if self._shut:
            return
        with self._lock:
            self.graph.publish([n._entities for n in self.nodes])
            if readers_changed:
                self.generation += 1
        self.wake()

    def wake(self) -> None:
        """Wake any executor blocked in a DDS wait."""
        if not self._shut:
            self.guard.set(True)

    def on_sigterm(self, signum: int, frame: FrameType | None) -> None:
        """SIGTERM: request a clean shutdown of the spinning code."""
        self.external_shutdown = True
        self.wake()

    def install_signal_handlers(self) -> None:
        """SIGTERM -> external shutdown (only possible from the main thread)."""
        if threading.current_thread() is threading.main_thread():
            self._previous_sigterm = signal.signal(signal.SIGTERM, self.on_sigterm)

    def shutdown(self) -> None:
        """Destroy all nodes and delete the participant."""
        if self._shut:
            return
        for node in list(self.nodes):
            node.destroy_node()
        self._shut = True
        if self._previous_sigterm is not None and threading.current_thread() is threading.main_thread():
            signal.signal(signal.SIGTERM, self._previous_sigterm)
            self._previous_sigterm = None
        if self.executor is not None:
            self.executor._drop_waitset()
        self._topics.clear()
        delete_entity(self.participant)


_context: Context | None = None


def init(args: list[str] | None = None, *, domain_id: int | None = None) -> None:
    """Start the middleware: parse ``--ros-args`` (``sys.argv`` when ``args`` is None)."""
    global _context
    if _context is not None and not _context.is_shut_down:
        raise RuntimeError("ros.init() was already called; call ros.shutdown() first")
    parsed = parse_ros_args(sys.argv if args is None else list(args))
    log.set_levels(parsed.log_levels)
    dds_env.apply_loopback_default()
    dds_env.apply_discovery_range()
    ctx = Context(parsed, dds_env.domain_id() if domain_id is None else domain_id)
    ctx.install_signal_handlers()
    _context = ctx


def get_context() -> Context:
    """The current context (raises if ``init()`` was not called)."""
    if _context is None or _context.is_shut_down:
        raise NotInitializedError("call ros.init() before creating nodes or spinning")
    return _context


def ok() -> bool:
    """True between ``init()`` and ``shutdown()`` and until SIGTERM."""
    return _context is not None and _context.ok()


def shutdown() -> None:
    """Destroy all nodes and the DDS participant; raises if not initialized (like rclpy)."""
    global _context
    if _context is None or _context.is_shut_down:
        raise RuntimeError("ros.shutdown(): not initialized or already shut down")
    ctx, _context = _context, None
    ctx.shutdown()


def try_shutdown() -> None:
    """``shutdown()`` if still initialized; never raises for an already shut down context."""
    if _context is not None and not _context.is_shut_down:
        shutdown()


def remove_ros_args(argv: list[str] | None = None) -> list[str]:
    """``argv`` (default ``sys.argv``) without ``--ros-args`` sections."""
    from dualarm_control.ros.args import remove_ros_args as _remove

    return _remove(sys.argv if argv is None else argv)


# ------------------------------------------------------------------------- endpoints


def _plain(value: Any) -> Any:
    """Copy a message replacing numpy arrays/scalars and tuples by Python lists/numbers."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return dataclasses.replace(value, **{f.name: _plain(getattr(value, f.name)) for f in dataclasses.fields(value)})
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if hasattr(value, "tolist") and not isinstance(value, (str, bytes)):
        return value.tolist()
    return value


class Publisher:
    """``node.create_publisher`` result: ``publish(msg)``, ``topic_name``, ``get_subscription_count()``."""

    def __init__(self, node: Node, msg_type: type, topic_name: str, qos: QoSProfile) -> None:
        self.msg_type = msg_type
        self.topic_name = topic_name
        self.qos_profile = qos
        self._node = node
        self._writer: DataWriter | None = DataWriter(
            node.context.participant, node.context.topic(topic_name, msg_type), qos=to_cyclone_qos(qos)
        )

    @property
    def handle(self) -> DataWriter:
        """The Cyclone DataWriter."""
        if self._writer is None:
            raise RuntimeError(f"publisher on '{self.topic_name}' was destroyed")
        return self._writer

    def publish(self, msg: Any) -> None:
        """Send ``msg`` (numpy arrays in sequence fields are accepted)."""
        if not isinstance(msg, self.msg_type):
            raise TypeError(
                f"publisher on '{self.topic_name}' sends {self.msg_type.__name__}, got {type(msg).__name__}"
            )
        writer = self.handle
        try:
            writer.write(msg)
        except DDSException:
            raise
        except Exception:  # noqa: BLE001 - serializer refused a field: retry with plain Python values
            try:
                writer.write(_plain(msg))
            except Exception as exc:
                raise TypeError(f"cannot serialize {type(msg).__name__} for '{self.topic_name}': {exc}") from exc

    def get_subscription_count(self) -> int:
        """Matched subscriptions (QoS-compatible readers anywhere, this process included)."""
        return int(self.handle.get_publication_matched_status().current_count)

    def destroy(self) -> None:
        """Delete the DataWriter."""
        self._node.destroy_publisher(self)


class Subscription:
    """``node.create_subscription`` result (``topic_name``, ``destroy()``)."""

    def __init__(self, node: Node, msg_type: type, topic_name: str, callback: Callable[[Any], Any],
                 qos: QoSProfile, raw: bool = False) -> None:
        self.msg_type = msg_type
        self.topic_name = topic_name
        self.callback = callback
        self.qos_profile = qos
        self.raw = raw
        self._node = node
        self._reader: DataReader | None = DataReader(
            node.context.participant, node.context.topic(topic_name, msg_type), qos=to_cyclone_qos(qos)
        )
        mask = SampleState.Any | ViewState.Any | InstanceState.Any
        self.condition: ReadCondition | None = ReadCondition(self._reader, mask)

    @property
    def handle(self) -> DataReader:
        """The Cyclone DataReader."""
        if self._reader is None:
            raise RuntimeError(f"subscription on '{self.topic_name}' was destroyed")
        return self._reader

    def get_publisher_count(self) -> int:
        """Matched publications."""
        return int(self.handle.get_subscription_matched_status().current_count)

    def take(self) -> list[Any]:
        """All samples available now (messages, or CDR ``bytes`` when ``raw``)."""
        reader = self._reader
        if reader is None:
            return []
        out: list[Any] = []
        while True:
            if self.raw:
                got = ddspy_take(reader._ref, SampleState.Any | ViewState.Any | InstanceState.Any, _TAKE_BATCH)
                if isinstance(got, int):
                    raise DDSException(got, f"take on '{self.topic_name}'")
                out.extend(bytes(data) for data, info in got if info.valid_data)
            else:
                got = reader.take(N=_TAKE_BATCH)
                out.extend(s for s in got if not isinstance(s, InvalidSample))
            if len(got) < _TAKE_BATCH:
                return out

    def destroy(self) -> None:
        """Delete the DataReader."""
        self._node.destroy_subscription(self)


class Timer:
    """A periodic timer on the monotonic clock, phase-locked like rcl's.

    The first call is one period after creation; each next deadline is the previous
    deadline plus the period (no drift). If the executor falls behind by more than
    a period, the missed calls are skipped and the timer stays on its grid, as in
    rcl (``missed_calls`` counts them).
    """

    def __init__(self, node: Node, period_s: float, callback: Callable[[], Any]) -> None:
        if period_s <= 0:
            raise ValueError(f"timer period must be > 0 s, got {period_s}")
        self.timer_period_ns = round(period_s * 1e9)
        self.callback = callback
        self.missed_calls = 0
        self._node = node
        self._canceled = False
        self._next_ns = time.monotonic_ns() + self.timer_period_ns
        self._last_ns: int | None = None

    def cancel(self) -> None:
        """Stop calling the callback until ``reset()``."""
        self._canceled = True

    def is_canceled(self) -> bool:
        """Whether ``cancel()`` was called."""
        return self._canceled

    def reset(self) -> None:
        """Restart: next call one period from now."""
        self._canceled = False
        self._next_ns = time.monotonic_ns() + self.timer_period_ns
        self._node.context.wake()

    def time_until_next_call(self) -> int | None:
        """Nanoseconds to the next deadline (None when canceled)."""
        return None if self._canceled else self._next_ns - time.monotonic_ns()

    def is_ready(self) -> bool:
        """Whether the deadline has passed."""
        return not self._canceled and time.monotonic_ns() >= self._next_ns

    @property
    def next_deadline_ns(self) -> int:
        """Monotonic time (ns) of the next call."""
        return self._next_ns

    @property
    def last_deadline_ns(self) -> int | None:
        """Monotonic deadline (ns) of the call being run or last run (None before the first)."""
        return self._last_ns

    def _advance(self, now_ns: int) -> None:
        self._last_ns = self._next_ns
        self._next_ns += self.timer_period_ns
        if self._next_ns <= now_ns:
            behind = now_ns - self._next_ns
            skipped = 1 + behind // self.timer_period_ns
            self.missed_calls += skipped
            self._next_ns += skipped * self.timer_period_ns

    def destroy(self) -> None:
        """Remove the timer from its node."""
        self._node.destroy_timer(self)


# ------------------------------------------------------------------------- node


class Node:
    """An rclpy-like node. ``-r __node:=`` / ``-r __ns:=`` rename it; ``-r a:=b`` remap topics."""

    def __init__(self, node_name: str, *, namespace: str | None = None, context: Context | None = None) -> None:
        ctx = context or get_context()
        self.context = ctx
        original = names.validate_node_name(node_name)
        self._name = names.validate_node_name(ctx.args.node_name_override(original) or original)
        self._namespace = names.normalize_namespace(ctx.args.namespace_override(original) or namespace)
        self._remaps = [(r.src, r.dst) for r in ctx.args.topic_remaps(original)]
        fq_name = self.get_fully_qualified_name()
        self._params = ParameterStore(
            self._name, ctx.args.parameter_overrides(fq_name), ctx.args.parameter_sources(fq_name)
        )
        logger_name = ".".join([*self._namespace.strip("/").split("/"), self._name]).strip(".")
        self._logger = log.Logger(logger_name)
        self._clock = Clock()
        self.publishers: list[Publisher] = []
        self.subscriptions: list[Subscription] = []
        self.timers: list[Timer] = []
        self._entities = NodeEntities(self._namespace, self._name)
        self._destroyed = False
        if self.declare_parameter("use_sim_time", False).value:
            self._logger.warning("use_sim_time is not supported by the Cyclone DDS backend; using system time")
        with ctx._lock:
            ctx.nodes.append(self)
        ctx.graph_changed(readers_changed=False)

    # names, logger, clock
    def get_name(self) -> str:
        """Node name (after ``__node`` remapping)."""
        return self._name

    def get_namespace(self) -> str:
        """Node namespace, ``/`` by default."""
        return self._namespace

    def get_fully_qualified_name(self) -> str:
        """``/ns/name``."""
        return names.fully_qualified_node_name(self._namespace, self._name)

    def get_logger(self) -> log.Logger:
        """The node's logger (name ``ns.node``)."""
        return self._logger

    def get_clock(self) -> Clock:
        """System-time clock; ``now()`` gives a Time with ``nanoseconds`` and ``to_msg()``."""
        return self._clock

    def resolve_topic_name(self, topic: str) -> str:
        """Fully qualified topic name after namespace expansion and remapping."""
        return names.remap_topic_name(topic, self._name, self._namespace, self._remaps)

    # parameters
    def declare_parameter(self, name: str, value: Any = None, description: str = "",
                          ignore_override: bool = False) -> Parameter:
        """Declare a parameter; its default's type is enforced on overrides."""
        return self._params.declare(name, value, description, ignore_override)

    def declare_parameters(self, namespace: str, parameters: list[Any]) -> list[Parameter]:
        """Declare ``[(name, value[, description]), ...]`` under ``namespace.``."""
        return declare_many(self._params, namespace, parameters)

    def get_parameter(self, name: str) -> Parameter:
        """A declared parameter (``.value``)."""
        return self._params.get(name)

    def get_parameters(self, names_: list[str]) -> list[Parameter]:
        """Several declared parameters."""
        return [self._params.get(n) for n in names_]

    def has_parameter(self, name: str) -> bool:
        """Whether ``name`` is declared."""
        return self._params.has(name)

    def undeclared_overrides(self) -> dict[str, Any]:
        """Overrides from the command line / params file that this node did not declare."""
        return self._params.undeclared_overrides()

    # endpoints
    def create_publisher(self, msg_type: type, topic: str, qos_profile: QoSProfile | int) -> Publisher:
        """A publisher of ``msg_type`` on ``topic`` (relative names use the namespace)."""
        self._check_alive()
        _check_msg_type(msg_type)
        pub = Publisher(self, msg_type, self.resolve_topic_name(topic), as_profile(qos_profile))
        self.publishers.append(pub)
        self._entities.writers.append(pub.handle)
        self.context.graph_changed(readers_changed=False)
        return pub

    def create_subscription(self, msg_type: type, topic: str, callback: Callable[[Any], Any],
                            qos_profile: QoSProfile | int, *, raw: bool = False) -> Subscription:
        """A subscription; ``callback(msg)`` runs in the executor (``raw``: CDR bytes)."""
        self._check_alive()
        _check_msg_type(msg_type)
        sub = Subscription(self, msg_type, self.resolve_topic_name(topic), callback, as_profile(qos_profile), raw)
        self.subscriptions.append(sub)
        self._entities.readers.append(sub.handle)
        self.context.graph_changed(readers_changed=True)
        return sub

    def create_timer(self, timer_period_sec: float, callback: Callable[[], Any]) -> Timer:
        """A drift-free periodic timer (monotonic clock)."""
        self._check_alive()
        timer = Timer(self, timer_period_sec, callback)
        self.timers.append(timer)
        self.context.wake()
        return timer

    def destroy_publisher(self, publisher: Publisher) -> bool:
        """Delete a publisher of this node."""
        if publisher not in self.publishers:
            return False
        self.publishers.remove(publisher)
        writer, publisher._writer = publisher._writer, None
        if writer in self._entities.writers:
            self._entities.writers.remove(writer)
        delete_entity(writer)
        self.context.graph_changed(readers_changed=False)
        return True

    def destroy_subscription(self, subscription: Subscription) -> bool:
        """Delete a subscription of this node."""
        if subscription not in self.subscriptions:
            return False
        self.subscriptions.remove(subscription)
        reader, subscription._reader = subscription._reader, None
        condition, subscription.condition = subscription.condition, None
        if reader in self._entities.readers:
            self._entities.readers.remove(reader)
        self.context.graph_changed(readers_changed=True)
        if self.context.executor is not None:
            self.context.executor._drop_waitset()
        delete_entity(condition)
        delete_entity(reader)
        return True

    def destroy_timer(self, timer: Timer) -> bool:
        """Remove a timer of this node."""
        if timer not in self.timers:
            return False
        timer.cancel()
        self.timers.remove(timer)
        return True

    def count_subscribers(self, topic: str) -> int:
        """Subscriptions matched with this process's publishers on ``topic``.

        Counted from the publication-matched status, so a publisher on ``topic`` must
        exist in this process (the builtin discovery readers are not used).
        """
        fq = self.resolve_topic_name(topic)
        counts = [p.get_subscription_count() for n in self.context.nodes for p in n.publishers if p.topic_name == fq]
        if not counts:
            raise NotImplementedError(
                f"count_subscribers('{fq}'): the Cyclone backend counts matched readers of this "
                "process's publishers; create a publisher on that topic first"
            )
        return max(counts)

    def count_publishers(self, topic: str) -> int:
        """Publishers matched with this process's subscriptions on ``topic`` (see count_subscribers)."""
        fq = self.resolve_topic_name(topic)
        counts = [s.get_publisher_count() for n in self.context.nodes for s in n.subscriptions if s.topic_name == fq]
        if not counts:
            raise NotImplementedError(
                f"count_publishers('{fq}'): the Cyclone backend counts matched writers of this "
                "process's subscriptions; create a subscription on that topic first"
            )
        return max(counts)

    def destroy_node(self) -> None:
        """Delete the node's endpoints and remove it from the graph."""
        if self._destroyed:
            return
        for sub in list(self.subscriptions):
            self.destroy_subscription(sub)
        for pub in list(self.publishers):
            self.destroy_publisher(pub)
        for timer in list(self.timers):
            self.destroy_timer(timer)
        self._destroyed = True
        with self.context._lock:
            if self in self.context.nodes:
                self.context.nodes.remove(self)
        self.context.graph_changed(readers_changed=True)

    def _check_alive(self) -> None:
        if self._destroyed:
            raise RuntimeError(f"node '{self._name}' was destroyed")


def _check_msg_type(msg_type: Any) -> None:
    if not (isinstance(msg_type, type) and issubclass(msg_type, IdlStruct)):
        raise TypeError(f"{msg_type!r} is not a message class from dualarm_control.ros.msgs")


# ------------------------------------------------------------------------- executor


class SingleThreadedExecutor:
    """Runs the timers and subscription callbacks of its nodes on the calling thread."""

    def __init__(self, *, context: Context | None = None) -> None:
        self._context = context
        self._nodes: list[Node] = []
        # (node, callback, args) in the order they became ready; entries of nodes that are
        # not (or no longer) added stay parked until the node is added again or destroyed.
        self._ready: deque[tuple[Node, Callable[..., Any], tuple[Any, ...]]] = deque()
        self._waitset: WaitSet | None = None
        self._waitset_key: tuple[int, tuple[int, ...]] | None = None

    @property
    def context(self) -> Context:
        """The context of the nodes (bound at the first ``add_node``; else the global one)."""
        return self._context or get_context()

    def add_node(self, node: Node) -> bool:
        """Spin ``node`` too."""
        if node in self._nodes:
            return False
        if self._context is None:
            self._context = node.context
        self._nodes.append(node)
        return True

    def remove_node(self, node: Node) -> None:
        """Stop spinning ``node`` (its already received samples wait for a later add)."""
        if node in self._nodes:
            self._nodes.remove(node)

    def get_nodes(self) -> list[Node]:
        """Nodes spun by this executor."""
        return list(self._nodes)

    def spin(self) -> None:
        """Run callbacks until shutdown (raises ExternalShutdownException on SIGTERM)."""
        while self.context.ok():
            self.spin_once()
        self._raise_if_external()

    def spin_once(self, timeout_sec: float | None = None) -> None:
        """Run at most one ready callback, waiting up to ``timeout_sec`` (None = forever)."""
        ctx = self.context
        deadline = None if timeout_sec is None or timeout_sec < 0 else time.monotonic_ns() + int(timeout_sec * 1e9)
        while True:
            self._raise_if_external()
            if not ctx.ok():
                return
            item = self._pop_ready()
            if item is None:
                self._collect()
                item = self._pop_ready()
            if item is not None:
                _, callback, args = item
                callback(*args)
                return
            now = time.monotonic_ns()
            wait_ns = _WAIT_SLICE_NS
            next_timer = self._next_timer_ns()
            if next_timer is not None:
                wait_ns = min(wait_ns, next_timer - now)
            if deadline is not None:
                if now >= deadline:
                    return
                wait_ns = min(wait_ns, deadline - now)
            if wait_ns > 0:
                self._wait(wait_ns)

    def shutdown(self, timeout_sec: float | None = None) -> bool:
        """Forget nodes and pending callbacks."""
        self._nodes.clear()
        self._ready.clear()
        self._drop_waitset()
        return True

    # internals
    def _pop_ready(self) -> tuple[Node, Callable[..., Any], tuple[Any, ...]] | None:
        for index, item in enumerate(self._ready):
            node = item[0]
            if node._destroyed:
                continue
            if node in self._nodes:
                del self._ready[index]
                return item
        if self._ready and any(item[0]._destroyed for item in self._ready):
            self._ready = deque(item for item in self._ready if not item[0]._destroyed)
        return None

    def _raise_if_external(self) -> None:
        ctx = self._context if self._context is not None else _context
        if ctx is not None and ctx.external_shutdown:
            raise ExternalShutdownException("context shut down by SIGTERM")

    def _next_timer_ns(self) -> int | None:
        deadlines = [t.next_deadline_ns for n in self._nodes for t in n.timers if not t.is_canceled()]
        return min(deadlines) if deadlines else None

    def _collect(self) -> None:
        now = time.monotonic_ns()
        for node in list(self._nodes):
            for timer in list(node.timers):
                if not timer.is_canceled() and now >= timer.next_deadline_ns:
                    timer._advance(now)
                    self._ready.append((node, timer.callback, ()))
        for node in list(self._nodes):
            for sub in list(node.subscriptions):
                for sample in sub.take():
                    self._ready.append((node, sub.callback, (sample,)))

    def _drop_waitset(self) -> None:
        if self._waitset is not None:
            self._waitset.attached = []  # the conditions may be deleted already; nothing to detach
            delete_entity(self._waitset)
            self._waitset = None
        self._waitset_key = None

    def _wait(self, timeout_ns: int) -> None:
        ctx = self.context
        key = (ctx.generation, tuple(id(n) for n in self._nodes))
        if self._waitset is None or self._waitset_key != key:
            self._drop_waitset()
            waitset = WaitSet(ctx.participant)
            waitset.attach(ctx.guard)
            for node in self._nodes:
                for sub in node.subscriptions:
                    if sub.condition is not None:
                        waitset.attach(sub.condition)
            self._waitset = waitset
            self._waitset_key = key
        self._waitset.wait(timeout_ns)
        ctx.guard.take()


def _executor_for(node: Node, executor: SingleThreadedExecutor | None) -> SingleThreadedExecutor:
    if executor is not None:
        return executor
    ctx = node.context
    if ctx.executor is None:
        ctx.executor = SingleThreadedExecutor(context=ctx)
    return ctx.executor


def spin(node: Node, executor: SingleThreadedExecutor | None = None) -> None:
    """Run ``node``'s callbacks until shutdown; Ctrl-C raises KeyboardInterrupt."""
    ex = _executor_for(node, executor)
    added = ex.add_node(node)
    try:
        ex.spin()
    finally:
        if added:
            ex.remove_node(node)


def spin_once(node: Node, *, executor: SingleThreadedExecutor | None = None, timeout_sec: float | None = None) -> None:
    """Run at most one callback of ``node``, waiting up to ``timeout_sec``."""
    ex = _executor_for(node, executor)
    added = ex.add_node(node)
    try:
        ex.spin_once(timeout_sec)
    finally:
        if added:
            ex.remove_node(node)
