"""QoS of the cell's periodic streams (joint states, commands, targets).

``qos_reliability`` (read-only, every node): ``reliable`` (the default, rclpy's) or
``best_effort`` (sensor-like: a lost sample is not re-sent; the next one supersedes it).
A best-effort subscription also matches a reliable publisher, not the other way round, so
all nodes of a cell should use the same value. /diagnostics and /clock stay reliable.
"""

from __future__ import annotations

from typing import Any

from dualarm_control.params import ParamSpec

RELIABILITIES = ("reliable", "best_effort")
STREAM_DEPTH = 10
LOCKSTEP_DEPTH = 10000
"""History of every per-cycle publisher in lockstep mode. A keep-last writer drops its oldest
sample when its history is full, acknowledged or not, and in lockstep the cell runs as fast as
the simulator and controller answer each other: a recorder starved for more than 10 samples
(about 25 ms of a lockstep run on a loaded machine) lost joint states (test_task_nodes under
``stress-ng --cpu 1``), and a demo recorder 1300 samples behind at the end lost the run's end
with 1000. 10000 samples, as the recorder's own depth, is 50 s of simulated time at 200 Hz (a few
MB per writer)."""

QOS_PARAMETER = ParamSpec(
    "qos_reliability", "reliable",
    "reliability of the periodic streams (joint states, commands, targets): reliable or best_effort",
    choices=lambda: list(RELIABILITIES), read_only=True)


def publisher_depth(lockstep: bool) -> int:
    """Keep-last depth of a node's per-cycle publishers: :data:`LOCKSTEP_DEPTH` in lockstep mode,
    else :data:`STREAM_DEPTH` (in real time the newest sample is what counts)."""
    return LOCKSTEP_DEPTH if lockstep else STREAM_DEPTH


def stream_qos(reliability: str, depth: int = STREAM_DEPTH) -> Any:
    """The rclpy QoSProfile of a periodic stream: keep-last ``depth``, volatile, ``reliability``."""
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    policy = ReliabilityPolicy.BEST_EFFORT if reliability == "best_effort" else ReliabilityPolicy.RELIABLE
    return QoSProfile(depth=depth, reliability=policy)


def latched_qos() -> Any:
    """The QoS of ``/robot_description`` as robot_state_publisher offers it: keep-last 1, reliable,
    transient local (a reader that joins later still gets the last message)."""
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    return QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
