"""The fault matrix's row names (docs/safety.md), apart from the matrix itself: ``dualarm --help`` lists them
without importing what runs them (pinocchio, rosbags, the cell)."""

from __future__ import annotations

COMMAND_TIMEOUT_STEPS = 10  # sim_node command_timeout 0.05 s / 5 ms
LOOPBACK_ROWS = ("stale_states", "target_stopped", "kill_sim", "kill_controller", "recorder_sigint",
                 "recorder_sigterm")
PROFILE_KILLS = {"kill_controller_velocity_profile": ("ros2_control_velocity", COMMAND_TIMEOUT_STEPS + 3),
                 "kill_controller_position_profile": ("lbr_dual_position", 3)}
"""Controller kills on the shipped hardware profiles (app/faults/profile_kills.py): profile, at rest within steps."""
ROWS = (*LOOPBACK_ROWS, *PROFILE_KILLS, "best_effort_loss", "across_hosts", "link_cut", "link_netem",
        "goal_into_collision")
