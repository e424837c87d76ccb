"""Live parameter changes keep the controller's state (issue 25), over ROS as a user makes them.

``dualarm launch`` (three node processes, lockstep, recorded) on a motion back and forth, with the
standard QP and the acceleration bound of config/acceleration_limit.yaml; while the cell moves,
four gain changes and one change of solver, sent by a parameter client that is started before
the launch (a lockstep run keeps the CPU busy: a ``dualarm param set`` started mid-run took more than
120 s to discover the node under ``stress-ng --cpu 1``; by hand the same changes are made with
``dualarm param set``, docs/ros2.md). From the
bag's /velocity_controller/commands the largest per-cycle change must stay within a_max = 10
rad/s^2 (before issue 25 it was 21 rad/s^2: each change restarted the command from rest). The
run is ended by Ctrl-C once the changes have landed (the motion lasts minutes, so the changes
are made during it however slowly the tools start); the bag holds everything up to then.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from reading import read_line
from test_ros_live import Launch

from dualarm_control.app.record.bag import read_bag

REPO = Path(__file__).resolve().parents[1]
SCENARIO = Path(__file__).parent / "data" / "back_and_forth.yaml"
A_MAX = 10.0  # rad/s^2, config/acceleration_limit.yaml
PERIOD = 0.005
ROUNDING = 1e-6  # rad/s^2: the back-end's bound tolerance (1e-9 rad/s) over T; float64 in the bag is exact
CHANGES = (("gain", "8.0"), ("gain", "12.0"), ("gain", "6.0"), ("gain", "10.0"), ("solver", "sparse_qp"))
MOVING = 0.05  # rad/s: the largest joint command just before a change is above this (a_max T)
HANG_GUARD_S = 300.0
"""Each wait of the client (the service, a moment of motion, an answer, the next command) ends after this [s]:
the client then exits 1 saying what it waited for and what it saw; a hang guard, not a timing claim."""
CLIENT = """
import sys
import time
import rclpy
from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
from rcl_interfaces.srv import SetParameters
from std_msgs.msg import Float64MultiArray

rclpy.init()
node = rclpy.create_node("live_change_client")
client = node.create_client(SetParameters, "/controller_node/set_parameters")
seen = {"count": 0, "fast": 0.0}

def on_command(msg):
    seen["count"] += 1
    seen["fast"] = max(abs(v) for v in msg.data) if msg.data else 0.0

node.create_subscription(Float64MultiArray, "/velocity_controller/commands", on_command, 1)  # the latest only: a
# backlog read under load judged a change by commands sent before it landed ("landed at rest" 20 times)

def spin_until(condition, what):
    end = time.monotonic() + HANG_GUARD_S
    while not condition():
        if time.monotonic() > end:
            print(f"hang guard: {what} not within {HANG_GUARD_S:g} s; seen {seen}", file=sys.stderr, flush=True)
            sys.exit(1)
        rclpy.spin_once(node, timeout_sec=0.1)

spin_until(lambda: client.service_is_ready(), "the service /controller_node/set_parameters")
print("ready", flush=True)
last = 0
current = {"gain": "10.0", "solver": "standard_qp"}

def set_parameter(name, text):
    global last
    # mid-motion: a command faster than 0.15 rad/s, at least 300 cycles after the last change
    spin_until(lambda: seen["fast"] > 0.15 and seen["count"] - last >= 300, "a command faster than 0.15 rad/s")
    value = (ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=float(text)) if name == "gain"
             else ParameterValue(type=ParameterType.PARAMETER_STRING, string_value=text))
    future = client.call_async(SetParameters.Request(parameters=[Parameter(name=name, value=value)]))
    spin_until(future.done, f"the answer to {name}={text}")
    result = future.result().results[0]
    last = seen["count"]
    fast = []  # the next two commands: still fast, so the change landed while the arms moved
    while len(fast) < 2:
        before = seen["count"]
        spin_until(lambda before=before: seen["count"] > before, "the next command")
        fast.append(seen["fast"])
    # still faster than 0.1 rad/s: the change landed while the arms moved (a change answered at once, in lockstep,
    # can land just as the speed crosses the trigger: judging it against the trigger itself failed 20 of 20 here)
    return result, min(fast) > 0.1

for line in sys.stdin:
    name, text = line.split()
    for attempt in range(ATTEMPTS):  # on a loaded machine a change may land at a reversal (at rest): undo it, again
        result, moving = set_parameter(name, text)
        if not result.successful or moving:
            break
        if attempt == ATTEMPTS - 1:
            print(f"{name}={text} landed at rest {ATTEMPTS} times", file=sys.stderr, flush=True)
            sys.exit(1)
        print(f"landed at rest: {name}={text}; undone, again", file=sys.stderr, flush=True)
        set_parameter(name, current[name])
    if result.successful:
        current[name] = text
    print("ok" if result.successful else "refused " + result.reason, flush=True)
node.destroy_node()
rclpy.shutdown()
"""


@pytest.mark.realtime  # the client must change the parameters while the arms move fast: a race with the run
def test_live_changes_keep_the_acceleration_bound(tmp_path: Path) -> None:
    bag_path = Path(os.environ.get("KEEP_BAG", str(tmp_path))) / "bag"
    client = subprocess.Popen([sys.executable, "-c", f"HANG_GUARD_S = {HANG_GUARD_S!r}\nATTEMPTS = 20\n{CLIENT}"], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True)
    launch = Launch(str(SCENARIO), "--lockstep", "--params", str(REPO / "config/solvers/standard_qp.yaml"),
                    "--params", str(REPO / "config/acceleration_limit.yaml"), "--record", str(bag_path))
    try:
        assert client.stdin is not None
        # the controller's parameter service is there (the client's own hang guard is 300 s, then it exits)
        assert read_line(client, what="the client's 'ready'", timeout=HANG_GUARD_S + 60).strip() == "ready"
        launch.wait_for("segment 2/40", timeout=300.0)  # moving, the recorder running
        for name, value in CHANGES:  # the client sends each while the arms move fast (see CLIENT)
            client.stdin.write(f"{name} {value}\n")
            client.stdin.flush()
            answer = read_line(client, what=f"the client's answer to {name}={value}", timeout=HANG_GUARD_S + 60).strip()
            assert answer == "ok", f"{name}={value}: {answer!r}"
        launch.wait_for("solver='sparse_qp'", timeout=300.0)  # the last change has landed
    finally:
        launch.kill()
        if client.poll() is None:
            client.kill()
    log = "\n".join(launch.lines)
    changed = log.count("parameters changed at cycle")  # a change that landed at rest was undone and made again
    assert changed >= len(CHANGES) and (changed - len(CHANGES)) % 2 == 0, log[-3000:]

    bag = read_bag(bag_path)
    commands = np.array([row for _, row in bag.commands])
    t_commands = np.array([t for t, _ in bag.commands])
    assert len(commands) > 1000, f"{len(commands)} commands in the bag"
    steps = np.abs(np.diff(commands, axis=0)).max(axis=1) / PERIOD
    worst = int(steps.argmax())
    assert steps[worst] <= A_MAX + ROUNDING, (
        f"{steps[worst]:.4f} rad/s^2 between commands {worst} and {worst + 1} of {len(commands)}")

    # the changes landed while the arms were moving (the client undid and repeated those that did not):
    # find each switch in /diagnostics
    switches = [(t, int(v["parameter_switches"])) for t, v in bag.cycles if "parameter_switches" in v]
    landed = [t for (t, n), (_, before) in zip(switches[1:], switches[:-1], strict=True) if n > before]
    assert len(landed) == changed, f"switches seen in the bag at {landed}, {changed} in the log"
    speeds = [float(np.abs(commands[int(np.searchsorted(t_commands, t)) - 2]).max()) for t in landed]
    assert sum(v > MOVING for v in speeds) >= len(CHANGES), f"joint speed before each change: {speeds}"
