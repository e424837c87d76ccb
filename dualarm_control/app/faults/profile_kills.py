"""The controller killed on each shipped hardware profile (issue 40 item 5; rows of ``dualarm faults``).

What stops the arms when the controller dies depends on what it commands: on
``config/hardware/ros2_control_velocity.yaml`` a joint trajectory controller whose ``cmd_timeout`` (0.05 s)
holds the arms once no new point comes (the simulator stops them after its ``command_timeout`` of the same
length); on ``config/hardware/lbr_dual_position.yaml`` the last position command, which the forward position
controllers keep. Each row runs the cell in real time on the profile (its topics recorded with
``/dualarm/cell``, so the bag is read through the profile), kills the controller mid-motion and counts the
simulator steps from its last command's arrival to the first state at rest
(:func:`~dualarm_control.app.faults.episodes.arm_stop`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

from dualarm_control.app.faults.cell_run import RECORDED, CellRun, RunError
from dualarm_control.app.faults.matrix import (
    PROFILE_KILLS,
    Row,
    _failed,
    _kill_controller,
    _stop_row,
)
from dualarm_control.paths import config_path


def profile_file(profile: str) -> Path:
    return config_path("hardware", f"{profile}.yaml")


def recorded_topics(profile: Path, scenario: str) -> tuple[str, ...]:
    """The fault run's topics with the profile's joint-state and command topics in place of the default ones."""
    from dualarm_control.app.run.launcher import with_profile_topics
    from dualarm_control.cell_robot import cell_robot
    from dualarm_control.scenario import load_scenario

    robot, _ = cell_robot([profile], None)
    return with_profile_topics(RECORDED, [str(profile)], load_scenario(scenario, robot).robot.joint_names)


KILL_STALE_TIMEOUT = 0.05
"""s: the controller's ``stale_timeout`` in these rows (default 0.015 s). The row is about the arms' stop after the
kill, and it kills only while the controller is out of its safe state (``_kill_controller``); on a loaded 2-core
machine (and on a slower one quiet, 2026-12-07) 15-30 ms gaps in the two joint-state topics of lbr_dual_position
tripped the default watchdog 8-20 times in the 3.7 s move, and no 1.5 s window of motion was left to kill in (the
same with either Fast DDS transport: 1 of 3 runs each). The watchdog itself has its own rows (``stale_states``)."""


def kill_row(out: Path, scenario: str, name: str, profile: Path, steps: int, say: Callable[[str], None]) -> Row:
    """Row ``name``: the cell in real time on ``profile``, the controller killed mid-motion, at rest within ``steps``?"""
    run = CellRun(out / name, scenario, ["--params-file", str(profile), "-p",
                                         f"controller_node:stale_timeout:={KILL_STALE_TIMEOUT}"],
                  topics=recorded_topics(profile, scenario))
    try:
        say(f"{name}: the cell on {profile.name}")
        run.start()
        killed = _kill_controller(run, name, say)
    except RunError as exc:
        run.stop()
        return _failed([name], str(exc))[0]
    run.stop()
    return _stop_row(name, run.record(), killed, steps)


def profile_kill_rows(out: Path, scenario: str, only: Sequence[str], say: Callable[[str], None]) -> list[Row]:
    """One real-time run per selected profile row (:data:`~dualarm_control.app.faults.matrix.PROFILE_KILLS`)."""
    return [kill_row(out, scenario, name, profile_file(profile), steps, say)
            for name, (profile, steps) in PROFILE_KILLS.items() if name in only]
