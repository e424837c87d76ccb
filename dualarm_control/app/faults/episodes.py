"""What a fault run's bag shows: safe-state episodes, arms stopping, completion, bag completeness.

Times are the recorder's receive times (wall clock, ns) unless a name says ``stamp``: the
simulator stamps ``/joint_states`` with the wall clock at publication (real-time mode) and the
controller stamps ``/relative_pose`` with the joint state it answered, so "the last state the
controller answered" and "the first state at rest after it" are exact, counted in simulator
steps (simulation time) and independent of how late the recorder ran.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from dualarm_control.app.record.bag import BagError, Status, open_reader, read_bag
from dualarm_control.metrics import percentiles
from dualarm_control.ros.convert import stamp_ns

STOPPED_SPEED = 1e-3
"""A joint is at rest below this speed [rad/s] (the papers' activity threshold)."""
AFTER_ERROR_NS = 10_000_000
"""Commands within 10 ms after the first ERROR may be a cycle computed just before it (topics are not ordered)."""


@dataclass
class GraphStreams:
    """The graph-level streams of a fault run, in receive order: every node's /diagnostics
    status (controller, simulator, trajectory node), the largest |command| per message, the
    joint-state and pose stamps. Not a per-cycle record (that is
    :class:`dualarm_control.app.record.run_record.RunRecord`): a fault run is judged on what
    every node published and when, including safe commands and statuses outside cycles."""

    controller: list[Status] = field(default_factory=list)
    sim: list[Status] = field(default_factory=list)
    trajectory: list[Status] = field(default_factory=list)
    command_t: list[int] = field(default_factory=list)
    command_max: list[float] = field(default_factory=list)
    state_stamp: list[int] = field(default_factory=list)
    state_speed: list[float] = field(default_factory=list)
    pose_stamp: list[int] = field(default_factory=list)


def read_record(bag: Path) -> GraphStreams:
    """The graph streams of a fault run's bag, from the one bag reader (:func:`~dualarm_control.app.record.bag.read_bag`)."""
    data, rec = read_bag(bag), GraphStreams()
    statuses = {"controller_node": rec.controller, "sim_node": rec.sim, "trajectory_node": rec.trajectory}
    for s in data.statuses:
        if s.name in statuses:
            statuses[s.name].append(s)
    for t, command in data.commands:
        rec.command_t.append(t)
        rec.command_max.append(float(np.max(np.abs(command))) if len(command) else 0.0)
    for _, stamp, _, msg in data.states:
        rec.state_stamp.append(stamp)
        rec.state_speed.append(float(np.max(np.abs(msg.velocity))) if len(msg.velocity) else 0.0)
    rec.pose_stamp = list(data.pose_stamps)
    return rec


@dataclass(frozen=True)
class SafeEpisode:
    """The controller's answer to a fault injected at ``start`` and removed at ``resume`` (wall ns)."""

    reason: str  # the first ERROR's message ('' if none)
    detected_ms: float  # first ERROR received - fault start (nan if none)
    age_ms: float  # the controller's own figure in the reason: input age when it tripped (nan if none)
    zero_commands: int  # commands in [first ERROR + 10 ms, resume] that are all zero
    other_commands: int  # ... that are not
    recovered_ms: float  # first cycle with watchdog ok after resume - resume (nan if none)
    trips: int  # watchdog_trips increase over the episode

    def text(self) -> str:
        return (f"ERROR after {self.detected_ms:.0f} ms (input age {self.age_ms:.1f} ms: '{self.reason}'), "
                f"{self.zero_commands} zero commands and {self.other_commands} others while safe, "
                f"OK again {self.recovered_ms:.0f} ms after the input returned")


def _age_ms(reason: str) -> float:
    found = re.search(r"(?:stale by|none for) ([0-9.]+) ms", reason)
    return float(found.group(1)) if found else float("nan")


def _trips(statuses: list[Status]) -> int:
    return max((int(s.values.get("watchdog_trips", 0)) for s in statuses), default=0)


def safe_episode(rec: GraphStreams, start: int, resume: int, reason_text: str, end: int | None = None) -> SafeEpisode:
    """First ERROR whose message contains ``reason_text`` after ``start``, the commands sent while safe,
    and the first cycle after ``resume`` with the watchdog ok (searched until ``end``)."""
    errors = [s for s in rec.controller if s.t >= start and s.level == 2 and reason_text in s.message
              and (end is None or s.t <= end)]
    nan = float("nan")
    if not errors:
        return SafeEpisode("", nan, nan, 0, 0, nan, 0)
    first = errors[0]
    window = [m for t, m in zip(rec.command_t, rec.command_max) if first.t + AFTER_ERROR_NS <= t <= resume]
    zero = sum(1 for m in window if m == 0.0)
    ok = [s for s in rec.controller if s.t > resume and s.is_cycle and s.values.get("watchdog") == "ok"
          and (end is None or s.t <= end)]
    before = [s for s in rec.controller if s.t < start]
    after = [s for s in rec.controller if s.t <= (ok[0].t if ok else resume)]
    return SafeEpisode(first.message, (first.t - start) / 1e6, _age_ms(first.message), zero, len(window) - zero,
                       (ok[0].t - resume) / 1e6 if ok else nan, _trips(after) - _trips(before))


@dataclass(frozen=True)
class ArmStop:
    """The arms after the controller's last command (from /relative_pose, the commands' receipt and
    /joint_states stamps)."""

    speed_at_last: float  # max joint speed at the last answered state [rad/s]
    steps: int  # simulator steps from the last command's arrival to the first state at rest (-1: never)
    wall_ms: float  # the same span in the states' wall-clock stamps
    late_steps: int = 0  # steps from the last answered state to its command's arrival (the controller's lag)
    states_after: int = 0  # states recorded from that arrival on (a simulator that stopped stepping: few)
    span_ms: float = 0.0  # their stamps' span [ms]

    def text(self, period: float) -> str:
        if self.steps < 0:
            return (f"moving at {self.speed_at_last:.3f} rad/s when the controller died; never at rest (< "
                    f"{STOPPED_SPEED:g} rad/s) in the {self.states_after} states recorded after its last command "
                    f"({self.span_ms:.0f} ms of state stamps)")
        return (f"moving at {self.speed_at_last:.3f} rad/s when the controller died; at rest (< {STOPPED_SPEED:g} "
                f"rad/s) {self.steps} steps = {self.steps * period * 1e3:.0f} ms sim time "
                f"({self.wall_ms:.0f} ms wall) after its last command arrived ({self.late_steps} steps after the last "
                "state it answered)")


def command_arrival(rec: GraphStreams) -> int:
    """When the simulator received its last command, in its states' stamp clock [ns]: the largest
    ``last_command_ns`` of its statuses (it publishes one at once when its command timeout fires). The
    recorder's receive time of the last command only without one (0 if no command): a recorder starved on
    a busy machine takes a queued command seconds after it arrived, later than every state then recorded."""
    sent = [int(s.values["last_command_ns"]) for s in rec.sim if "last_command_ns" in s.values]
    return max(sent) if sent else max(rec.command_t, default=0)


def arm_stop(rec: GraphStreams, after_stamp: int) -> ArmStop:
    """Steps to rest from the arrival of the controller's last command (the first state stamped at or after
    it (:func:`command_arrival`), or the last state it answered if later: the simulator's command timeout
    counts from the command it received, and a loaded controller answers a state late), over states stamped
    >= ``after_stamp``."""
    answered = [s for s in rec.pose_stamp if s >= after_stamp]
    if not answered:
        return ArmStop(float("nan"), -1, float("nan"))
    last = max(answered)
    order = np.argsort(rec.state_stamp)
    stamps = np.array(rec.state_stamp)[order]
    speeds = np.array(rec.state_speed)[order]
    i_answered = int(np.searchsorted(stamps, last))
    if i_answered >= len(stamps) or stamps[i_answered] != last:
        return ArmStop(float("nan"), -1, float("nan"))
    i0 = max(i_answered, int(np.searchsorted(stamps, command_arrival(rec))))
    rest = np.nonzero(speeds[i0:] < STOPPED_SPEED)[0]
    if not len(rest):
        span_ms = (stamps[-1] - stamps[i0]) / 1e6 if i0 < len(stamps) else 0.0
        return ArmStop(float(speeds[i_answered]), -1, float("nan"), i0 - i_answered, len(stamps) - i0, span_ms)
    k = int(rest[0])
    return ArmStop(float(speeds[i_answered]), k, (stamps[i0 + k] - stamps[i0]) / 1e6, i0 - i_answered)


@dataclass(frozen=True)
class Completion:
    """How a whole run went, from the controller's per-cycle diagnostics."""

    complete: bool  # the trajectory node reported "complete"
    cycles: int
    trips: int
    position_error_m: float  # at the last cycle
    orientation_error_rad: float
    latency_p50_ms: float  # state stamp -> command publication, transport included
    latency_p99_ms: float

    def text(self) -> str:
        return (f"{'complete' if self.complete else 'NOT complete'}, {self.cycles} cycles, {self.trips} watchdog "
                f"trips, final error {self.position_error_m * 1e3:.3f} mm / {self.orientation_error_rad * 1e3:.2f} "
                f"mrad, state-to-command latency p50/p99 {self.latency_p50_ms:.2f}/{self.latency_p99_ms:.2f} ms")


def completion(rec: GraphStreams) -> Completion:
    cycles = [s for s in rec.controller if s.is_cycle]
    complete = any(s.message == "complete" for s in rec.trajectory)
    if not cycles:
        return Completion(complete, 0, _trips(rec.controller), float("nan"), float("nan"), float("nan"), float("nan"))
    last = cycles[-1].values
    latency = np.array([float(s.values["state_to_command_latency_s"]) for s in cycles])
    p50, p99 = percentiles(latency)
    return Completion(complete, int(last["cycles"]), _trips(rec.controller), float(last["position_error_m"]),
                      float(last["orientation_error_rad"]), p50 * 1e3, p99 * 1e3)


@dataclass(frozen=True)
class BagCheck:
    """A bag closed by a signal, against the reference bag of the same run."""

    readable: bool
    messages: int
    expected: int  # reference /joint_states stamped between the bag's first one and the signal - 1 ms
    missing: int
    detail: str

    def text(self) -> str:
        return (f"{'readable' if self.readable else 'NOT readable'}, {self.messages} messages decoded, "
                f"{self.expected - self.missing}/{self.expected} joint states up to the signal{self.detail}")


SIGNAL_MARGIN_NS = 1_000_000


def check_signalled_bag(bag: Path, reference: GraphStreams, signal_ns: int) -> BagCheck:
    """Every /joint_states of the reference stamped from the bag's first to 1 ms before the signal is in the bag."""
    try:
        reader = open_reader(bag)
    except BagError as exc:
        return BagCheck(False, 0, 0, 0, f": {exc}")
    stamps: set[int] = set()
    decoded = 0
    try:
        for conn, _, raw in reader.messages():
            msg: Any = reader.deserialize(raw, conn.msgtype)
            decoded += 1
            if conn.topic == "/joint_states":
                stamps.add(stamp_ns(msg.header.stamp))
    except Exception as exc:  # noqa: BLE001 - a damaged bag is the finding: report it, do not crash the matrix
        return BagCheck(False, decoded, 0, 0, f": {type(exc).__name__}: {exc}")
    finally:
        reader.close()
    if not stamps:
        return BagCheck(True, decoded, 0, 0, ": no /joint_states in the bag")
    first = min(stamps)
    expected = {s for s in reference.state_stamp if first <= s <= signal_ns - SIGNAL_MARGIN_NS}
    return BagCheck(True, decoded, len(expected), len(expected - stamps), "")
