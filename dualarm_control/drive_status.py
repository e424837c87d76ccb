"""The drive's states and its status keys: what the online generator and the trajectory node report.

The generator's states (:data:`IDLE` at rest without a goal, :data:`MOVING` toward a goal,
:data:`JOGGING` following or braking from a twist, :data:`REACHED` at rest exactly on the last goal;
:class:`~dualarm_control.online_trajectory.OnlineTrajectory`), the node-level ones
(:data:`STALLED`, :data:`REJECTED`), :class:`GoalProgress`, and the ``/diagnostics`` keys that carry
them, defined in one place (:func:`status_values`, :func:`parse_status`).
"""

from __future__ import annotations

from dataclasses import dataclass

IDLE = "idle"
MOVING = "moving"
JOGGING = "jogging"
REACHED = "reached"
STATES = (IDLE, MOVING, JOGGING, REACHED)


@dataclass(frozen=True)
class GoalProgress:
    """The generator's state for status reports.

    Attributes:
        state: one of :data:`STATES`.
        goal_stamp: stamp [s] of the current goal (None: no goal, or not stamped).
        distance: ||p_g - p|| [m] (0 without a goal).
        angle: rotation angle of ``R_g R^T`` [rad] in [0, pi] (0 without a goal).
        time_to_go: time [s] until the goal is reached at rest, per the current plan
            (0 without a goal; for a jog: until at rest once braking).
    """

    state: str
    goal_stamp: float | None
    distance: float
    angle: float
    time_to_go: float


STALLED = "stalled"
"""Node-level state: the controller cannot follow (joint limits); set by the node, not here."""
REJECTED = "rejected"
"""Node-level state: the last command was refused (``reason`` says why); the motion goes on."""
DRIVE_STATES = (*STATES, STALLED, REJECTED)

STATUS_NAME = "trajectory_node"
"""``/diagnostics`` status name carrying the drive keys (the trajectory node's entry)."""
ABSOLUTE_STATUS_NAME = "trajectory_node/absolute"
"""``/diagnostics`` status name carrying the drive keys of the absolute frame's goals (issue 41)."""
KEY_STATE = "drive_state"
KEY_GOAL_STAMP = "goal_stamp"  # s, "%.9f" (the last goal received, accepted or not)
KEY_DISTANCE = "distance_m"
KEY_ANGLE = "angle_rad"
KEY_TIME_TO_GO = "time_to_go_s"
KEY_REASON = "reason"
STATUS_KEYS = (KEY_STATE, KEY_GOAL_STAMP, KEY_DISTANCE, KEY_ANGLE, KEY_TIME_TO_GO, KEY_REASON)


def status_values(progress: GoalProgress, state: str | None = None, reason: str = "",
                  goal_stamp: float | None = None) -> dict[str, str]:
    """The drive keys of the ``/diagnostics`` status (strings, as diagnostic_msgs/KeyValue holds them).

    ``state`` overrides the generator's state (the node's :data:`STALLED` / :data:`REJECTED`);
    ``goal_stamp`` the goal's stamp (a rejected goal's own stamp).
    """
    stamp = goal_stamp if goal_stamp is not None else progress.goal_stamp
    return {KEY_STATE: state or progress.state, KEY_GOAL_STAMP: "" if stamp is None else f"{stamp:.9f}",
            KEY_DISTANCE: f"{progress.distance:.6f}", KEY_ANGLE: f"{progress.angle:.6f}",
            KEY_TIME_TO_GO: f"{progress.time_to_go:.3f}", KEY_REASON: reason}


def parse_status(values: dict[str, str]) -> tuple[GoalProgress, str] | None:
    """Inverse of :func:`status_values`: ``(progress, reason)``, or None if the keys are absent/malformed."""
    try:
        stamp = values[KEY_GOAL_STAMP]
        progress = GoalProgress(values[KEY_STATE], float(stamp) if stamp else None, float(values[KEY_DISTANCE]),
                                float(values[KEY_ANGLE]), float(values[KEY_TIME_TO_GO]))
    except (KeyError, ValueError):
        return None
    return progress, values.get(KEY_REASON, "")
