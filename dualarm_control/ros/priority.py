"""SCHED_FIFO for a node's control thread, like ros2_control's ``thread_priority``: the parameter, the
permission check before the node starts (:func:`request_realtime_priority`), and the priority given to
every thread right before spinning (:func:`apply_priority`)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import yaml

from dualarm_control.errors import DualArmError
from dualarm_control.params import ParamSpec, params_files, read_params_files


def thread_priority_spec(default: int, what: str) -> ParamSpec:
    """The ``thread_priority`` parameter of a node whose ``what`` runs every control period."""
    return ParamSpec("thread_priority", default, f"SCHED_FIFO priority of {what} (0: normal scheduling)",
                     check=lambda v: "" if 0 <= v <= 99 else "an integer in [0, 99]", read_only=True, bounds=(0, 99))


def log_priority(log: Any, note: str, priority: int) -> None:
    """Log the outcome of :func:`request_realtime_priority` (``note``: '' granted, "disabled", or why not)."""
    if note == LOCKSTEP_NOTE:
        log.info(note)
    elif note and note != "disabled":
        log.warning(note)
    elif not note:
        log.info(f"running under SCHED_FIFO priority {priority}")


def early_parameter(argv: Sequence[str], name: str, default: Any, node_name: str) -> Any:
    """Parameter ``name`` as the node will declare it, read before rclpy exists: ``-p name:=V`` in ``argv``
    (also ``-p NODE:name:=V``, rcl's node-scoped form, which the container's command uses) wins over the
    node's entry in ``--params-file`` files (later files win), as in ROS 2; the value read as YAML.
    ``default`` when absent or malformed (:func:`~dualarm_control.ros.node.declare` then reports a
    malformed value with exit 2)."""
    try:
        value = read_params_files(params_files(argv), node_name).get(name, default)
    except (DualArmError, OSError, ValueError):  # a bad file is reported by run() with exit 2
        value = default
    for i, arg in enumerate(argv[:-1]):
        if arg == "-p" and argv[i + 1].startswith((f"{name}:=", f"{node_name}:{name}:=")):
            try:
                value = yaml.safe_load(argv[i + 1].split(":=", 1)[1])
            except yaml.YAMLError:
                pass
    return value


def priority_from_args(argv: Sequence[str], default: int, node_name: str) -> int:
    """``thread_priority`` as the node will declare it (:func:`early_parameter`: its permission is checked
    before the node starts); ``default`` when absent or not an integer."""
    value = early_parameter(argv, "thread_priority", default, node_name)
    return value if isinstance(value, int) and not isinstance(value, bool) else default


LOCKSTEP_NOTE = "lockstep: normal scheduling (a lockstep run keeps no deadline; under SCHED_FIFO it would take the cores)"


def node_scheduling(argv: Sequence[str], default: int, node_name: str) -> PriorityRequest:
    """The scheduling a node process asks for at start: SCHED_FIFO ``thread_priority`` in real time
    (:func:`request_realtime_priority`); normal scheduling in lockstep (``lockstep:=true``), whatever
    ``thread_priority`` says: a lockstep run waits for no clock and runs as fast as the cores go, so
    under SCHED_FIFO its busy processes take the cores from every other process of the machine."""
    if early_parameter(argv, "lockstep", False, node_name) is True:
        return PriorityRequest(0, LOCKSTEP_NOTE)
    return request_realtime_priority(priority_from_args(argv, default, node_name))


@dataclass(frozen=True)
class PriorityRequest:
    """The outcome of :func:`request_realtime_priority`.

    Attributes:
        granted: the SCHED_FIFO priority :func:`run` gives every thread before spinning (0: none).
        note: '' when granted, "disabled" (``thread_priority`` 0), else why not (the node warns).
    """

    granted: int
    note: str


def request_realtime_priority(priority: int) -> PriorityRequest:
    """Ask for SCHED_FIFO ``priority`` (1-99) for this process, like ros2_control's ``thread_priority``.

    The permission is checked now (on this thread, then restored); :func:`run` applies the
    priority to every thread of the process, the middleware's included, once the node is built
    and right before it spins. Start-up (imports, participant, node) runs under normal
    scheduling: a node starting under SCHED_FIFO while another one still started took its
    first /joint_states 0.05-0.5 s after being up instead of 3-30 ms (docs/bench.md, "Start-up").
    """
    import os

    if priority <= 0:
        return PriorityRequest(0, "disabled")
    try:
        policy, param = os.sched_getscheduler(0), os.sched_getparam(0)
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(min(priority, 99)))
        os.sched_setscheduler(0, policy, param)
    except (AttributeError, PermissionError, OSError) as exc:
        return PriorityRequest(0, f"SCHED_FIFO {priority} not permitted ({exc}); running with normal priority")
    return PriorityRequest(min(priority, 99), "")


def apply_priority(priority: int) -> None:
    """Put every thread of this process under SCHED_FIFO ``priority`` (threads created later inherit
    it); nothing for 0."""
    import os

    if priority <= 0:
        return
    try:
        threads = [int(tid) for tid in os.listdir("/proc/self/task")]
    except OSError:
        threads = [0]
    for tid in threads:
        try:
            os.sched_setscheduler(tid, os.SCHED_FIFO, os.sched_param(priority))
        except (ProcessLookupError, PermissionError, OSError):
            pass  # a thread that ended meanwhile
