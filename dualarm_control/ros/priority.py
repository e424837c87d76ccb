"""SCHED_FIFO for a node's control thread, like ros2_control's ``thread_priority``: the parameter, the
permission check before the node starts (:func:`request_realtime_priority`), and the priority given to
every thread right before spinning (:func:`apply_priority`)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from dualarm_control.errors import DualArmError
from dualarm_control.params import ParamSpec, params_files, read_params_files


def thread_priority_spec(default: int, what: str) -> ParamSpec:
    """The ``thread_priority`` parameter of a node whose ``what`` runs every control period."""
    return ParamSpec("thread_priority", default, f"SCHED_FIFO priority of {what} (0: normal scheduling)",
                     check=lambda v: "" if 0 <= v <= 99 else "an integer in [0, 99]", read_only=True, bounds=(0, 99))


def log_priority(log: Any, note: str, priority: int) -> None:
    """Log the outcome of :func:`request_realtime_priority` (``note``: '' granted, "disabled", or why not)."""
    if note and note != "disabled":
        log.warning(note)
    elif not note:
        log.info(f"running under SCHED_FIFO priority {priority}")


def priority_from_args(argv: Sequence[str], default: int, node_name: str) -> int:
    """``thread_priority`` as the node will declare it, read before rclpy exists (its permission is
    checked before the node starts): ``-p thread_priority:=N`` in ``argv`` wins
    over the node's entry in ``--params-file`` files (later files win), as in ROS 2 (also
    ``-p NODE:thread_priority:=N``, rcl's node-scoped form, which the container's command uses); ``default``
    when absent or malformed (:func:`declare` then reports a malformed value with exit 2)."""
    priority = default
    try:
        value = read_params_files(params_files(argv), node_name).get("thread_priority", default)
    except (DualArmError, OSError, ValueError):  # a bad file is reported by run() with exit 2
        value = default
    if isinstance(value, int) and not isinstance(value, bool):
        priority = value
    for i, arg in enumerate(argv[:-1]):
        if arg == "-p" and argv[i + 1].startswith(("thread_priority:=", f"{node_name}:thread_priority:=")):
            try:
                priority = int(argv[i + 1].split(":=", 1)[1])
            except ValueError:
                pass
    return priority


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
