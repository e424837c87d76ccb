"""controller_node's parts without a node (dualarm_control/nodes/: task_clock, startup_wait, controller_inputs,
controller_status, controller_params): the texts and decisions the node reports, one case each. The node
itself runs in test_controller_waits.py, test_ros_live.py, test_task_nodes.py and test_fuzz.py."""

from __future__ import annotations

import time
from types import SimpleNamespace
from typing import Any

import numpy as np

from dualarm_control.errors import InputRejected
from dualarm_control.hardware import StateAssembler
from dualarm_control.nodes.controller_inputs import ControllerInputs, stream_sample
from dualarm_control.nodes.controller_setup import acceleration_text
from dualarm_control.nodes.startup_wait import StartupWait
from dualarm_control.nodes.task_clock import TaskClock
from dualarm_control.references.base import JOINT_REFERENCE, RELATIVE_TARGET, WRENCH

MS = 1_000_000


class Out:
    """What ControllerInputs asks of the node's CommandOutput, recorded."""

    def __init__(self) -> None:
        self.calls: list[tuple[str, int, str]] = []

    def reject(self, stamp: int, reason: str) -> None:
        self.calls.append(("reject", stamp, reason))

    def report(self, stamp: int, reason: str, status: str) -> None:
        self.calls.append((status, stamp, reason))

    def safe(self, stamp: int, reason: str) -> None:
        self.calls.append(("safe", stamp, reason))

    def enter_safe_state(self, stamp: int, reason: str) -> None:
        self.calls.append(("enter_safe_state", stamp, reason))


def guard(streams: tuple[str, ...], lockstep: bool = False) -> tuple[ControllerInputs, Out, list[int]]:
    out, cycles = Out(), []
    values = {"stale_timeout": 0.015, "target_timeout": 0.05}
    inputs = ControllerInputs(streams, lockstep, out, SimpleNamespace(warning=lambda text: None), lambda: values,
                              StateAssembler(("/joint_states",), 14, 0), lambda: cycles.append(1))
    return inputs, out, cycles


def test_task_clock_waits_for_readers_in_real_time_then_counts_steps() -> None:
    clock = TaskClock(steps=3, period=0.005, lockstep=False, readers=1)
    assert clock.waiting(lambda: 0) == "waiting for 1 /diagnostics reader(s) before the task starts"
    assert clock.waiting(lambda: 1) == ""
    assert clock.time(10 * MS) == 0.0
    assert clock.waiting(lambda: 0) == ""  # started: the readers are not asked again
    assert clock.time(12 * MS) == 0.002  # real time: from the stamps
    assert clock.time(25 * MS) is None  # step 3 of 3: over
    lockstep = TaskClock(steps=3, period=0.005, lockstep=True, readers=1)
    assert lockstep.waiting(lambda: 0) == ""
    assert lockstep.time(0) == 0.0 and lockstep.time(6 * MS) == 0.005  # k T


def test_startup_wait_says_why_and_turns_to_an_error_past_its_deadline() -> None:
    wait = StartupWait(0.0)
    assert not wait.checking and not wait.expired
    assert wait.waiting(lambda: "no publisher on /joint_states") == (
        "waiting for joint_states: no publisher on /joint_states", False)
    wait.started -= 11.0
    assert wait.waiting(lambda: "") == (
        "waiting for joint_states: no publisher on /joint_states (none consistent after 10 s)", True)  # asked 1/s
    checked = StartupWait(0.5)
    assert checked.checking and not checked.expired
    checked.check_deadline = time.monotonic() - 1.0
    assert checked.expired
    checked.matched()
    assert not checked.checking and not checked.expired


def test_inputs_reject_with_the_stream_and_keep_the_last_valid_sample() -> None:
    inputs, out, cycles = guard((RELATIVE_TARGET,), lockstep=True)
    inputs.put(RELATIVE_TARGET, 5, "target at 5")
    inputs.rejected(RELATIVE_TARGET, InputRejected("relative_target contains NaN or inf", stamp=6))
    inputs.put(RELATIVE_TARGET, 4, "older")
    assert out.calls == [("reject", 6, "relative_target rejected: relative_target contains NaN or inf"),
                         ("reject", 4, ("relative_target stamp 0.000 s is older than the last accepted 0.000 s "
                                        "(non-monotonic)"))]
    assert cycles == [1] and inputs.for_cycle(5) == {RELATIVE_TARGET: "target at 5"}


def test_a_message_input_decodes_or_reports_the_rejection_at_the_message_stamp() -> None:
    inputs, out, _ = guard((WRENCH,))

    def decode(msg: Any) -> np.ndarray:
        if msg.bad:
            raise InputRejected("wrench has non-finite values", stamp=7)
        return np.zeros(6)

    receive = inputs.message_input(WRENCH, decode)
    stamp = SimpleNamespace(header=SimpleNamespace(stamp=SimpleNamespace(sec=0, nanosec=8)))
    receive(SimpleNamespace(bad=True, **vars(stamp)))
    receive(SimpleNamespace(bad=False, **vars(stamp)))
    assert out.calls == [("reject", 7, "wrench rejected: wrench has non-finite values")]
    assert WRENCH in inputs.samples.latest


def test_real_time_watchdogs_stale_state_and_a_target_stopped_mid_motion() -> None:
    inputs, out, _ = guard((RELATIVE_TARGET, JOINT_REFERENCE))
    assert inputs.fresh(1) is None and out.calls == [("safe", 1, "waiting for relative_target")]
    now = time.monotonic_ns()
    assert inputs.watchdog(now, now - 20 * MS) == "joint_states stale by 20.0 ms"
    moving = SimpleNamespace(speed=0.1)
    inputs.samples.latest = {RELATIVE_TARGET: (moving, now - 60 * MS), JOINT_REFERENCE: ((0, 0, np.zeros(14)), now)}
    assert inputs.target_fault(now) == ""  # the joint reference is fresh
    inputs.samples.latest[JOINT_REFERENCE] = ((0, 0, np.zeros(14)), now - 60 * MS)
    assert inputs.watchdog(now, now).startswith("joint_reference stopped mid-motion: none for 60.")
    inputs.samples.latest[RELATIVE_TARGET] = (SimpleNamespace(speed=0.0), now - 60 * MS)
    assert inputs.target_fault(now) == ""  # a stream that stopped at rest is no fault


def test_stream_sample_pairs_the_target_with_the_joint_reference() -> None:
    q, qd = np.ones(14), np.zeros(14)
    sample = stream_sample({RELATIVE_TARGET: "target", JOINT_REFERENCE: (3, q, qd)})
    assert sample is not None and sample.relative == "target" and sample.joints is not None
    assert stream_sample({WRENCH: np.zeros(6)}) is None


def test_acceleration_text_names_the_bound() -> None:
    assert acceleration_text(()) == "no joint acceleration bound (acceleration_limit: [0.0])"
    assert acceleration_text((10.0,)) == "joint acceleration bound 10 rad/s^2 on every joint"
