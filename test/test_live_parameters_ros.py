"""Live parameter changes keep the controller's state (issue 25), over ROS as a user makes them.

``dualarm launch`` (three node processes, lockstep, recorded) on a motion back and forth, with the
standard QP and the acceleration bound of config/acceleration_limit.yaml; while the cell moves,
four ``dualarm param set /controller_node gain X`` and one ``... solver sparse_qp``. From the
bag's /velocity_controller/commands the largest per-cycle change must stay within a_max = 10
rad/s^2 (before issue 25 it was 21 rad/s^2: each change restarted the command from rest). The
run is ended by Ctrl-C once the changes have landed (the motion lasts minutes, so the changes
are made during it however slowly the tools start); the bag holds everything up to then.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from test_ros_live import Launch, dualarm

from dualarm_control.app.record.bag import COMMANDS_TOPIC, read_bag

REPO = Path(__file__).resolve().parents[1]
SCENARIO = Path(__file__).parent / "data" / "back_and_forth.yaml"
A_MAX = 10.0  # rad/s^2, config/acceleration_limit.yaml
PERIOD = 0.005
ROUNDING = 1e-6  # rad/s^2: the back-end's bound tolerance (1e-9 rad/s) over T; float64 in the bag is exact
CHANGES = (("gain", "8.0"), ("gain", "12.0"), ("gain", "6.0"), ("gain", "10.0"), ("solver", "sparse_qp"))
MOVING = 0.05  # rad/s: the largest joint command just before a change is above this (a_max T)


def test_live_changes_keep_the_acceleration_bound(tmp_path: Path) -> None:
    bag_path = tmp_path / "bag"
    launch = Launch(str(SCENARIO), "--lockstep", "--params", str(REPO / "config/solvers/standard_qp.yaml"),
                    "--params", str(REPO / "config/acceleration_limit.yaml"), "--record", str(bag_path))
    try:
        launch.wait_for("segment 2/40", timeout=120.0)  # moving, the recorder running
        for name, value in CHANGES:
            out = dualarm("param", "set", "/controller_node", name, value, "--timeout", "120", timeout=300)
            assert out.returncode == 0 and out.stdout.strip() == "Set parameter successful", out.stdout + out.stderr
        launch.wait_for("solver='sparse_qp'", timeout=120.0)  # the last change has landed
    finally:
        launch.kill()
    log = "\n".join(launch.lines)
    assert log.count("parameters changed at cycle") == len(CHANGES), log[-3000:]

    bag = read_bag(bag_path)
    commands = np.array([row for _, row in bag.rows[COMMANDS_TOPIC]])
    t_commands = np.array([t for t, _ in bag.rows[COMMANDS_TOPIC]])
    assert len(commands) > 1000, f"{len(commands)} commands in the bag"
    steps = np.abs(np.diff(commands, axis=0)).max(axis=1) / PERIOD
    worst = int(steps.argmax())
    assert steps[worst] <= A_MAX + ROUNDING, (
        f"{steps[worst]:.4f} rad/s^2 between commands {worst} and {worst + 1} of {len(commands)}")

    # every change landed while the arms were moving: find each switch in /diagnostics
    switches = [(t, int(v["parameter_switches"])) for t, v in bag.cycles if "parameter_switches" in v]
    landed = [t for (t, n), (_, before) in zip(switches[1:], switches[:-1], strict=True) if n > before]
    assert len(landed) == len(CHANGES), f"switches seen in the bag at {landed}"
    for t in landed:
        k = int(np.searchsorted(t_commands, t)) - 1  # the command of the cycle the change landed in
        assert np.abs(commands[k - 1]).max() > MOVING, f"at rest before the change at command {k}"
