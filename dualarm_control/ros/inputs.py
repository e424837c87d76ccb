"""Guards on what the nodes receive: malformed samples, stamps that go back in time, log floods.

One place for the checks every node shell needs (docs/safety.md, "Input validation and
solver failure"):

* :func:`subscribe_checked`: a raw subscription that deserializes each sample itself, so a
  malformed CDR payload is reported ("malformed message on /topic") and dropped instead of
  vanishing silently inside the middleware.
* :class:`StampGate`: stamps of one stream must not go back in time; a restarted time
  source (a simulator restarted mid-run) is accepted after a few consecutive, mutually
  monotonic older samples.
* :class:`Throttle`: at most one log line per interval, with the count of suppressed ones.

Nothing here holds control math; only :func:`subscribe_checked` imports rclpy.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol, TypeVar

from dualarm_control.ros.cdr import CdrError

DESERIALIZE_ERRORS = (RuntimeError, ValueError, TypeError, OverflowError, MemoryError)
"""What deserialize_message raises on a bad payload (rclpy's RMWError is a RuntimeError)."""
T_co = TypeVar("T_co", covariant=True)
RESTART_AFTER = 3
"""Consecutive older, mutually monotonic stamps after which a new time base is accepted."""


@dataclass(frozen=True)
class StampVerdict:
    """Outcome of :meth:`StampGate.check`.

    Attributes:
        accepted: the sample may be used.
        message: why it was rejected, or the restart note for an accepted sample; '' otherwise.
    """

    accepted: bool
    message: str = ""


class StampGate:
    """Monotonic stamps for one input stream, with restart detection.

    A stamp equal to or newer than the last accepted one is accepted (equal: a re-sent
    sample, e.g. the lockstep simulator's resend). An older stamp is rejected, unless it is
    the ``restart_after``-th of consecutive older stamps that are non-decreasing among
    themselves: then the stream's time source restarted (a simulator restarted with its
    clock at 0, a ``use_sim_time`` node whose /clock restarted) and the new time base is
    accepted with the note "time source restarted".
    """

    def __init__(self, what: str, restart_after: int = RESTART_AFTER) -> None:
        if restart_after < 1:
            raise ValueError(f"restart_after must be >= 1, got {restart_after}")
        self.what = what
        self.restart_after = restart_after
        self.last: int | None = None
        self._older: list[int] = []

    def check(self, stamp_ns: int) -> StampVerdict:
        """Accept or reject the stamp [ns] of the next sample of the stream."""
        if self.last is None or stamp_ns >= self.last:
            self.last, self._older = stamp_ns, []
            return StampVerdict(True)
        if self._older and stamp_ns < self._older[-1]:
            self._older = []
        self._older.append(stamp_ns)
        if len(self._older) >= self.restart_after:
            note = (f"{self.what}: time source restarted ({len(self._older)} consecutive stamps before "
                    f"the last accepted {self.last / 1e9:.3f} s; new time base at {stamp_ns / 1e9:.3f} s)")
            self.last, self._older = stamp_ns, []
            return StampVerdict(True, note)
        return StampVerdict(False, f"{self.what} stamp {stamp_ns / 1e9:.3f} s is older than the last accepted "
                                   f"{self.last / 1e9:.3f} s (non-monotonic)")


class Throttle:
    """Lets one message through per ``interval`` [s] (monotonic clock) and counts the rest."""

    def __init__(self, interval: float = 1.0) -> None:
        self.interval = interval
        self._last = -float("inf")
        self.suppressed = 0

    def text(self, message: str) -> str | None:
        """``message`` (with the count suppressed since the last one) when it may be logged, else None."""
        now = time.monotonic()
        if now - self._last < self.interval:
            self.suppressed += 1
            return None
        self._last = now
        note = f" ({self.suppressed} similar messages suppressed)" if self.suppressed else ""
        self.suppressed = 0
        return message + note


class Decoder(Protocol[T_co]):
    """Turns a sample into what a node's callback uses: from its CDR bytes (the fast path, may
    raise :class:`~dualarm_control.ros.cdr.CdrError`) or from the rclpy message."""

    def from_bytes(self, data: bytes) -> T_co: ...

    def from_message(self, msg: Any) -> T_co: ...


def subscribe_checked(node: Any, msg_type: Any, topic: str, callback: Callable[[Any], None], qos: Any,
                      on_malformed: Callable[[str], None], decoder: Decoder[Any] | None = None) -> Any:
    """A subscription on ``topic`` that never lets a malformed sample reach ``callback`` or kill the node.

    Subscribes raw (serialized CDR bytes). With a ``decoder``, ``callback`` receives
    ``decoder.from_bytes(data)``; a payload the fast reader refuses goes through
    ``rclpy.serialization.deserialize_message`` and ``decoder.from_message``, so rclpy decides
    what is malformed. Without one, ``callback`` receives the deserialized message (~16 us
    per 14-joint JointState). A sample that fails to deserialize is reported through
    ``on_malformed("malformed message on /topic: <reason>")`` and dropped (a typed
    subscription would drop it silently inside the middleware).
    """
    from rclpy.serialization import deserialize_message

    def receive(data: bytes) -> None:
        if decoder is not None:
            try:
                value = decoder.from_bytes(data)
            except CdrError:
                pass
            else:
                callback(value)
                return
        try:
            msg = deserialize_message(data, msg_type)
        except DESERIALIZE_ERRORS as exc:
            on_malformed(f"malformed message on {topic} ({len(data)} bytes): {exc}")
            return
        callback(msg if decoder is None else decoder.from_message(msg))

    return node.create_subscription(msg_type, topic, receive, qos, raw=True)
