"""``dualarm bag record|info`` and ``dualarm report``: real processes over loopback DDS, rosbags as the reader.

The recorder runs as ``python -m dualarm_control.app.cli bag record`` next to a tiny publisher
process; it is stopped by SIGINT/SIGTERM like the launcher does, and the bag is read back
with ``rosbags.highlevel.AnyReader``. The report is checked on a bag written here with the
rosbags Writer, against numbers computed by hand.
"""

from __future__ import annotations

import json
import math
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest
import yaml
from launching import side_by_side
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore
from waiting import DEADLINE_S, exited, node_env, tail, wait_until

from dualarm_control.app import cli
from dualarm_control.app.record.bag_runs import (
    nearest_labels,
    pose_error,
    quaternion_angle,
)

REPO = Path(__file__).resolve().parents[1]
N_MSGS = 40
TS = get_typestore(Stores.ROS2_JAZZY)

PUBLISHER = r'''
import sys, time
import rclpy
from rclpy.qos import QoSProfile
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, Header

rclpy.init()
node = rclpy.create_node("bag_test_publisher")
qos = QoSProfile(depth=200)
pubs = [node.create_publisher(JointState, "/joint_states", qos),
        node.create_publisher(Float64MultiArray, "/velocity_controller/commands", qos),
        node.create_publisher(DiagnosticArray, "/diagnostics", qos)]
deadline = time.monotonic() + 90.0  # a deadline for discovery on a loaded machine, not a speed
while min(p.get_subscription_count() for p in pubs) < 1:
    if time.monotonic() > deadline:
        sys.exit("no subscriber")
    time.sleep(0.01)
time.sleep(0.2)
for i in range(int(sys.argv[1])):
    pubs[0].publish(JointState(header=Header(stamp=Time(sec=i, nanosec=7), frame_id="world"),
                               name=[f"j{k}" for k in range(14)], position=[i + 0.1 * k for k in range(14)],
                               velocity=[-1.0 * k for k in range(14)]))
    pubs[1].publish(Float64MultiArray(data=[0.5 * i + k for k in range(14)]))
    pubs[2].publish(DiagnosticArray(status=[DiagnosticStatus(
        level=b"\x01", name="controller_node", values=[KeyValue(key="i", value=str(i))])]))
    time.sleep(0.005)
print("published", flush=True)
time.sleep(120.0)  # alive while the recorder drains; the test kills it
'''
TOPICS = ("/joint_states", "/velocity_controller/commands", "/diagnostics")


# ----------------------------------------------------------------------------- helpers


class Proc:
    """A child process whose stdout lines are collected by a thread (bounded waits)."""

    def __init__(self, args: list[str], stderr_path: Path, env: dict[str, str] | None = None) -> None:
        """``env`` adds to the environment (a ROS domain of its own)."""
        self._stderr = stderr_path.open("w")
        self.popen = subprocess.Popen(args, cwd=REPO, stdout=subprocess.PIPE, stderr=self._stderr, text=True,
                                      env={**node_env(), **(env or {})})
        self.lines: list[str] = []
        self.stderr_path = stderr_path
        threading.Thread(target=self._pump, daemon=True).start()

    def _pump(self) -> None:
        assert self.popen.stdout is not None
        for line in self.popen.stdout:
            self.lines.append(line.rstrip("\n"))

    def wait_line(self, text: str, timeout: float = DEADLINE_S) -> None:
        """Wait for a stdout line equal to ``text``; fail with the output and stderr so far when
        ``timeout`` [s] passes or the process exits first."""
        wait_until(lambda: text in self.lines, lambda: tail(self.lines) + "\nstderr:\n" + self.stderr(),
                   what=f"'{text}' on stdout", timeout=timeout, gone=exited(self.popen))

    def stop(self, sig: int, timeout: float = 15.0) -> int:
        """Send ``sig`` and wait for the exit code."""
        self.popen.send_signal(sig)
        return self.popen.wait(timeout=timeout)

    def kill(self) -> None:
        """Kill if still running (always safe)."""
        if self.popen.poll() is None:
            self.popen.kill()
            self.popen.wait(timeout=10)
        self._stderr.close()

    def stderr(self) -> str:
        return self.stderr_path.read_text()


def dualarm(*args: str) -> list[str]:
    return [sys.executable, "-m", "dualarm_control.app.cli", *args]


def record_with_publisher(tmp_path: Path, name: str, sig: int, n: int = N_MSGS,
                          env: dict[str, str] | None = None) -> tuple[Path, int, str]:
    """Record while the publisher sends ``n`` messages per topic, then stop the recorder with ``sig``;
    ``env`` adds to both processes' environment (a ROS domain of their own)."""
    bag = tmp_path / name
    script = tmp_path / "publisher.py"
    script.write_text(PUBLISHER)
    rec = Proc(dualarm("bag", "record", "-o", str(bag), *TOPICS), tmp_path / f"{name}.rec.err", env)
    pub = Proc([sys.executable, str(script), str(n)], tmp_path / f"{name}.pub.err", env)
    try:
        # deadlines, not speeds: each process starts (imports, discovery) in seconds on a loaded machine
        rec.wait_line("bag: ready", 120.0)
        pub.wait_line("published", 120.0)
        wait_for_progress(rec, n)
        code = rec.stop(sig)
        return bag, code, rec.stderr()
    finally:
        rec.kill()
        if pub is not None:
            pub.kill()


def wait_for_progress(rec: Proc, n: int, timeout: float = DEADLINE_S) -> None:
    """Wait until the recorder's progress (every 2 s on stderr) shows all 3 * n messages; fail with
    its stderr when ``timeout`` [s] passes or it exits first."""
    wait_until(lambda: f"recorded {3 * n} messages" in rec.stderr(), rec.stderr, what=f"{3 * n} messages recorded",
               timeout=timeout, gone=exited(rec.popen, "the recorder"))


def read_bag(bag: Path) -> dict[str, list[object]]:
    with AnyReader([bag], default_typestore=TS) as reader:
        out: dict[str, list[object]] = {t: [] for t in reader.topics}
        for conn, _, raw in reader.messages():
            out[conn.topic].append(reader.deserialize(raw, conn.msgtype))
    return out


SIGTERM_MSGS = 10
"""Messages per topic of the recording stopped by SIGTERM."""


@pytest.fixture(scope="module")
def recordings(request: pytest.FixtureRequest,
               tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[Path, int, str]]:
    """The recordings the selected tests use, side by side (each recorder and its publisher on a ROS
    domain of their own): stopped by SIGINT (:data:`N_MSGS` messages per topic) and by SIGTERM
    (:data:`SIGTERM_MSGS`); by signal name, each its bag, the recorder's exit code and its stderr."""
    used = {name for item in request.session.items if item.module is request.module
            for name, fixture in (("sigint", "sigint_bag"), ("sigterm", "sigterm_bag")) if fixture in item.fixturenames}
    runs = {"sigint": (signal.SIGINT, N_MSGS), "sigterm": (signal.SIGTERM, SIGTERM_MSGS)}

    # the directories made here, not in the jobs' threads: pytest's TempPathFactory is not thread-safe
    # (two first mktemp calls at once raced for its base directory: "is not a normalized and relative path")
    dirs = {name: tmp_path_factory.mktemp(name) for name in sorted(used)}

    def record(name: str, env: dict[str, str]) -> tuple[Path, int, str]:
        sig, n = runs[name]
        return record_with_publisher(dirs[name], f"{name}_bag", sig, n, env)

    return side_by_side({name: lambda env, name=name: record(name, env) for name in sorted(used)})


@pytest.fixture(scope="module")
def sigint_bag(recordings: dict[str, tuple[Path, int, str]]) -> Iterator[tuple[Path, int, str]]:
    yield recordings["sigint"]


@pytest.fixture(scope="module")
def sigterm_bag(recordings: dict[str, tuple[Path, int, str]]) -> tuple[Path, int, str]:
    return recordings["sigterm"]


# ----------------------------------------------------------------------------- record


def test_sigint_closes_a_jazzy_style_bag(sigint_bag: tuple[Path, int, str]) -> None:
    bag, code, err = sigint_bag
    assert code == 0, err
    assert "bag closed (signal SIGINT)" in err
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["version"] == 9
    assert meta["storage_identifier"] == "mcap"
    assert meta["relative_file_paths"] == [f"{bag.name}_0.mcap"] and (bag / f"{bag.name}_0.mcap").is_file()
    assert meta["ros_distro"] == "jazzy"
    topics = {t["topic_metadata"]["name"]: t for t in meta["topics_with_message_count"]}
    assert topics["/joint_states"]["topic_metadata"]["type"] == "sensor_msgs/msg/JointState"
    assert topics["/joint_states"]["topic_metadata"]["type_description_hash"].startswith("RIHS01_")
    qos = topics["/velocity_controller/commands"]["topic_metadata"]["offered_qos_profiles"]
    assert qos and qos[0]["reliability"] == "reliable" and qos[0]["durability"] == "volatile"


def test_recorded_messages_are_intact(sigint_bag: tuple[Path, int, str]) -> None:
    bag, _, _ = sigint_bag
    msgs = read_bag(bag)
    assert {t: len(v) for t, v in msgs.items()} == {
        "/joint_states": N_MSGS, "/velocity_controller/commands": N_MSGS, "/diagnostics": N_MSGS}
    for i, (js, cmd, diag) in enumerate(zip(msgs["/joint_states"], msgs["/velocity_controller/commands"],
                                            msgs["/diagnostics"], strict=True)):
        assert (js.header.stamp.sec, js.header.stamp.nanosec, js.header.frame_id) == (i, 7, "world")
        assert list(js.name) == [f"j{k}" for k in range(14)]
        np.testing.assert_array_equal(js.position, [i + 0.1 * k for k in range(14)])
        np.testing.assert_array_equal(js.velocity, [-1.0 * k for k in range(14)])
        assert len(js.effort) == 0
        np.testing.assert_array_equal(cmd.data, [0.5 * i + k for k in range(14)])
        assert cmd.layout.dim == [] and cmd.layout.data_offset == 0
        (status,) = diag.status
        assert (status.level, status.name, status.message) == (1, "controller_node", "")
        assert [(kv.key, kv.value) for kv in status.values] == [("i", str(i))]


def test_bag_info(sigint_bag: tuple[Path, int, str]) -> None:
    bag, _, _ = sigint_bag
    out = subprocess.run(dualarm("bag", "info", str(bag)), cwd=REPO, capture_output=True, text=True, timeout=30,
                         check=False)
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    assert "Storage id:        mcap" in lines
    assert f"Messages:          {3 * N_MSGS}" in lines
    assert any(line.startswith("Duration:") and line.endswith("s") for line in lines)
    assert (f"Topic: /joint_states | Type: sensor_msgs/msg/JointState | Count: {N_MSGS} | "
            "Serialization Format: cdr") in out.stdout


def test_sigterm_also_leaves_a_valid_bag(sigterm_bag: tuple[Path, int, str]) -> None:
    bag, code, err = sigterm_bag
    assert code == 0, err
    assert "bag closed (signal SIGTERM)" in err
    with AnyReader([bag], default_typestore=TS) as reader:
        assert reader.topics["/velocity_controller/commands"].msgcount == SIGTERM_MSGS
        assert reader.message_count == 3 * SIGTERM_MSGS


def test_duration_stops_and_closes(tmp_path: Path) -> None:
    bag = tmp_path / "empty"
    out = subprocess.run(dualarm("bag", "record", "-o", str(bag), "--duration", "0.5", "/no_publisher_here"),
                         cwd=REPO, capture_output=True, text=True, timeout=30, check=False)
    assert out.returncode == 0, out.stderr
    assert out.stdout.splitlines() == []  # never ready: the topic has no publisher
    assert "recording to" in out.stderr
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["message_count"] == 0 and meta["version"] == 9


# ----------------------------------------------------------------------------- report (synthetic bag)

JOINTS = [f"{side}_joint_{i}" for side in ("left", "right") for i in range(1, 8)]
PERIOD = 0.01
N_CYCLES = 8


def _header(t_ns: int, frame: str = "") -> object:
    m = TS.types
    return m["std_msgs/msg/Header"](stamp=m["builtin_interfaces/msg/Time"](
        sec=t_ns // 10**9, nanosec=t_ns % 10**9), frame_id=frame)


def _command(k: int) -> np.ndarray:
    """Cycle k: joints 0..a-1 at 0.1 * (j + 1) with a = k % 4 + 1, and 5e-4 (inactive) on joint 13."""
    q = np.zeros(14)
    active = k % 4 + 1
    q[:active] = 0.1 * np.arange(1, active + 1)
    q[13] = 5e-4
    return q


def _quat(z_angle: float) -> object:
    return TS.types["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(z_angle / 2), w=math.cos(z_angle / 2))


def _point(cls: str, x: float, y: float, z: float) -> object:
    return TS.types[cls](x=x, y=y, z=z)


def write_synthetic_bag(path: Path, *, solvers: tuple[str, ...] = ("sparse_qp",), with_commands: bool = True) -> None:
    """A run of N_CYCLES per solver: one message of each report topic per cycle."""
    m = TS.types
    shuffled = JOINTS[1:] + JOINTS[:1]  # not the model order: the report must reorder by name
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        conns = {
            topic: w.add_connection(topic, typ, typestore=TS) for topic, typ in (
                ("/joint_states", "sensor_msgs/msg/JointState"),
                ("/velocity_controller/commands", "std_msgs/msg/Float64MultiArray"),
                ("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray"),
                ("/relative_pose", "geometry_msgs/msg/PoseStamped"),
                ("/relative_target", "trajectory_msgs/msg/MultiDOFJointTrajectory"),
            ) if with_commands or topic != "/velocity_controller/commands"
        }

        def put(topic: str, t: int, msg: object) -> None:
            if topic in conns:
                w.write(conns[topic], t, TS.serialize_cdr(msg, conns[topic].msgtype))

        t0 = 1_700_000_000_000_000_000
        for c in range(N_CYCLES * len(solvers)):
            solver, k = solvers[c // N_CYCLES], c % N_CYCLES
            t = t0 + c * 10_000_000
            q = np.full(14, 0.1)
            if k == 2:
                q[1] = 2.5  # left_joint_2 beyond its 2.094 rad limit: one position violation
            by_name = dict(zip(JOINTS, q, strict=True))
            put("/joint_states", t, m["sensor_msgs/msg/JointState"](
                header=_header(t), name=shuffled, position=np.array([by_name[j] for j in shuffled]),
                velocity=np.zeros(14), effort=np.zeros(0)))
            last = k == N_CYCLES - 1
            tf = m["geometry_msgs/msg/Transform"](translation=_point("geometry_msgs/msg/Vector3", 0.1, 0.2, 0.3),
                                                  rotation=_quat(0.2 if last else 0.0))
            twist = m["geometry_msgs/msg/Twist"](linear=_point("geometry_msgs/msg/Vector3", 0, 0, 0),
                                                 angular=_point("geometry_msgs/msg/Vector3", 0, 0, 0))
            put("/relative_target", t + 500_000, m["trajectory_msgs/msg/MultiDOFJointTrajectory"](
                header=_header(t, "left_tool"), joint_names=["right_tool"],
                points=[m["trajectory_msgs/msg/MultiDOFJointTrajectoryPoint"](
                    transforms=[tf], velocities=[twist], accelerations=[],
                    time_from_start=m["builtin_interfaces/msg/Duration"](sec=0, nanosec=0))]))
            put("/velocity_controller/commands", t + 1_000_000, m["std_msgs/msg/Float64MultiArray"](
                layout=m["std_msgs/msg/MultiArrayLayout"](dim=[], data_offset=0), data=_command(k)))
            pose_xyz = (0.103, 0.204, 0.3) if last else (0.0, 0.0, 0.0)
            put("/relative_pose", t + 1_500_000, m["geometry_msgs/msg/PoseStamped"](
                header=_header(t, "left_tool"), pose=m["geometry_msgs/msg/Pose"](
                    position=_point("geometry_msgs/msg/Point", *pose_xyz), orientation=_quat(0.0))))
            values = {"solver": solver, "status": "infeasible" if k == 3 else "optimal",
                      "solve_time_s": "0.0005", "cycle_time_s": f"{0.001 * (k + 1):.6f}",
                      "control_period_s": f"{PERIOD}", "stamp_ns": str(t), "active_joints": "0"}
            put("/diagnostics", t + 2_000_000, m["diagnostic_msgs/msg/DiagnosticArray"](
                header=_header(t), status=[m["diagnostic_msgs/msg/DiagnosticStatus"](
                    level=0, name="controller_node", message="", hardware_id="",
                    values=[m["diagnostic_msgs/msg/KeyValue"](key=a, value=b) for a, b in values.items()])]))


def test_report_matches_hand_computed_metrics(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bag = tmp_path / "synthetic"
    write_synthetic_bag(bag)
    out = tmp_path / "report"
    assert cli.main(["report", str(bag), "--output", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "mean ||qd||_0 (active joints)" in printed and "sparse_qp" in printed
    record = json.loads((out / "metrics.json").read_text())["sparse_qp"]
    # active joints per cycle: 1, 2, 3, 4, 1, 2, 3, 4 (the 5e-4 rad/s joint is below 1e-3)
    assert record["l0_mean"] == pytest.approx(2.5)
    # ||qd||_1 per cycle: 0.1 * a (a + 1) / 2 + 5e-4 -> 0.1005, 0.3005, 0.6005, 1.0005
    assert record["l1_mean"] == pytest.approx(0.5005)
    assert record["l0_integral"] == pytest.approx(2.5 * N_CYCLES * PERIOD)
    assert record["duration_s"] == pytest.approx(N_CYCLES * PERIOD)
    assert record["solver_failures"] == 1
    assert record["joint_position_limit_violations"] == 1
    assert record["joint_velocity_limit_violations"] == 0
    assert record["final_position_error_m"] == pytest.approx(0.005)
    assert record["final_orientation_error_rad"] == pytest.approx(0.2)
    assert record["cycle_time_p50_s"] == pytest.approx(0.0045)
    assert (out / "velocity_norms.png").stat().st_size > 1000


def test_report_splits_solvers(tmp_path: Path) -> None:
    bag = tmp_path / "two"
    write_synthetic_bag(bag, solvers=("standard_qp", "sparse_qp"))
    out = tmp_path / "report"
    assert cli.main(["report", str(bag), "--output", str(out)]) == 0
    results = json.loads((out / "metrics.json").read_text())
    assert list(results) == ["standard_qp", "sparse_qp"]
    for record in results.values():
        assert record["duration_s"] == pytest.approx(N_CYCLES * PERIOD)
        assert record["l0_mean"] == pytest.approx(2.5)
        assert record["solver_failures"] == 1


def test_bag_cell_of_a_bag_without_one_exits_1(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A bag without /dualarm/cell (recorded before issue 40): `dualarm bag cell` says so, exit 1."""
    bag = tmp_path / "old"
    write_synthetic_bag(bag)
    assert cli.main(["bag", "cell", str(bag)]) == 1
    assert "no /dualarm/cell message" in capsys.readouterr().err


def test_report_names_missing_topics(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bag = tmp_path / "no_commands"
    write_synthetic_bag(bag, with_commands=False)
    assert cli.main(["report", str(bag), "--output", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err
    assert "lacks /velocity_controller/commands" in err
    assert not (tmp_path / "r" / "metrics.json").exists()


def test_report_on_a_missing_bag_exits_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["report", str(tmp_path / "nothing"), "--output", str(tmp_path / "r")]) == 2
    assert "no bag at" in capsys.readouterr().err


# ----------------------------------------------------------------------------- helpers of the report


def test_quaternion_angle_and_pose_error() -> None:
    assert quaternion_angle([0, 0, 0, 1], [0, 0, 0, -1]) == pytest.approx(0.0)  # same rotation
    half = math.sqrt(0.5)
    assert quaternion_angle([0, 0, 0, 1], [0, 0, half, half]) == pytest.approx(math.pi / 2)
    assert quaternion_angle([1, 0, 0, 0], [0, 1, 0, 0]) == pytest.approx(math.pi)
    assert quaternion_angle([0, 0, 0, 1], [0, 0, math.sin(5e-9), math.cos(5e-9)]) == pytest.approx(1e-8, rel=1e-6)
    assert pose_error([0, 0, 0, 0, 0, 0, 1], [0.3, 0.4, 0, 0, 0, 0, 1]) == pytest.approx((0.5, 0.0))


def test_nearest_labels() -> None:
    ref = np.array([10, 20, 30], dtype=np.int64)
    labels = nearest_labels(np.array([0, 14, 16, 26, 99], dtype=np.int64), ref, ["a", "b", "c"])
    assert list(labels) == ["a", "a", "b", "c", "c"]


def test_after_data_must_name_a_recorded_topic(tmp_path: Path) -> None:
    """--after-data TOPIC (a topic subscribed once the others deliver) must be one of the topics."""
    out = subprocess.run(dualarm("bag", "record", "-o", str(tmp_path / "b"), "--duration", "0.2", "/a",
                                 "--after-data", "/b"), cwd=REPO, capture_output=True, text=True, timeout=30,
                         check=False)
    assert out.returncode != 0 and "--after-data /b is not one of the topics to record ['/a']" in out.stderr


@pytest.mark.parametrize(("args", "message"), [
    (("/a", "--after-matched", "/b"), "--after-matched /b is not one of the topics to record ['/a']"),
    (("/a", "/b", "--after-matched", "/b", "--after-data", "/b"), "/b is given to both --after-data and --after-matched"),
])
def test_after_matched_must_name_a_recorded_topic_once(tmp_path: Path, args: tuple[str, ...], message: str) -> None:
    """--after-matched TOPIC must be one of the topics, and not also an --after-data one."""
    out = subprocess.run(dualarm("bag", "record", "-o", str(tmp_path / "b"), "--duration", "0.2", *args), cwd=REPO,
                         capture_output=True, text=True, timeout=30, check=False)
    assert out.returncode != 0 and message in out.stderr, out.stderr


def test_after_matched_topic_waits_for_every_publisher_of_the_others(tmp_path: Path) -> None:
    """``after_matched`` /b: /b is subscribed only once the recorder's reader of /a has matched every
    publisher the graph lists for /a. A second publisher of /a with another type never matches: /b
    stays unsubscribed (polled many times, the first publisher matched) until it is gone."""
    import rclpy
    from rclpy.context import Context
    from std_msgs.msg import Int32, String

    from dualarm_control.ros.node import tool_node
    from dualarm_control.ros.recorder import BagWriter, Recorder

    def spin_until(condition: Callable[[], bool], what: str, timeout: float = 120.0) -> None:  # hang guards
        deadline = time.monotonic() + timeout
        while not condition():
            assert time.monotonic() < deadline, f"not within {timeout} s: {what}"
            recorder.poll()
            executor.spin_once(timeout_sec=0.02)

    bag = BagWriter(tmp_path / "bag")
    contexts = [Context(), Context()]  # the publishers in participants of their own: one participant
    for context in contexts:           # cannot have two types on a topic
        rclpy.init(context=context)
    try:
        strings, ints = (rclpy.create_node(f"_test_after_matched_{i}", context=c) for i, c in enumerate(contexts))
        publishers = {String: (strings, strings.create_publisher(String, "/a", 10)),
                      Int32: (ints, ints.create_publisher(Int32, "/a", 10))}
        strings.create_publisher(String, "/b", 10)
        with tool_node("_test_after_matched", signals=False) as (node, executor, _):
            recorder = Recorder(node, bag, ["/a", "/b"], False, compute_tf=False, after_matched=["/b"])
            deadline = time.monotonic() + 120.0  # a hang guard, not a timing claim
            while node.count_publishers("/a") < 2 or node.count_publishers("/b") < 1:  # all in the graph first
                assert time.monotonic() < deadline, "the publishers of /a and /b not in the graph within 120 s"
                executor.spin_once(timeout_sec=0.02)
            spin_until(lambda: "/a" in recorder.subscriptions, "/a subscribed")
            reader = recorder.subscriptions["/a"]
            spin_until(lambda: reader.get_publisher_count() >= 1, "the reader of /a matched its own type's publisher")
            for _ in range(50):
                recorder.poll()
                executor.spin_once(timeout_sec=0.01)
            assert reader.get_publisher_count() == 1
            assert "/b" not in recorder.subscriptions, "/b subscribed while a publisher of /a was not matched"
            owner, late = next(v for t, v in publishers.items() if t is not reader.msg_type)
            owner.destroy_publisher(late)
            spin_until(lambda: "/b" in recorder.subscriptions, "/b subscribed once /a's publishers all matched")
    finally:
        for context in contexts:
            context.try_shutdown()
        bag.close()
