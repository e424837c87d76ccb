"""Real-time runs as a user meets them: live parameter changes, a foreign rclpy client, Ctrl-C.

Every process is real (the launcher, its three nodes, the ``dualarm`` tools, a plain rclpy
script that imports nothing from this package), on localhost discovery and this session's
private ROS_DOMAIN_ID.
"""

from __future__ import annotations

import re
import signal
import subprocess
import sys
import threading
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
import yaml
from waiting import DEADLINE_S, exited, node_env, tail, wait_for_line, wait_until

REPO = Path(__file__).resolve().parents[1]
SLOW = Path(__file__).parent / "data" / "slow.yaml"
STREAMS = ("/joint_states", "/velocity_controller/commands")


class Launch:
    """``dualarm launch`` in the background with its output lines collected."""

    def __init__(self, *args: str, env: dict[str, str] | None = None) -> None:
        """``env`` adds to the environment (a ROS domain of its own, say)."""
        self.popen = subprocess.Popen([sys.executable, "-u", "-m", "dualarm_control.app.cli", "launch", *args],
                                      cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                      env={**node_env(), **(env or {})})
        self.lines: list[str] = []
        self._reader = threading.Thread(target=self._pump, daemon=True)
        self._reader.start()

    def _pump(self) -> None:
        assert self.popen.stdout is not None
        for line in self.popen.stdout:
            self.lines.append(line.rstrip("\n"))

    def wait_for(self, text: str, timeout: float = DEADLINE_S) -> None:
        wait_for_line(self.lines, text, self.popen, timeout=timeout, name="dualarm launch")

    def finish(self, timeout: float = 120.0) -> int:
        """The exit code, once the launch has exited and every line of its output is in ``lines``."""
        code = self.popen.wait(timeout=timeout)
        self._reader.join(timeout=DEADLINE_S)  # to the end of its output
        assert not self._reader.is_alive(), "the launch's output did not end:\n" + tail(self.lines)
        return code

    def kill(self) -> None:
        if self.popen.poll() is None:
            self.popen.send_signal(signal.SIGINT)
            try:
                self.popen.wait(timeout=30)
            except subprocess.TimeoutExpired:
                self.popen.kill()


def moving_slow() -> Iterator[Launch]:
    """``dualarm launch`` of test/data/slow.yaml (it holds for minutes), once its motion has started."""
    launch = Launch(str(SLOW), "--solver", "sparse_qp")
    try:
        launch.wait_for("segment 1/1 'move'")
        yield launch
    finally:
        launch.kill()


@pytest.fixture
def launch_slow() -> Iterator[Launch]:
    """A launch of its own, for a test that changes it (and ends it)."""
    yield from moving_slow()


@pytest.fixture(scope="class")
def running_slow() -> Iterator[Launch]:
    """One launch for the tests of a class that only read from it (parameters, the streams)."""
    yield from moving_slow()


def dualarm(*args: str, timeout: float = 60.0) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "dualarm_control.app.cli", *args], cwd=REPO, capture_output=True,
                          text=True, timeout=timeout, check=False)


def controller_cycles(echo_stdout: str) -> list[int]:
    """The controller's ``cycles`` counter in each /diagnostics message of ``dualarm topic echo``."""
    cycles = []
    for doc in yaml.safe_load_all(echo_stdout):
        for status in (doc or {}).get("status", []):
            values = {kv["key"]: kv["value"] for kv in status["values"]}
            if status["name"] == "controller_node" and "cycles" in values:
                cycles.append(int(values["cycles"]))
    return cycles


def test_live_solver_switch_and_refusal(launch_slow: Launch) -> None:
    """``param set`` switches the running solver at a cycle boundary without a failed cycle;
    an invalid solver is refused with the valid choices and the run goes on (its cycle count
    grows after the refusals). Each tool call is a process start, seconds on a loaded machine:
    the run holds for minutes (test/data/slow.yaml) and the test ends it with Ctrl-C."""
    out = dualarm("param", "set", "/controller_node", "solver", "standard_qp")
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "Set parameter successful"
    echo = dualarm("topic", "echo", "/diagnostics", "-n", "5", "--timeout", "10")
    assert "value: standard_qp" in echo.stdout and "key: parameter_switches\n    value: '1'" in echo.stdout
    bad = dualarm("param", "set", "/controller_node", "solver", "nope")
    assert bad.returncode == 2
    assert "nope" in bad.stderr and "sparse_qp" in bad.stderr and "refused" in bad.stderr
    bad_type = dualarm("param", "set", "/controller_node", "gain", "10")
    assert bad_type.returncode == 2 and "gain" in bad_type.stderr
    read_only = dualarm("param", "set", "/controller_node", "control_period", "0.001")
    assert read_only.returncode == 2 and "read-only" in read_only.stderr
    got = dualarm("param", "get", "/controller_node", "solver")
    assert got.returncode == 0, got.stderr
    assert got.stdout.strip() == "String value is: standard_qp"
    later = dualarm("topic", "echo", "/diagnostics", "-n", "5", "--timeout", "10")
    assert "value: standard_qp" in later.stdout
    assert min(controller_cycles(later.stdout)) > max(controller_cycles(echo.stdout))
    launch_slow.popen.send_signal(signal.SIGINT)
    code = launch_slow.finish()
    log = "\n".join(launch_slow.lines)
    assert code == 130, log
    assert "[launch] stopped cleanly: controller_node, trajectory_node, sim_node exited 0" in log, log
    assert "parameters changed at cycle" in log and "solver='standard_qp'" in log
    assert "0 solver failures" in log and "1 parameter switches" in log


FOREIGN_LISTENER = r'''
import sys, time
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

rclpy.init()
node = rclpy.create_node("foreign_listener")
counts = {"js": 0, "cmd": 0, "diag": 0}
node.create_subscription(JointState, "/joint_states", lambda m: counts.__setitem__("js", counts["js"] + 1), 10)
node.create_subscription(Float64MultiArray, "/velocity_controller/commands",
                         lambda m: counts.__setitem__("cmd", counts["cmd"] + 1), 10)
node.create_subscription(DiagnosticArray, "/diagnostics", lambda m: counts.__setitem__("diag", counts["diag"] + 1), 10)
want, end = int(sys.argv[1]), time.monotonic() + 60.0  # a deadline, not a rate
while min(counts.values()) < want and time.monotonic() < end:
    rclpy.spin_once(node, timeout_sec=0.05)
print(counts["js"], counts["cmd"], counts["diag"], flush=True)
'''


class TestOneRunningLaunch:
    """The tests that only read from a running launch share one (``running_slow``, class-scoped: it ends
    before the tests below start nodes of their own on this session's domain)."""

    def test_param_list_and_describe(self, running_slow: Launch) -> None:
        names = dualarm("param", "list", "/controller_node").stdout.split()
        for expected in ("solver", "gain", "l1_weight", "qp_eps_abs", "use_sim_time", "control_period"):
            assert expected in names
        text = dualarm("param", "describe", "/controller_node", "control_period").stdout
        assert "Type: double" in text and "Read only: true" in text and "a value > 0" in text
        missing = dualarm("param", "get", "/no_such_node", "solver", "--timeout", "1")  # no such node: any wait
        assert missing.returncode == 2 and "not found" in missing.stderr

    def test_plain_rclpy_script_sees_the_graph(self, running_slow: Launch, tmp_path: Path) -> None:
        """A script that knows nothing of this package receives the streams: 200 messages of each
        (one second at 200 Hz; how fast they come is a benchmark figure, not this test's)."""
        script = tmp_path / "listener.py"
        script.write_text(FOREIGN_LISTENER)
        out = subprocess.run([sys.executable, str(script), "200"], capture_output=True, text=True, timeout=120,
                             check=False)
        assert out.returncode == 0, out.stderr
        js, cmd, diag = (int(v) for v in out.stdout.split())
        assert js >= 200 and cmd >= 200 and diag >= 200, out.stdout


FOREIGN_DRIVER = r'''
import statistics, sys, time
import rclpy
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

rclpy.init()
node = rclpy.create_node("foreign_driver")
states = []
node.create_subscription(JointState, "/joint_states", lambda m: states.append((m.position[0], m.velocity[0])), 10)
pub = node.create_publisher(Float64MultiArray, "/velocity_controller/commands", 10)
end = time.monotonic() + 60.0  # deadlines, not rates
while not states or pub.get_subscription_count() < 1:
    rclpy.spin_once(node, timeout_sec=0.05)
    if time.monotonic() > end:
        sys.exit("no simulator")
first = len(states)
command = [0.2] + [0.0] * 13
# 200 moving simulator states of 5 ms: the first commands may be lost while the simulator's reader matches this
# writer (it can lag the writer's side by 100 ms and more on a loaded machine: 25 states once)
while sum(v > 0.1 for _, v in states[first:]) < 200:
    pub.publish(Float64MultiArray(data=command))
    rclpy.spin_once(node, timeout_sec=0.005)
    if time.monotonic() > end:
        sys.exit("too few states")
pub.publish(Float64MultiArray(data=[0.0] * 14))
window = states[first:]
steps = [b[0] - a[0] for a, b in zip(window, window[1:])]
moving = sum(v > 0.1 for _, v in window)  # states after the command took effect
print(window[-1][0] - window[0][0], statistics.median(v for _, v in window), statistics.median(steps), moving,
      flush=True)
'''


def test_plain_rclpy_script_drives_the_simulator(tmp_path: Path) -> None:
    """sim_node alone, driven by Float64MultiArray commands from a foreign script at 0.2 rad/s until 200 of its
    states move: the joint reports 0.2 rad/s and advances 0.2 rad/s x 5 ms per state. Counted in simulator
    states, not wall-clock seconds (before: 1 s of wall clock, 0.2 +- 0.03 rad); how soon the first command
    takes effect is discovery's timing, not asserted (under stress-ng the simulator's reader matched 25 states
    after the script's writer had)."""
    script = tmp_path / "driver.py"
    script.write_text(FOREIGN_DRIVER)
    sim = subprocess.Popen([sys.executable, "-m", "dualarm_control.app.cli", "run", "sim_node", "--ros-args",
                            "-p", "command_timeout:=0.2"], cwd=REPO, stdout=subprocess.DEVNULL,
                           stderr=subprocess.DEVNULL, env=node_env())
    try:
        out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=120, check=False)
    finally:
        sim.send_signal(signal.SIGINT)
        code = sim.wait(timeout=30)
    assert out.returncode == 0, out.stderr
    moved, velocity, step, moving = (float(v) for v in out.stdout.split())
    print(f"moved {moved:.5f} rad in {moving:.0f} moving states, median velocity {velocity:.6f} rad/s, "
          f"median step {step:.3e} rad")
    assert velocity == pytest.approx(0.2, rel=0.01)
    assert step == pytest.approx(0.2 * 0.005, rel=0.01)
    assert moving >= 200
    # 0.2 rad/s x 5 ms per moving state after the first; more where the script missed states.
    assert moved >= 0.99 * 0.2 * 0.005 * (moving - 1)  # 1 %: the median step above
    assert code == 0


RECORDED = re.compile(r"\[bag\] recorded \d+ messages in [0-9.]+ s \((.*)\)")
MID_RUN = 300
"""Messages of /joint_states and of /velocity_controller/commands the recorder reports before the Ctrl-C."""


def recorded_counts(lines: list[str]) -> dict[str, int] | None:
    """Per-topic counts of the recorder's latest progress line (``[bag] recorded N messages ...``)."""
    for line in reversed(lines):
        found = RECORDED.search(line)
        if found:
            items = found.group(1).split(", ") if found.group(1) else []
            return {topic: int(n) for topic, n in (item.rsplit(" ", 1) for item in items)}
    return None


def test_ctrl_c_mid_recorded_launch(tmp_path: Path) -> None:
    """SIGINT to ``dualarm launch`` mid-run, once the recorder has reported 300 joint states and 300
    commands: every node exits 0, no tracebacks, a whole bag with at least what was reported."""
    from rosbags.highlevel import AnyReader

    bag = tmp_path / "bag"
    launch = Launch(str(SLOW), "--record", str(bag))
    try:
        launch.wait_for("bag: ready")  # the recorder subscribes once every recorded topic has a publisher
        launch.wait_for("segment 1/1 'move'")

        def mid_run() -> dict[str, int] | None:
            counts = recorded_counts(launch.lines)
            return counts if counts and min(counts.get(t, 0) for t in STREAMS) >= MID_RUN else None

        reported = wait_until(mid_run, lambda: tail(launch.lines), what=f"{MID_RUN} messages of {STREAMS} recorded",
                              gone=exited(launch.popen, "dualarm launch"))
        launch.popen.send_signal(signal.SIGINT)
        code = launch.finish(timeout=60)
    finally:
        launch.kill()
    log = "\n".join(launch.lines)
    assert code == 130, log
    assert "[launch] stopped cleanly: bag, controller_node, trajectory_node, sim_node exited 0" in log, log
    for bad in ("Traceback", "context is invalid", "failed"):
        assert bad not in log, log
    with AnyReader([bag]) as reader:
        counts = {t: i.msgcount for t, i in reader.topics.items()}
        assert all(counts[t] >= reported[t] for t in STREAMS), (counts, reported)  # nothing received is lost
        decoded = [reader.deserialize(raw, conn.msgtype) for conn, _, raw in reader.messages()]
        assert len(decoded) == reader.message_count  # every message readable, up to the signal
    commands = [m.data for m in decoded if hasattr(m, "layout")]
    assert np.all(np.isfinite(np.array(commands)))
