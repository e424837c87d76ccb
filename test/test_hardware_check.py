"""``dualarm hardware check`` on a live graph (issue 29): the simulator speaking a profile, checked with
that profile (exit 0) and with another one (exit 1, one line per problem naming the topic)."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from waiting import node_env

HARDWARE = Path(__file__).parents[1] / "config" / "hardware"
CHECK_TIMEOUT_S = "20"  # the check answers as soon as the graph matches; discovery took up to ~4 s here


def dualarm(*args: str, timeout: float = 120.0) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "dualarm_control.app.cli", *args], capture_output=True, text=True,
                          timeout=timeout, check=False)


@pytest.fixture(scope="module")
def lbr_sim() -> Iterator[None]:
    """The simulator in real time on the lbr_dual_position profile (no controller: it holds the arms)."""
    proc = subprocess.Popen([sys.executable, "-m", "dualarm_control.app.cli", "run", "sim_node", "--ros-args",
                             "--params-file", str(HARDWARE / "lbr_dual_position.yaml")],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, env=node_env())
    try:
        yield
    finally:
        proc.terminate()
        try:
            proc.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.communicate()


def test_the_profile_the_simulator_speaks_can_run(lbr_sim: None) -> None:
    result = dualarm("hardware", "check", "--params", str(HARDWARE / "lbr_dual_position.yaml"),
                     "--timeout", CHECK_TIMEOUT_S)
    assert result.returncode == 0, result.stdout + result.stderr
    out = result.stdout
    assert "joint states /left/joint_states: publishers /sim_node [sensor_msgs/msg/JointState]" in out, out
    assert ("command /right/forward_position_controller/commands (position, 7 joints): subscribers /sim_node "
            "[std_msgs/msg/Float64MultiArray]; publishers none") in out, out
    assert "joints matched: 14 of 14" in out, out
    assert out.rstrip().endswith("the profile can run"), out


def test_another_profile_is_refused_with_one_line_per_problem(lbr_sim: None) -> None:
    result = dualarm("hardware", "check", "--params", str(HARDWARE / "ros2_control_velocity.yaml"),
                     "--timeout", "5")
    assert result.returncode == 1, result.stdout + result.stderr
    problems = [line for line in result.stdout.splitlines() if line.startswith("problem: ")]
    assert problems == ["problem: no publisher on /joint_states",
                        "problem: no subscriber on /arms_trajectory_controller/joint_trajectory"], result.stdout
