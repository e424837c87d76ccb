"""How the fault matrix judges a run (dualarm_control/app/faults/episodes.py), on synthetic records."""

from __future__ import annotations

import math

from dualarm_control.app.faults.episodes import (
    GraphStreams,
    Status,
    arm_stop,
    completion,
    safe_episode,
)

MS = 1_000_000


def cycle(t: int, watchdog: str = "ok", trips: int = 0) -> Status:
    return Status(t, "controller_node", 0, "solved", {"state_interval_s": "5e-3", "watchdog": watchdog, "watchdog_trips": str(trips),
                                   "cycles": "1", "position_error_m": "1e-5", "orientation_error_rad": "1e-4",
                                   "state_to_command_latency_s": "1e-3"})


def test_safe_episode_figures() -> None:
    rec = GraphStreams()
    rec.controller = [cycle(0), Status(120 * MS, "controller_node", 2, "joint_states stale by 16.2 ms", {"watchdog_trips": "1"}),
                      cycle(620 * MS, trips=1)]
    rec.command_t = [10 * MS, 125 * MS, 200 * MS, 300 * MS, 630 * MS]
    rec.command_max = [0.3, 0.2, 0.0, 0.0, 0.4]  # 125 ms: within 10 ms of the ERROR, not counted
    ep = safe_episode(rec, 100 * MS, 600 * MS, "joint_states stale")
    assert ep.detected_ms == 20.0 and ep.age_ms == 16.2
    assert (ep.zero_commands, ep.other_commands) == (2, 0)
    assert ep.recovered_ms == 20.0 and ep.trips == 1


def test_safe_episode_without_error_is_nan() -> None:
    rec = GraphStreams(controller=[cycle(0), cycle(5 * MS)])
    ep = safe_episode(rec, 1 * MS, 3 * MS, "joint_states stale")
    assert math.isnan(ep.detected_ms) and ep.zero_commands == 0


def test_arm_stop_counts_steps_from_the_last_answered_state() -> None:
    stamps = [k * 5 * MS for k in range(30)]
    speeds = [0.2] * 12 + [0.1] * 10 + [1e-4] * 8  # last answered state: index 9; rest from index 22
    rec = GraphStreams(state_stamp=stamps, state_speed=speeds, pose_stamp=stamps[:10])
    stop = arm_stop(rec, 0)
    assert stop.speed_at_last == 0.2 and stop.steps == 13 and stop.wall_ms == 65.0


def test_arm_stop_counts_from_a_late_commands_arrival() -> None:
    """A loaded controller answered state 9 with a command that arrived at state 14: the simulator's
    timeout counts from there (the controller's lag is reported, not charged to the simulator)."""
    stamps = [k * 5 * MS for k in range(30)]
    speeds = [0.2] * 12 + [0.1] * 10 + [1e-4] * 8
    rec = GraphStreams(state_stamp=stamps, state_speed=speeds, pose_stamp=stamps[:10],
                       command_t=[s + MS for s in stamps[:9]] + [stamps[14] - MS // 2])
    stop = arm_stop(rec, 0)
    assert (stop.late_steps, stop.steps, stop.wall_ms) == (5, 8, 40.0)
    assert "8 steps = 40 ms sim time" in stop.text(0.005) and "(5 steps after the last state" in stop.text(0.005)


def test_arm_stop_counts_from_the_simulators_arrival_not_a_starved_recorders() -> None:
    """A recorder starved for 2 s received the last command after every state it then recorded (the CI
    failure of 2026-12-07: 'never at rest'); the simulator's own figure (``last_command_ns``, in its
    states' stamp clock) puts the arrival at state 14: at rest 8 steps later."""
    stamps = [k * 5 * MS for k in range(30)]
    speeds = [0.2] * 12 + [0.1] * 10 + [1e-4] * 8
    late = [stamps[-1] + 2000 * MS]
    starved = GraphStreams(state_stamp=stamps, state_speed=speeds, pose_stamp=stamps[:10], command_t=late)
    assert arm_stop(starved, 0).steps == -1  # the receive time alone: no state after it
    sim = [Status(t, "sim_node", 0, "running", {"last_command_ns": str(c)})
           for t, c in ((stamps[5], stamps[4] + MS), (late[0], stamps[13] + MS))]
    rec = GraphStreams(state_stamp=stamps, state_speed=speeds, pose_stamp=stamps[:10], command_t=late, sim=sim)
    stop = arm_stop(rec, 0)
    assert (stop.late_steps, stop.steps) == (5, 8), stop


def test_arm_stop_never_at_rest() -> None:
    """Never at rest: the row says how many states came after the last command and over how long, so that a
    simulator that stopped stepping (one state in a second; seen 2026-12-07) reads apart from one still moving."""
    stamps = [k * 5 * MS for k in range(5)]
    rec = GraphStreams(state_stamp=stamps, state_speed=[0.2] * 5, pose_stamp=stamps[:2])
    stop = arm_stop(rec, 0)
    assert (stop.steps, stop.states_after, stop.span_ms) == (-1, 4, 15.0), stop
    assert "in the 4 states recorded after its last command (15 ms of state stamps)" in stop.text(0.005)


def test_completion_reads_the_last_cycle() -> None:
    rec = GraphStreams(controller=[cycle(0), cycle(5 * MS)],
                    trajectory=[Status(6 * MS, "trajectory_node", 0, "complete", {})])
    done = completion(rec)
    assert done.complete and done.position_error_m == 1e-5 and done.latency_p50_ms == 1.0
