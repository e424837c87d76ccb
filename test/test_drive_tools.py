"""``dualarm topic pub``, ``dualarm goal`` and ``dualarm jog`` against a plain rclpy subscriber process.

The subscriber is a plain rclpy script (no code of this package): it prints what it receives
as JSON lines and, for each goal, answers on /diagnostics with the drive keys the trajectory
node will publish (``reached`` or ``rejected``, per its argument) for that goal's stamp.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import yaml
from reading import read_line

from dualarm_control.drive_status import (
    KEY_ANGLE,
    KEY_DISTANCE,
    KEY_GOAL_STAMP,
    KEY_REASON,
    KEY_STATE,
    KEY_TIME_TO_GO,
    STATUS_NAME,
)
from dualarm_control.ros.drive import FieldError, parse_values, set_message_fields

DUALARM = str(Path(sys.executable).with_name("dualarm"))

SUBSCRIBER = r'''
import json, os, sys
import rclpy
from rclpy.executors import ExternalShutdownException
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped, TwistStamped
from sensor_msgs.msg import JointState

answer = sys.argv[1]
rclpy.init()
node = rclpy.create_node("drive_test_subscriber")
diag = node.create_publisher(DiagnosticArray, "/diagnostics", 10)

def out(topic, data):
    print(json.dumps({"topic": topic, **data}), flush=True)

def on_goal(m):
    stamp = m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec
    out("goal", {"frame": m.header.frame_id, "xyz": [m.pose.position.x, m.pose.position.y, m.pose.position.z],
                 "quat": [m.pose.orientation.x, m.pose.orientation.y, m.pose.orientation.z, m.pose.orientation.w],
                 "stamp": stamp})
    for state in ("moving", answer):
        values = {KEYS}
        values[STATE] = state
        values[STAMP] = "%.9f" % stamp
        diag.publish(DiagnosticArray(status=[DiagnosticStatus(name=NAME, values=[
            KeyValue(key=k, value=v) for k, v in values.items()])]))

def on_twist(m):
    out("twist", {"frame": m.header.frame_id, "linear": [m.twist.linear.x, m.twist.linear.y, m.twist.linear.z],
                  "angular": [m.twist.angular.x, m.twist.angular.y, m.twist.angular.z],
                  "stamp": m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec})

def on_pose(m):
    out("pose", {"frame": m.header.frame_id, "x": m.pose.position.x, "w": m.pose.orientation.w,
                 "stamp_sec": m.header.stamp.sec})

def on_joints(m):
    out("joints", {"name": list(m.name), "position": list(m.position)})

node.create_subscription(PoseStamped, "/relative_goal", on_goal, 10)
node.create_subscription(TwistStamped, "/relative_twist", on_twist, 10)
node.create_subscription(PoseStamped, "/poke_pose", on_pose, 10)
node.create_subscription(JointState, "/poke_joints", on_joints, 10)
print("ready", flush=True)
try:
    rclpy.spin(node)
except (KeyboardInterrupt, ExternalShutdownException):
    pass
os._exit(0)  # no interpreter finalization: rclpy's and Fast DDS's teardown can hang at exit (not under test)
'''


def _script() -> str:
    keys = {KEY_DISTANCE: "0.000100", KEY_ANGLE: "0.000000", KEY_TIME_TO_GO: "0.000", KEY_REASON: "test answer"}
    return (SUBSCRIBER.replace("{KEYS}", repr(keys)).replace("STATE", repr(KEY_STATE))
            .replace("STAMP]", repr(KEY_GOAL_STAMP) + "]").replace("NAME", repr(STATUS_NAME)))


def start_subscriber(answer: str) -> subprocess.Popen[str]:
    proc = subprocess.Popen([sys.executable, "-c", _script(), answer], stdout=subprocess.PIPE, text=True,
                            env=os.environ.copy())
    assert read_line(proc, what="the subscriber's 'ready'").strip() == "ready"
    return proc


@pytest.fixture
def reached_subscriber() -> Iterator[subprocess.Popen[str]]:
    proc = start_subscriber("reached")
    yield proc
    if proc.poll() is None:
        stop(proc)


def stop(proc: subprocess.Popen[str]) -> str:
    """SIGTERM, then SIGKILL after 10 s: the script prints each message flushed, so nothing is lost."""
    proc.terminate()
    try:
        out, _ = proc.communicate(timeout=10)
    except subprocess.TimeoutExpired:  # rclpy's shutdown can stall on a loaded machine (CI, 2026-12-02)
        proc.kill()
        out, _ = proc.communicate(timeout=10)
    return out


def received(proc: subprocess.Popen[str]) -> list[dict]:
    out = stop(proc)
    return [json.loads(line) for line in out.splitlines() if line.startswith("{")]


def dualarm(*args: str, timeout: float = 60) -> subprocess.CompletedProcess[str]:
    return subprocess.run([DUALARM, *args], check=False, capture_output=True, text=True, timeout=timeout,
                          env=os.environ.copy())


def test_topic_pub_once_and_times_reach_a_plain_subscriber(reached_subscriber) -> None:
    once = dualarm("topic", "pub", "--once", "/poke_pose", "geometry_msgs/msg/PoseStamped",
                   "{header: {stamp: {sec: 7}, frame_id: left_tool}, pose: {position: {x: 0.1}}}")
    assert once.returncode == 0, once.stderr
    assert "publishing #1" in once.stdout
    many = dualarm("topic", "pub", "-t", "3", "-r", "20", "/poke_joints", "sensor_msgs/msg/JointState",
                   "{name: [a, b], position: [1, 2.5]}")
    assert many.returncode == 0, many.stderr
    got = received(reached_subscriber)
    poses = [m for m in got if m["topic"] == "pose"]
    joints = [m for m in got if m["topic"] == "joints"]
    assert poses == [{"topic": "pose", "frame": "left_tool", "x": 0.1, "w": 1.0, "stamp_sec": 7}]
    assert joints == [{"topic": "joints", "name": ["a", "b"], "position": [1.0, 2.5]}] * 3


def test_topic_pub_refuses_bad_values_and_types() -> None:
    bad_field = dualarm("topic", "pub", "--once", "/x", "geometry_msgs/msg/PoseStamped", "{pose: {place: 1}}")
    assert bad_field.returncode != 0 and "'pose.place' is not a field of Pose" in bad_field.stderr
    bad_type = dualarm("topic", "pub", "--once", "/x", "geometry_msgs/msg/Nope", "{}")
    assert bad_type.returncode != 0 and "not installed" in bad_type.stderr
    timeout = dualarm("topic", "pub", "--once", "--max-wait-time-secs", "0.5", "/nobody_here", "std_msgs/msg/String",
                      "{data: hi}")
    assert timeout.returncode == 1 and "Timed out waiting for subscribers" in timeout.stderr


def test_set_message_fields_like_ros2cli() -> None:
    from builtin_interfaces.msg import Time
    from geometry_msgs.msg import PoseStamped
    from trajectory_msgs.msg import MultiDOFJointTrajectory

    msg = PoseStamped()
    set_message_fields(msg, parse_values("{header: {frame_id: left_tool}, pose: {position: {x: 1, z: -0.5}}}"))
    assert (msg.header.frame_id, msg.pose.position.x, msg.pose.position.z) == ("left_tool", 1.0, -0.5)
    traj = MultiDOFJointTrajectory()
    set_message_fields(traj, parse_values("{joint_names: [r], points: [{transforms: [{translation: {x: 2}}]}]}"))
    assert traj.points[0].transforms[0].translation.x == 2.0
    with pytest.raises(FieldError, match="expected a number"):
        set_message_fields(PoseStamped(), {"pose": {"position": {"x": "far"}}})
    with pytest.raises(FieldError, match="needs to be a dictionary"):
        parse_values("[1, 2]")
    assert isinstance(msg.header.stamp, Time)


def test_goal_publishes_a_pose_stamped_and_wait_exits_0_when_reached(reached_subscriber) -> None:
    result = dualarm("goal", "--xyz", "0.01", "0.02", "0.15", "--rpy", "0", "0", "1.5707963267948966",
                     "--wait", "--timeout", "20")
    assert result.returncode == 0, result.stdout + result.stderr
    assert "reached: distance 0.10 mm" in result.stdout
    goals = [m for m in received(reached_subscriber) if m["topic"] == "goal"]
    assert len(goals) == 1
    goal = goals[0]
    assert goal["frame"] == "left_tool"
    assert goal["xyz"] == [0.01, 0.02, 0.15]
    assert goal["quat"] == pytest.approx([0.0, 0.0, 2**-0.5, 2**-0.5], abs=1e-12)
    assert abs(goal["stamp"] - time.time()) < 120  # stamped now (system clock)


def test_goal_wait_exits_1_when_rejected() -> None:
    proc = start_subscriber("rejected")
    try:
        result = dualarm("goal", "--xyz", "0", "0", "0.1", "--quat", "0", "0", "0", "1", "--wait", "--timeout", "20")
    finally:
        received(proc)
    assert result.returncode == 1
    assert "rejected" in result.stdout and "(test answer)" in result.stdout


def test_goal_refuses_a_bad_quaternion_before_publishing() -> None:
    result = dualarm("goal", "--xyz", "0", "0", "0.1", "--quat", "0", "0", "0", "2")
    assert result.returncode == 2 and "quaternion norm 2" in result.stderr


def test_jog_streams_twist_stamped(reached_subscriber) -> None:
    result = dualarm("jog", "--linear", "0.01", "0", "0", "--angular", "0", "0", "0.2", "--seconds", "0.5",
                     "--rate", "20")
    assert result.returncode == 0, result.stderr
    sent = re.search(r"jog: (\d+) twists sent in", result.stdout)
    assert sent is not None, result.stdout
    twists = [m for m in received(reached_subscriber) if m["topic"] == "twist"]
    # about 10 sent at 20 Hz in 0.5 s (fewer when the jog process was starved, the time being up); the first
    # may precede the subscriber's side of the match and the last its exit: how many arrive is the machine's load
    assert 1 <= len(twists) <= int(sent.group(1)), (len(twists), result.stdout)
    assert all(t["frame"] == "left_tool" and t["linear"] == [0.01, 0, 0] and t["angular"] == [0, 0, 0.2]
               for t in twists)
    stamps = [t["stamp"] for t in twists]
    assert stamps == sorted(stamps) and len(set(stamps)) == len(stamps)


def test_values_yaml_of_the_docs_example_parses() -> None:
    data = parse_values("{header: {frame_id: left_tool}, pose: {position: {x: 0.1}}}")
    assert data == yaml.safe_load("header: {frame_id: left_tool}\npose: {position: {x: 0.1}}")
