"""Subscribe to the cell's topics for the app's monitors (live view, Foxglove server, soak).

:func:`listen` makes a tool node (:func:`~dualarm_control.ros.node.tool_node`) with the
subscriptions of a ``{topic: Topic}`` mapping and yields a :class:`Listener` that the caller
spins until its own stop condition (a duration, a stop event, the signal flag), so the app's
code names message types by their ``pkg/msg/Type`` name and never imports rclpy or a message
package.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

from dualarm_control.ros.graph import message_class
from dualarm_control.ros.inputs import Decoder, subscribe_checked
from dualarm_control.ros.node import StopOnSignal, tool_node


@dataclass(frozen=True)
class Topic:
    """One subscription of :func:`listen`.

    Attributes:
        type_name: message type, ``pkg/msg/Type``.
        callback: receives the serialized CDR bytes (``raw``), else ``decoder``'s value of the
            sample, else the deserialized message.
        qos: keep-last depth or an rclpy QoS profile (:mod:`dualarm_control.ros.qos`).
        raw: hand the CDR bytes over as received.
        decoder: turns a sample into the callback's value (:mod:`dualarm_control.ros.convert`).
    """

    type_name: str
    callback: Callable[[Any], None]
    qos: Any = 10
    raw: bool = False
    decoder: Decoder[Any] | None = None


class Listener:
    """The node of :func:`listen`: more subscriptions, one spin step, the signal flag."""

    def __init__(self, node: Any, executor: Any, stop: StopOnSignal,
                 on_malformed: Callable[[str], None]) -> None:
        self.node, self.executor, self.stop, self.on_malformed = node, executor, stop, on_malformed

    def subscribe(self, topics: Mapping[str, Topic]) -> None:
        """Subscribe ``topics``; a sample that is not raw goes through
        :func:`~dualarm_control.ros.inputs.subscribe_checked` (a malformed one, or one its decoder
        rejects, is reported to ``on_malformed`` and dropped)."""
        for name, topic in topics.items():
            cls = message_class(topic.type_name)
            if topic.raw:
                self.node.create_subscription(cls, name, topic.callback, topic.qos, raw=True)
            else:
                subscribe_checked(self.node, cls, name, topic.callback, topic.qos, self.on_malformed, topic.decoder)

    def spin_once(self, timeout: float) -> None:
        """Run the callbacks that are ready, waiting at most ``timeout`` [s] for one."""
        self.executor.spin_once(timeout_sec=timeout)

    @property
    def signalled(self) -> bool:
        """Ctrl-C or SIGTERM arrived (only with ``signals``, in the main thread)."""
        return self.stop.signal is not None


def _ignore(text: str) -> None:
    """The default ``on_malformed``: drop the sample (as a typed subscription does)."""


@contextmanager
def listen(name: str, topics: Mapping[str, Topic], *, signals: bool = True,
           on_malformed: Callable[[str], None] = _ignore) -> Iterator[Listener]:
    """A tool node ``name`` subscribed to ``topics``, torn down on exit.

    With ``signals`` Ctrl-C/SIGTERM set :attr:`Listener.signalled` (the caller's loop checks it);
    without, no signal handler is installed (for a server run in any thread).
    """
    with tool_node(name, signals) as (node, executor, stop):
        listener = Listener(node, executor, stop, on_malformed)
        listener.subscribe(topics)
        yield listener
