"""``dualarm topic list|echo|hz|info`` against a real 50 Hz publisher process (loopback DDS)."""

from __future__ import annotations

import math
import re
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
import yaml
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped, Transform, Twist, WrenchStamped
from reading import read_line
from rosbags.typesys import Stores, get_typestore
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, Header
from trajectory_msgs.msg import MultiDOFJointTrajectory, MultiDOFJointTrajectoryPoint
from waiting import wait_until

from dualarm_control.ros.graph import (
    RateMeter,
    RateStats,
    format_rate,
    message_to_dict,
    message_to_yaml,
)

REPO = Path(__file__).resolve().parents[1]

# A plain rclpy publisher: nothing from this package.
PUBLISHER = r'''
import os
import rclpy
from rclpy.executors import ExternalShutdownException
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, Header

rclpy.init()
node = rclpy.create_node("topic_test_publisher")
js = node.create_publisher(JointState, "/joint_states", 10)
diag = node.create_publisher(DiagnosticArray, "/diagnostics", 10)
node.create_subscription(Float64MultiArray, "/velocity_controller/commands", lambda m: None, 10)
count = [0]

def tick():
    count[0] += 1
    js.publish(JointState(header=Header(stamp=Time(sec=count[0], nanosec=5), frame_id="base"),
                          name=["left_joint_1", "left_joint_2"], position=[0.25, -1.5], velocity=[0.0, 2.0]))
    diag.publish(DiagnosticArray(status=[DiagnosticStatus(level=DiagnosticStatus.WARN, name="controller_node",
                                                          values=[KeyValue(key="solver", value="sparse_qp")])]))

node.create_timer(0.02, tick)
print("publishing", flush=True)
try:
    rclpy.spin(node)
except (KeyboardInterrupt, ExternalShutdownException):
    pass
os._exit(0)  # no interpreter finalization: rclpy's and Fast DDS's teardown can hang at exit (not under test)
'''


def dualarm(*args: str, timeout: float = 30.0) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "dualarm_control.app.cli", *args], cwd=REPO,
                          capture_output=True, text=True, timeout=timeout, check=False)


@pytest.fixture(scope="module")
def publisher(tmp_path_factory: pytest.TempPathFactory) -> Iterator[subprocess.Popen[str]]:
    script = tmp_path_factory.mktemp("topic") / "publisher.py"
    script.write_text(PUBLISHER)
    proc = subprocess.Popen([sys.executable, str(script)], cwd=REPO, stdout=subprocess.PIPE,
                            stderr=subprocess.DEVNULL, text=True)
    try:
        assert read_line(proc, what="the publisher's 'publishing'").strip() == "publishing"
        yield proc
    finally:
        proc.kill()
        proc.wait(timeout=10)


def echo_documents(stdout: str) -> list[dict[str, object]]:
    return [d for d in yaml.safe_load_all(stdout) if d is not None]


def test_echo_once_prints_yaml(publisher: subprocess.Popen[str]) -> None:
    out = dualarm("topic", "echo", "/joint_states", "--once", "--timeout", "10")
    assert out.returncode == 0, out.stderr
    assert out.stdout.endswith("---\n")
    (doc,) = echo_documents(out.stdout)
    assert list(doc) == ["header", "name", "position", "velocity", "effort"]
    assert doc["header"]["frame_id"] == "base" and doc["header"]["stamp"]["nanosec"] == 5
    assert doc["name"] == ["left_joint_1", "left_joint_2"]
    assert doc["position"] == [0.25, -1.5] and doc["velocity"] == [0.0, 2.0] and doc["effort"] == []
    assert "position:\n- 0.25\n- -1.5\n" in out.stdout  # block-style lists like ros2 topic echo


def test_echo_count_nested_sequences(publisher: subprocess.Popen[str]) -> None:
    out = dualarm("topic", "echo", "diagnostics", "-n", "3", "--timeout", "10")
    assert out.returncode == 0, out.stderr
    docs = echo_documents(out.stdout)
    assert len(docs) == 3
    status = docs[0]["status"][0]
    assert status["level"] == 1 and status["name"] == "controller_node"
    assert status["values"] == [{"key": "solver", "value": "sparse_qp"}]


RATE_REPORT = r"average rate: (\S+)\n\tmin: (\S+)s max: (\S+)s std dev: (\S+)s window: (\d+)"


def test_hz_reports_the_rate_of_what_it_received(publisher: subprocess.Popen[str]) -> None:
    """End to end: reports come, each self-consistent (the mean period 1/rate lies between the
    smallest and largest period of its window). The arithmetic against known arrival times is
    test_rate_meter_and_format; how close the rate is to the publisher's 50 Hz depends on how
    busy the machine is, which is not this test's subject."""
    runs: list[subprocess.CompletedProcess[str]] = []

    def reported() -> list[tuple[str, ...]]:  # a run of 2.5 s reports once it received two messages
        runs.append(dualarm("topic", "hz", "/joint_states", "--duration", "2.5"))
        return re.findall(RATE_REPORT, runs[-1].stdout) if runs[-1].returncode == 0 else []

    reports = wait_until(reported, lambda: f"{len(runs)} runs, the last: exit {runs[-1].returncode}\n"
                         f"{runs[-1].stdout}{runs[-1].stderr}", what="a rate report of dualarm topic hz", interval=0.0)
    out = runs[-1]
    for rate, low, high, std, window in reports:
        assert math.isfinite(float(rate)) and float(rate) > 0.0 and int(window) >= 2, out.stdout
        assert float(low) - 5e-4 <= 1.0 / float(rate) <= float(high) + 5e-4, out.stdout  # printed to 1 ms
        assert float(std) >= 0.0


def test_info_counts_publishers_and_subscriptions(publisher: subprocess.Popen[str]) -> None:
    out = dualarm("topic", "info", "/joint_states")
    assert out.returncode == 0, out.stderr
    assert out.stdout.splitlines() == ["Type: sensor_msgs/msg/JointState", "Publisher count: 1",
                                       "Subscription count: 0"]
    out = dualarm("topic", "info", "/velocity_controller/commands")
    assert out.stdout.splitlines()[1:] == ["Publisher count: 0", "Subscription count: 1"]


def test_list_shows_topics_with_endpoints(publisher: subprocess.Popen[str]) -> None:
    """list prints what discovery found within --spin-time (a snapshot): listed again until the
    publisher's topics are there, and only they. 4 s: over the plain rclpy publisher's 3 s announcement
    period (Fast DDS's default), the wait when its first answer to a new participant is lost
    (docs/bench.md, "Start-up"); more on a loaded machine."""
    expected = {"/joint_states [sensor_msgs/msg/JointState]", "/diagnostics [diagnostic_msgs/msg/DiagnosticArray]",
                "/velocity_controller/commands [std_msgs/msg/Float64MultiArray]"}
    runs: list[subprocess.CompletedProcess[str]] = []

    def listed() -> list[str] | None:
        runs.append(dualarm("topic", "list", "-t", "--spin-time", "4"))
        lines = runs[-1].stdout.splitlines()
        return lines if runs[-1].returncode == 0 and expected <= set(lines) else None

    lines = wait_until(listed, lambda: f"{len(runs)} runs, the last: exit {runs[-1].returncode}\n"
                       f"{runs[-1].stdout}{runs[-1].stderr}", what=f"{sorted(expected)} listed", interval=0.0)
    assert "/wrench [geometry_msgs/msg/WrenchStamped]" not in lines


def test_unknown_topic_is_a_clear_error() -> None:
    out = dualarm("topic", "echo", "/no_such_topic", "--once", "--spin-time", "0.3")
    assert out.returncode == 2
    assert "no publisher of '/no_such_topic' found within 0.3 s" in out.stderr


# ----------------------------------------------------------------------------- units


GRAPH_TYPES = (JointState, Float64MultiArray, MultiDOFJointTrajectory, PoseStamped, DiagnosticArray,
               WrenchStamped, Clock)


@pytest.mark.parametrize("cls", GRAPH_TYPES, ids=lambda c: c.__name__)
def test_every_message_class_converts_to_yaml(cls: type) -> None:
    msg = cls()
    text = message_to_yaml(msg)
    assert yaml.safe_load(text) == message_to_dict(msg)
    assert list(message_to_dict(msg)) == list(cls.get_fields_and_field_types())  # type: ignore[attr-defined]


def test_nested_message_to_dict() -> None:
    msg = MultiDOFJointTrajectory(
        header=Header(frame_id="left_tool", stamp=Time(sec=3)), joint_names=["right_tool"],
        points=[MultiDOFJointTrajectoryPoint(transforms=[Transform()], velocities=[Twist()])])
    d = message_to_dict(msg)
    assert d["points"][0]["transforms"][0]["rotation"] == {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}
    assert d["points"][0]["accelerations"] == [] and d["joint_names"] == ["right_tool"]
    assert d["header"]["stamp"] == {"sec": 3, "nanosec": 0}
    status = DiagnosticArray(status=[DiagnosticStatus(level=DiagnosticStatus.ERROR, values=[KeyValue(key="k")])])
    assert message_to_dict(status)["status"][0]["level"] == 2


def test_rosbags_messages_convert_too() -> None:
    ts = get_typestore(Stores.ROS2_JAZZY)
    m = ts.types
    js = m["sensor_msgs/msg/JointState"](
        header=m["std_msgs/msg/Header"](stamp=m["builtin_interfaces/msg/Time"](sec=1, nanosec=2), frame_id="a"),
        name=["j"], position=np.array([1.5]), velocity=np.array([]), effort=np.array([]))
    assert message_to_dict(js) == {"header": {"stamp": {"sec": 1, "nanosec": 2}, "frame_id": "a"},
                                   "name": ["j"], "position": [1.5], "velocity": [], "effort": []}


def test_rate_meter_and_format() -> None:
    meter = RateMeter(window=5)
    assert meter.stats() is None
    for k in range(10):
        meter.add(0.02 * k)
    stats = meter.stats()
    assert stats is not None
    assert stats.rate == pytest.approx(50.0) and stats.window == 5 and stats.std_dev == pytest.approx(0.0, abs=1e-12)
    assert format_rate(RateStats(49.9876, 0.019, 0.021, 0.000123, 51)) == (
        "average rate: 49.988\n\tmin: 0.019s max: 0.021s std dev: 0.00012s window: 51")
