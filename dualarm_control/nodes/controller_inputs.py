"""What controller_node's cycle takes besides the joint state, and when those inputs forbid motion.

:class:`ControllerInputs` holds, per stream of the reference source (``/relative_target``,
``/joint_reference``, ``/wrench``), the accepted samples (:class:`~dualarm_control.ros.inputs.StreamInputs`:
monotonic stamps per stream, ``/joint_states`` included; a restarted time source is accepted after 3
samples), counts and reports the rejected ones (throttled log line, /diagnostics), and judges the
real-time watchdogs: joint states older than ``stale_timeout``, a wrench older than ``stale_timeout``,
a target stream silent for ``target_timeout`` while its last sample asked for motion (docs/safety.md).
:func:`stream_sample` is what a cycle's samples give the tracker.
No node and no publisher here: what it reports goes through the node's ``CommandOutput``.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from dualarm_control.errors import InputRejected
from dualarm_control.hardware import StateAssembler
from dualarm_control.references.base import (
    JOINT_REFERENCE,
    LEFT_WRENCH,
    RELATIVE_TARGET,
    RIGHT_WRENCH,
    WRENCH,
    StreamSample,
)
from dualarm_control.ros import convert
from dualarm_control.ros.inputs import StampVerdict, StreamInputs

WRENCH_STREAMS = (WRENCH, LEFT_WRENCH, RIGHT_WRENCH)
"""The F/T streams: the force variant's one sensor, a held object's two wrist sensors."""
SYNCED_STREAMS = (LEFT_WRENCH, RIGHT_WRENCH)
"""Streams a real-time cycle waits for at its joint state's stamp (as in lockstep): the wrist sensors of a held
object, whose stiff grasp makes the internal-force loop unstable with a one-period-old reading (measured in
process: 42 N without control, 980 N with it at any gain tried, 5e-4 to 1e-2 m/(N s))."""
MOVING = 1e-9
"""A target twist / reference velocity norm above this is motion [m/s, rad/s]."""


class ControllerInputs:
    """The streams a cycle consumes (``streams``), their rejections and their watchdogs.

    ``out``: the node's :class:`~dualarm_control.ros.output.CommandOutput` (rejections, safe commands);
    ``values``: the node's current parameter values (``stale_timeout``, ``target_timeout`` [s] change
    live); ``assembler``: the joint-state topics' :class:`~dualarm_control.hardware.StateAssembler`;
    ``on_sample``: called after each accepted sample in lockstep (it may complete a cycle).
    """

    def __init__(self, streams: Sequence[str], lockstep: bool, out: Any, log: Any,
                 values: Callable[[], Mapping[str, Any]], assembler: StateAssembler,
                 on_sample: Callable[[], None]) -> None:
        self.streams, self.lockstep = tuple(streams), lockstep
        self.out, self.log, self.values, self.assembler, self.on_sample = out, log, values, assembler, on_sample
        self.samples = StreamInputs(self.streams, lockstep)
        self.stamps: dict[str, int] = {}  # the latest accepted stamp [ns] of each synced stream

    def check_stamp(self, stream: str, stamp: int) -> StampVerdict:
        """Monotonic stamps [ns] per stream (:class:`~dualarm_control.ros.inputs.StampGate`): an older one is
        rejected, a restarted time source logged and reported (``time_source_restarted``)."""
        verdict = self.samples.check(stream, stamp)
        if not verdict.accepted:
            self.out.reject(stamp, verdict.message)
        elif verdict.message:
            self.log.warning(verdict.message)
            self.out.report(stamp, verdict.message, "time_source_restarted")
        return verdict

    def message_input(self, stream: str, decode: Callable[[Any], Any]) -> Callable[[Any], None]:
        """The callback of a stream read from the rclpy message: ``decode(msg)`` at the header's stamp to
        :meth:`put`, or its rejection (:class:`InputRejected`) to :meth:`rejected`."""
        def receive(msg: Any) -> None:
            try:
                value = decode(msg)
            except InputRejected as exc:
                self.rejected(stream, exc)
            else:
                self.put(stream, convert.stamp_ns(msg.header.stamp), value)
        return receive

    def rejected(self, stream: str, exc: InputRejected) -> None:
        """A sample of ``stream`` its decoder rejected: counted and reported at its stamp; the last valid one is kept."""
        self.out.reject(exc.stamp or 0, f"{stream.lstrip('/')} rejected: {exc.reason}")

    def put(self, stream: str, stamp: int, value: Any) -> None:
        """A decoded sample of ``stream`` at ``stamp`` [ns]: kept if its stamp is accepted (lockstep: then :attr:`on_sample`)."""
        if self.check_stamp(stream, stamp).accepted:
            self.samples.put(stream, stamp, value)
            if stream in SYNCED_STREAMS:
                self.stamps[stream] = stamp
            if self.lockstep or stream in SYNCED_STREAMS:
                self.on_sample()

    def for_cycle(self, stamp: int) -> dict[str, Any] | None:
        """The samples of the cycle of the joint state stamped ``stamp`` [ns], or None: lockstep, the samples of
        that stamp (None while one is on the way); real time, the latest fresh ones (None after a safe command)."""
        return self.samples.at(stamp) if self.lockstep else self.fresh(stamp)

    def fresh(self, stamp: int) -> dict[str, Any] | None:
        """Real time: the latest sample of every stream, or None after a safe command (none yet,
        a stale wrench, a target stream stopped mid-motion), or None without one while a wrist reading of the
        state's stamp is on the way (:data:`SYNCED_STREAMS`)."""
        sample = {}
        for stream in self.streams:
            if stream not in self.samples.latest:
                self.out.safe(stamp, f"waiting for {stream.lstrip('/')}")
                return None
            value, received = self.samples.latest[stream]
            age = time.monotonic_ns() - received
            if stream in WRENCH_STREAMS and age > self.values()["stale_timeout"] * 1e9:
                self.out.enter_safe_state(stamp, f"{stream.lstrip('/')} stale by {age / 1e6:.1f} ms")
                return None
            if stream in SYNCED_STREAMS and self.stamps.get(stream, stamp) < stamp:
                return None  # the reading of this state's stamp is on the way (put() calls the cycle again)
            sample[stream] = value
        reason = self.target_fault(time.monotonic_ns())
        if reason:
            self.out.enter_safe_state(stamp, reason)
            return None
        return sample

    def watchdog(self, now: int, received: int) -> str:
        """Real time: why the last joint state (received at monotonic ``received`` [ns]) may not be followed
        at monotonic ``now`` [ns]: it is stale (several topics: which one), or a target fault; '' if neither."""
        age = now - received
        timeout = self.values()["stale_timeout"] * 1e9
        if age <= timeout:
            return self.target_fault(now)
        stale = self.assembler.stale_reason(now, timeout) if len(self.assembler.topics) > 1 else ""
        return stale or f"joint_states stale by {age / 1e6:.1f} ms"

    def target_fault(self, now: int) -> str:
        """Why the target streams count as stopped mid-motion at monotonic ``now`` [ns] ('' if they do not):
        their last sample is older than ``target_timeout`` and asked for motion (a non-zero twist or joint
        reference velocity)."""
        latest = self.samples.latest
        if RELATIVE_TARGET not in latest:
            return ""
        speed = latest[RELATIVE_TARGET][0].speed
        if JOINT_REFERENCE in latest:
            speed = max(speed, float(np.linalg.norm(latest[JOINT_REFERENCE][0][2])))
        age = now - max(latest[s][1] for s in (RELATIVE_TARGET, JOINT_REFERENCE) if s in latest)
        if speed <= MOVING or age <= self.values()["target_timeout"] * 1e9:
            return ""
        return f"{self.streams[-1].lstrip('/')} stopped mid-motion: none for {age / 1e6:.1f} ms"


def cycle_wrench(samples: Mapping[str, Any]) -> np.ndarray | None:
    """The F/T reading a cycle gives its tracker: both wrist sensors (12,) (left, right) when the cycle has
    them, else the one sensor's (6,), else None."""
    if LEFT_WRENCH in samples:
        return np.concatenate((samples[LEFT_WRENCH], samples[RIGHT_WRENCH]))
    return samples.get(WRENCH)


def stream_sample(samples: Mapping[str, Any]) -> StreamSample | None:
    """The tracker's sample of a cycle's ``samples`` (:meth:`ControllerInputs.for_cycle`): the relative
    target with the joint reference's (q_ref [rad], qd_ref [rad/s]) if there is one; None without a target
    stream (tasks)."""
    if RELATIVE_TARGET not in samples:
        return None
    ref = samples.get(JOINT_REFERENCE)
    target = samples[RELATIVE_TARGET]
    return StreamSample(target, (ref[1], ref[2]) if ref is not None else None, "", getattr(target, "absolute", None))
