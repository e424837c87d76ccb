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
* :class:`StreamInputs`: the latest (lockstep: by stamp) samples of the streams a cycle takes.
* :class:`CycleTiming`: period jitter, missed periods and state-to-command latency of the cycles.

Nothing here holds control math; only :func:`subscribe_checked` imports rclpy.
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Protocol, TypeVar

import numpy as np

from dualarm_control.errors import InputRejected
from dualarm_control.metrics import percentiles
from dualarm_control.ros.cdr import CdrError
from dualarm_control.ros.local_bus import LocalBus, LocalSubscription

DESERIALIZE_ERRORS = (RuntimeError, ValueError, TypeError, OverflowError, MemoryError)
"""What deserialize_message raises on a bad payload (rclpy's RMWError is a RuntimeError)."""
T_co = TypeVar("T_co", covariant=True)
WINDOW = 2000
"""Samples kept for the jitter and latency percentiles."""
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
    raise :class:`~dualarm_control.ros.cdr.CdrError`) or from the rclpy message. Either raises
    :class:`~dualarm_control.errors.InputRejected` for a sample it reads but cannot use."""

    def from_bytes(self, data: bytes) -> T_co: ...

    def from_message(self, msg: Any) -> T_co: ...


def subscribe_checked(node: Any, msg_type: Any, topic: str, callback: Callable[[Any], None], qos: Any,
                      on_malformed: Callable[[str], None], decoder: Decoder[Any] | None = None,
                      bus: LocalBus | None = None,
                      on_rejected: Callable[[InputRejected], None] | None = None) -> Any:
    """A subscription on ``topic`` that never lets a malformed sample reach ``callback`` or kill the node.

    Subscribes raw (serialized CDR bytes). With a ``decoder``, ``callback`` receives
    ``decoder.from_bytes(data)``; a payload the fast reader refuses goes through
    ``rclpy.serialization.deserialize_message`` and ``decoder.from_message``, so rclpy decides
    what is malformed. Without one, ``callback`` receives the deserialized message (~16 us
    per 14-joint JointState). A sample that fails to deserialize is reported through
    ``on_malformed("malformed message on /topic: <reason>")`` and dropped (a typed
    subscription would drop it silently inside the middleware). A sample the decoder rejects
    (:class:`~dualarm_control.errors.InputRejected`) goes to ``on_rejected``, without one its reason
    to ``on_malformed``. With a ``bus`` that carries ``topic`` (nodes in one process), the samples
    come from the bus, not the wire.
    """
    from rclpy.serialization import deserialize_message

    rejected = on_rejected or (lambda exc: on_malformed(exc.reason))

    def receive(data: bytes) -> None:
        if decoder is not None:
            try:
                value = decoder.from_bytes(data)
            except CdrError:
                pass
            except InputRejected as exc:
                rejected(exc)
                return
            else:
                callback(value)
                return
        try:
            msg = deserialize_message(data, msg_type)
        except DESERIALIZE_ERRORS as exc:
            on_malformed(f"malformed message on {topic} ({len(data)} bytes): {exc}")
            return
        if decoder is None:
            callback(msg)
            return
        try:
            value = decoder.from_message(msg)
        except InputRejected as exc:
            rejected(exc)
            return
        callback(value)

    if bus is not None and bus.carries(topic):
        return bus.subscribe(topic, receive)
    return node.create_subscription(msg_type, topic, receive, qos, raw=True)


def unsubscribe(node: Any, sub: Any) -> None:
    """Remove a subscription made by :func:`subscribe_checked` (on the wire or on a local bus)."""
    if isinstance(sub, LocalSubscription):
        sub.close()
    else:
        node.destroy_subscription(sub)


class StreamInputs:
    """What a node's cycle takes besides the joint state: per stream (topic) the latest accepted
    sample with its receipt time (monotonic ns) and, in lockstep, the samples waiting for the
    cycle of their stamp. Stamps are checked per stream, ``/joint_states`` included (:class:`StampGate`)."""

    def __init__(self, streams: Sequence[str], lockstep: bool) -> None:
        self.streams, self.lockstep = tuple(streams), lockstep
        self.gates = {s: StampGate(s.lstrip("/")) for s in ("/joint_states", *self.streams)}
        self.latest: dict[str, tuple[Any, int]] = {}
        self.pending: dict[str, dict[int, Any]] = {s: {} for s in self.streams}

    def check(self, stream: str, stamp_ns: int) -> StampVerdict:
        """The stream's stamp gate; a restarted time source drops the lockstep samples of the old time base."""
        verdict = self.gates[stream].check(stamp_ns)
        if verdict.accepted and verdict.message:
            self.pending = {s: {k: v for k, v in p.items() if k <= stamp_ns} for s, p in self.pending.items()}
        return verdict

    def put(self, stream: str, stamp_ns: int, value: Any) -> None:
        """An accepted sample: the latest of its stream (lockstep: also kept by stamp)."""
        self.latest[stream] = (value, time.monotonic_ns())
        if self.lockstep:
            self.pending[stream][stamp_ns] = value

    def at(self, stamp_ns: int) -> dict[str, Any] | None:
        """Lockstep: the sample of every stream stamped ``stamp_ns`` (these and older ones are
        dropped), or None while one of them is on the way."""
        if not all(stamp_ns in p for p in self.pending.values()):
            return None
        out = {s: p[stamp_ns] for s, p in self.pending.items()}
        self.pending = {s: {k: v for k, v in p.items() if k > stamp_ns} for s, p in self.pending.items()}
        return out


class CycleTiming:
    """Timing of the cycles a stream drives: the stream's period jitter and missed periods (real
    time only), and the state-to-command latency; percentiles over the last ``WINDOW`` cycles."""

    def __init__(self, realtime: bool) -> None:
        self.realtime = realtime
        self.missed = 0
        self.interval = math.nan  # last inter-arrival time [s]
        self.jitter: deque[float] = deque(maxlen=WINDOW)
        self.latency: deque[float] = deque(maxlen=WINDOW)
        self._last: int | None = None
        self._stats = self._formatted(self.percentiles())

    def arrival(self, now_ns: int, period: float) -> None:
        """A sample of the driving stream arrived at monotonic ``now_ns``; ``period`` [s] is the nominal one."""
        period_ns = period * 1e9
        if self._last is not None and self.realtime:
            dt = now_ns - self._last
            self.interval = dt / 1e9
            self.jitter.append(abs(dt - period_ns) / 1e9)
            if dt > 1.5 * period_ns:
                self.missed += round(dt / period_ns) - 1
        self._last = now_ns

    def command(self, stamp_ns: int, received_ns: int, period: float) -> float:
        """A command was sent for the state of ``stamp_ns`` received at monotonic ``received_ns``;
        returns the latency [s]. Real time: from the state's stamp (its publication, wall clock) to
        now, transport included; lockstep stamps are simulation time: from receipt."""
        latency = (time.time_ns() - stamp_ns if self.realtime else time.monotonic_ns() - received_ns) / 1e9
        self.latency.append(latency)
        if self.realtime and latency > period:
            self.missed += 1
        return latency

    def values(self, latency: float, refresh: bool) -> dict[str, str]:
        """A cycle's /diagnostics timing values: its ``latency`` [s], the last interval, and the
        percentiles of both (recomputed when ``refresh``: once a second, not every cycle)."""
        if refresh:
            self._stats = self._formatted(self.percentiles())
        return {**self._stats, "state_interval_s": f"{self.interval:.6e}",
                "state_to_command_latency_s": f"{latency:.6e}"}

    @staticmethod
    def _formatted(stats: tuple[tuple[float, float], tuple[float, float]]) -> dict[str, str]:
        """The percentiles' /diagnostics values (formatted once per refresh, not every cycle)."""
        (j50, j99), (l50, l99) = stats
        return {"period_jitter_p50_s": f"{j50:.6e}", "period_jitter_p99_s": f"{j99:.6e}",
                "state_to_command_latency_p50_s": f"{l50:.6e}", "state_to_command_latency_p99_s": f"{l99:.6e}"}

    def percentiles(self) -> tuple[tuple[float, float], tuple[float, float]]:
        """(p50, p99) of the period jitter and of the latency [s] (NaN when there is no sample)."""
        return tuple(percentiles(np.fromiter(b, float, len(b))) if b else (math.nan, math.nan)  # type: ignore[return-value]
                     for b in (self.jitter, self.latency))
