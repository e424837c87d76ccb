"""controller_node with a solver that ignores its bounds (issue 20): the failure reaches /diagnostics.

Real processes on this session's private domain: sim_node and trajectory_node as launched, and
controller_node with test/bound_ignoring.py's solver in its registry (``python -m bound_ignoring``).
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import yaml
from bound_ignoring import NAME
from waiting import wait_for_line

from dualarm_control.app.run.launcher import Launch, node_command

TEST_DIR = Path(__file__).resolve().parent
SLOW = TEST_DIR / "data" / "slow.yaml"


def controller_diagnostics(count: int) -> list[tuple[int, dict[str, str]]]:
    """The next ``count`` /diagnostics statuses of controller_node: (level, {key: value})."""
    out = subprocess.run([sys.executable, "-m", "dualarm_control.app.cli", "topic", "echo", "/diagnostics", "-n",
                          str(count), "--timeout", "30"], capture_output=True, text=True, timeout=120, check=True)
    return [(int(s["level"]), {kv["key"]: str(kv["value"]) for kv in s["values"]})
            for doc in yaml.safe_load_all(out.stdout) if doc for s in doc["status"] if s["name"] == "controller_node"]


def test_bounds_violations_reach_diagnostics() -> None:
    """Each cycle of the bound-ignoring solver is status "bounds_violated" on /diagnostics (level ERROR),
    counted by ``bounds_violations`` and ``solver_failures`` (not as fallbacks); the node logs the joint
    and the excess, and counts every cycle as a failure when it stops."""
    launch = Launch(echo=False)
    scenario = ["-p", f"scenario:={SLOW}"]
    path = os.pathsep.join(filter(None, (str(TEST_DIR), os.environ.get("PYTHONPATH"))))
    try:
        launch.start("sim_node", node_command("sim_node", scenario))
        launch.start("trajectory_node", node_command("trajectory_node", scenario))
        controller = launch.start("controller_node", [sys.executable, "-u", "-m", "bound_ignoring", "--ros-args",
                                                      "-p", f"solver:={NAME}"], env={"PYTHONPATH": path})
        wait_for_line(controller.lines, "solver bounds_violated", controller.popen, name="controller_node")
        statuses = controller_diagnostics(5)
    finally:
        launch.stop()
    violations = [(level, v) for level, v in statuses if v["status"] == "bounds_violated"]
    assert violations, statuses
    for level, values in violations:
        assert level == 2 and values["solver"] == NAME
        assert int(values["bounds_violations"]) >= 1 and values["solver_fallbacks"] == "0"
    for _, values in statuses:  # every failure is a bound violation
        assert values["bounds_violations"] == values["solver_failures"]
    assert any(re.search(r"joint \d+ at .* beyond its upper bound .* bounded least-squares step used", line)
               for line in controller.lines)
    summary = next(line for line in controller.lines if "solver failures," in line)
    cycles, failures = (int(re.search(rf"(\d+) {what}", summary).group(1))  # type: ignore[union-attr]
                        for what in ("cycles", "solver failures"))
    assert cycles == failures > 0, summary
