"""Samples between nodes of one process, without the middleware (``cell_container``).

As rclcpp's intra-process communication in a component container: a sample that a node of the
process publishes on a *local* topic goes, as the same CDR bytes, straight to the callbacks of
the process's subscriptions on that topic, in publication order; it is also published on the
wire while a reader outside the process matches it, so any ROS 2 tool outside the process
(``dualarm topic echo``, a recorder, the view) reads every topic as before. The nodes do not
subscribe the local topics on the wire: a sample another process publishes on one of them is not
heard by the container (its inputs from outside are ``/relative_goal``, ``/relative_twist`` and
the parameters).

What it saves per sample: the middleware's delivery to another process (shared memory, its
threads' wake-ups) and the executor's dispatch of the receiving callback (docs/bench.md, "Cost
per cycle"). The receiver still decodes the bytes with the same checks as over the wire.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Hashable, Iterable
from typing import Any, TypeVar

Receive = Callable[[bytes], None]
T = TypeVar("T")


class LocalSubscription:
    """A callback on a local topic of ``bus``; :meth:`close` removes it."""

    def __init__(self, bus: LocalBus, topic: str, receive: Receive) -> None:
        self.bus, self.topic, self.receive = bus, topic, receive

    def close(self) -> None:
        subs = self.bus.subscriptions.get(self.topic, [])
        if self in subs:
            subs.remove(self)


class LocalPublisher:
    """Publisher of a local topic: each sample to the local subscriptions, then to the wire while a
    subscription there matches it.

    As rclcpp's intra-process publisher (``inter_process_publish_needed``: the subscription count
    above the intra-process one): a sample that no reader outside the process matches is not written
    to the middleware. On these volatile topics such a sample reaches nobody either way (a reader
    that matches later does not get the samples written before it matched), and the write costs
    10-16 us (docs/bench.md, "One process")."""

    def __init__(self, bus: LocalBus, wire: Any, topic: str) -> None:
        self.bus, self.wire, self.topic = bus, wire, topic

    def publish(self, data: bytes) -> None:
        self.bus.deliver(self.topic, data)
        if self.wire.get_subscription_count():
            self.wire.publish(data)

    def get_subscription_count(self) -> int:
        """Matched subscriptions: the local ones and those on the wire."""
        return len(self.bus.subscriptions.get(self.topic, ())) + self.wire.get_subscription_count()


class LocalBus:
    """The local topics of one process and their subscriptions.

    Delivery is breadth-first: a sample published from inside a callback (a command computed on
    a joint state) is queued and handed over after the current one, as a middleware would, so a
    chain of callbacks never recurses.
    """

    def __init__(self, topics: Iterable[str]) -> None:
        self.topics = frozenset(topics)
        self.subscriptions: dict[str, list[LocalSubscription]] = {}
        self._queue: deque[tuple[str, bytes]] = deque()
        self._delivering = False
        self._shared: dict[Hashable, Any] = {}

    def carries(self, topic: str) -> bool:
        return topic in self.topics

    def subscribe(self, topic: str, receive: Receive) -> LocalSubscription:
        sub = LocalSubscription(self, topic, receive)
        self.subscriptions.setdefault(topic, []).append(sub)
        return sub

    def publisher(self, wire: Any, topic: str) -> Any:
        """``wire`` (an rclpy publisher of ``topic``) as a :class:`LocalPublisher` when the topic is local."""
        return LocalPublisher(self, wire, topic) if self.carries(topic) else wire

    def shared(self, key: Hashable, make: Callable[[], T]) -> T:
        """One object per ``key`` for the nodes of the process: ``make()`` the first time, the same object after.
        For the decoders of a local topic: the nodes that read it with the same decoder settings decode each
        sample once (``JointStateInput.from_bytes`` keeps its last answer)."""
        if key not in self._shared:
            self._shared[key] = make()
        return self._shared[key]

    def deliver(self, topic: str, data: bytes) -> None:
        """Hand ``data`` to every local subscription of ``topic`` (queued while a delivery runs)."""
        self._queue.append((topic, data))
        if self._delivering:
            return
        self._delivering = True
        try:
            while self._queue:
                name, sample = self._queue.popleft()
                for sub in tuple(self.subscriptions.get(name, ())):
                    sub.receive(sample)
        finally:
            self._delivering = False
            self._queue.clear()


def local_publisher(bus: LocalBus | None, wire: Any, topic: str) -> Any:
    """``wire`` itself without a bus (a node in its own process), else :meth:`LocalBus.publisher`."""
    return wire if bus is None else bus.publisher(wire, topic)


def publish_if_subscribed(pub: Any, build: Callable[[], bytes]) -> bool:
    """Publish ``build()`` on ``pub`` only while a subscription matches it (local or on the wire), as
    lazy ROS publishers do: a sample nobody reads is neither computed nor sent. Returns whether it was.

    For the per-cycle topics that no node of the cell needs in every run (/wrench, /relative_pose,
    /clock in real time, /contact_force): a recorder, ``dualarm topic echo`` or the view subscribes
    and gets them from the next cycle on (the lockstep runs start once their readers matched).
    """
    if pub.get_subscription_count() == 0:
        return False
    pub.publish(build())
    return True

