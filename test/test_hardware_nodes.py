"""Hardware profiles over real rclpy processes (issue 29): the nodes with each shipped profile, lockstep.

The simulator speaks each profile (its command topics and interfaces, joint states as
joint_state_broadcaster gives them); the run's Table I metrics equal the default profile's, the
final error is below 1 mm, and no position command is farther than v_max T from the measured position.
"""

from __future__ import annotations

import subprocess
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from launching import side_by_side
from reports import assert_same_report, report_metrics
from waiting import node_env

from dualarm_control.app.run.launcher import launch_scenario
from dualarm_control.hardware import HardwareProfile, load_profile
from dualarm_control.kinematics import DualArmModel
from dualarm_control.metrics import velocity_norm_metrics
from dualarm_control.params import read_params_file

ROOT = Path(__file__).parents[1]
SHORT = ROOT / "test" / "data" / "short.yaml"
PROFILES = ("sim", "ros2_control_velocity", "lbr_dual_position", "servo_trajectories")
PERIOD = 0.005
ACCELERATION = ROOT / "config" / "acceleration_limit.yaml"
"""10 rad/s^2, the bound the shipped hardware profiles turn on (issue 40): the default profile's run gets it too."""
SERVO = ROOT / "test" / "data" / "servo_trajectories.yaml"
"""A profile of one-point JointTrajectory outputs (MoveIt Servo's form): the left arm by velocity, the right
by position, in their own joint orders, /left and /right joint states."""


def profile_file(name: str) -> Path:
    return SERVO if name == "servo_trajectories" else ROOT / "config" / "hardware" / f"{name}.yaml"


def profile_of(name: str) -> HardwareProfile:
    return load_profile(read_params_file(profile_file(name), "controller_node"), DualArmModel().joint_names)


def command_values(o: Any, msg: Any) -> list[float]:
    """A command message's values in the output's joint order."""
    if o.message == "float64_multi_array":
        return list(msg.data)
    point = msg.points[0]
    values = dict(zip(msg.joint_names, point.positions if o.position else point.velocities))
    return [values[j] for j in o.joints]


def read_bag(bag: Path) -> dict[str, list[Any]]:
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    out: dict[str, list[Any]] = {}
    with AnyReader([bag], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        for conn, _, raw in reader.messages():
            out.setdefault(conn.topic, []).append(reader.deserialize(raw, conn.msgtype))
    return out


class Run:
    """A profile's lockstep run from its bag: measured positions per stamp and the commanded velocities
    (description order; a position output's as its position differences over one period)."""

    def __init__(self, profile: HardwareProfile, topics: dict[str, list[Any]]) -> None:
        names = DualArmModel().joint_names
        order = {n: i for i, n in enumerate(names)}
        states: dict[int, np.ndarray] = {}
        for topic in profile.joint_states:
            for m in topics[topic]:
                stamp = m.header.stamp.sec * 10**9 + m.header.stamp.nanosec
                q = states.setdefault(stamp, np.full(len(names), np.nan))
                for n, v in zip(m.name, m.position):
                    if n in order:
                        q[order[n]] = v
        self.stamps = sorted(states)
        self.positions = np.array([states[s] for s in self.stamps])
        counts = {len(topics[o.topic]) for o in profile.outputs}
        assert len(counts) == 1, f"outputs sent different command counts: {counts}"
        n = counts.pop()
        self.velocities = np.zeros((n, len(names)))
        self.position_commands: list[tuple[np.ndarray, np.ndarray]] = []  # (joint indices, (n, k) positions)
        for o, idx in zip(profile.outputs, profile.indices(names)):
            values = np.array([command_values(o, m) for m in topics[o.topic]])
            if o.position:
                start = self.positions[0, idx]
                self.velocities[:, idx] = np.diff(np.vstack((start, values)), axis=0) / PERIOD
                self.position_commands.append((idx, values))
            else:
                self.velocities[:, idx] = values
        status = [s for d in topics["/diagnostics"] for s in d.status if s.name == "controller_node"]
        errors = [float(kv.value) for s in status for kv in s.values if kv.key == "position_error_m"]
        self.final_error = errors[-1]
        self.bag = Path()


def lockstep_run(name: str, scenario: str, bag: Path, timeout: float, env: dict[str, str] | None = None) -> Run:
    """The scenario over the nodes in lockstep on profile ``name``, recorded (its topics) and read back;
    ``env`` adds to the nodes' environment (a ROS domain of its own: launching.side_by_side)."""
    profile = profile_of(name)
    topics = (*profile.joint_states, *profile.topics, "/diagnostics", "/relative_target", "/relative_pose")
    params = [str(profile_file(name)), str(ACCELERATION)]  # every run with the shipped profiles' bound
    assert launch_scenario(scenario, params, [], True, bag, timeout=timeout, record_topics=topics, env=env) == 0
    run = Run(profile, read_bag(bag))
    run.bag = bag
    return run


def assert_same_run(default: Run, got: Run) -> None:
    """Lockstep Table I metrics equal to 1e-6, and the same joint trajectory."""
    assert got.velocities.shape == default.velocities.shape
    a, b = velocity_norm_metrics(default.velocities, PERIOD), velocity_norm_metrics(got.velocities, PERIOD)
    for key in ("l0_mean", "l1_mean", "l2_mean"):
        assert getattr(b, key) == pytest.approx(getattr(a, key), abs=1e-6), key
    np.testing.assert_allclose(got.positions, default.positions, atol=1e-6, rtol=0)


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Run]:
    """The four profiles' lockstep runs, side by side (each on a ROS domain of its own)."""
    out = tmp_path_factory.mktemp("hw")
    return side_by_side({name: lambda env, name=name: lockstep_run(name, str(SHORT), out / name, 240.0, env)
                         for name in PROFILES})


@pytest.mark.parametrize("name", PROFILES)
def test_each_profile_completes_the_scenario(runs: dict[str, Run], name: str) -> None:
    run = runs[name]
    assert not np.isnan(run.positions).any(), "a stamp without every joint"
    assert run.final_error < 1e-3


@pytest.mark.parametrize("name", PROFILES[1:])
def test_lockstep_table_one_metrics_equal_the_default_profiles(runs: dict[str, Run], name: str) -> None:
    assert_same_run(runs["sim"], runs[name])


@pytest.mark.parametrize("name", PROFILES)
def test_the_bag_carries_its_cell_and_the_product_reads_it_as_this_test_does(runs: dict[str, Run], name: str) -> None:
    """Issue 40: the bag holds each node's parameters (/dualarm/cell); through the recorded profile the
    product's reader gives the commands (velocities, description order) and the joint states this
    test's own reading above gives."""
    from dualarm_control.app.record.bag import read_bag as product_bag

    run = runs[name]
    bag = product_bag(run.bag)
    assert {"sim_node", "controller_node", "trajectory_node"} <= set(bag.cell)
    assert bag.streams.topics.outputs == profile_of(name).topics
    commands = np.array([v for _, v in bag.commands])
    assert commands.shape == run.velocities.shape
    np.testing.assert_allclose(commands, run.velocities, rtol=0, atol=1e-9)
    positions, _ = bag.joint_states(DualArmModel().joint_names)
    states = {stamp: q for (_, stamp, _, _), q in zip(bag.states, positions.values, strict=True)}
    np.testing.assert_allclose(np.array([states[s] for s in run.stamps]), run.positions, rtol=0, atol=0)


def test_dualarm_bag_cell_prints_a_parameter_file_that_gives_the_profile_back(
        runs: dict[str, Run], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from dualarm_control.app.cli import main

    assert main(["bag", "cell", str(runs["lbr_dual_position"].bag), "--node", "controller_node"]) == 0
    printed = tmp_path / "cell.yaml"
    printed.write_text(capsys.readouterr().out)
    assert printed.read_text().startswith("controller_node:\n")
    assert load_profile(read_params_file(printed, "controller_node"), DualArmModel().joint_names) == \
        profile_of("lbr_dual_position")
    assert main(["bag", "cell", str(runs["sim"].bag), "--node", "nobody"]) == 2
    assert "no node 'nobody'" in capsys.readouterr().err


@pytest.mark.parametrize("name", PROFILES[1:])
def test_dualarm_report_of_each_profiles_bag_equals_the_default_profiles(runs: dict[str, Run], name: str,
                                                                          tmp_path: Path) -> None:
    """Issue 40: ``dualarm report BAG`` of a run recorded on a hardware profile reads it through the recorded
    profile: every metric of the default profile's report to 1e-6 (the cycle times, wall-clock
    measurements, excepted)."""
    from dualarm_control.app.cli import main

    assert main(["report", str(runs["sim"].bag), "--output", str(tmp_path / "sim")]) == 0
    assert main(["report", str(runs[name].bag), "--output", str(tmp_path / name)]) == 0
    got = report_metrics(tmp_path / name)
    assert_same_report(report_metrics(tmp_path / "sim"), got)
    for label in got:  # the profile's acceleration bound holds, by the report of its bag
        assert got[label]["max_joint_acceleration"] <= 10.0 * (1 + 1e-6), got[label]


def test_the_video_of_a_two_topic_profiles_bag(runs: dict[str, Run], tmp_path: Path) -> None:
    """Issue 40: ``dualarm view BAG --video`` draws a run recorded on lbr_dual_position (joint states on
    /left and /right): as many frames as its duration gives, and the arms move in them."""
    from dualarm_control.app.cli import main
    from dualarm_control.app.view.recording import read_joint_recording

    bag, video = runs["lbr_dual_position"].bag, tmp_path / "run.mp4"
    assert main(["view", str(bag), "--video", str(video), "--fps", "10", "--size", "160x120"]) == 0
    recording = read_joint_recording(bag)
    assert recording.duration_s > 1.0
    assert np.abs(recording.positions[-1] - recording.positions[0]).max() > 0.01
    assert video.stat().st_size > 1000


@pytest.mark.slow
def test_the_assembly_with_each_shipped_profile(tmp_path: Path) -> None:
    """The full assembly (paper 000) in lockstep with each shipped profile: final error < 1 mm, Table I
    equal to the default profile's."""
    got = {name: lockstep_run(name, "assembly", tmp_path / name, 900.0) for name in PROFILES[:3]}
    for name, run in got.items():
        assert run.final_error < 1e-3, name
        assert_same_run(got["sim"], run)


@pytest.mark.parametrize("name", ["lbr_dual_position", "servo_trajectories"])
def test_position_commands_stay_within_one_cycle_at_the_velocity_limit(runs: dict[str, Run], name: str) -> None:
    run = runs[name]
    qd_max = DualArmModel().qd_max
    assert run.position_commands
    for idx, values in run.position_commands:
        measured = run.positions[: len(values), idx]  # command k was computed at the state of stamp k
        gap = np.abs(values - measured) / (qd_max[idx] * PERIOD)
        assert gap.max() <= 1.0 + 1e-9, f"command {gap.max():.3f} v_max T from the measured position"


def dualarm_node(name: str, *args: str, log: Path | None = None) -> Any:
    """``dualarm run NAME`` with the position profile; its output into ``log`` (else discarded)."""
    import subprocess
    import sys

    out = subprocess.DEVNULL if log is None else log.open("w")
    return subprocess.Popen([sys.executable, "-m", "dualarm_control.app.cli", "run", name, "--ros-args",
                             "-p", f"scenario:={SHORT}", "--params-file",
                             str(ROOT / "config" / "hardware" / "lbr_dual_position.yaml"), *args],
                            stdout=out, stderr=subprocess.STDOUT, env=node_env())


def test_position_commands_hold_the_arms_after_the_controller_is_killed(tmp_path: Path) -> None:
    """Real time, lbr_dual_position: once the arms move, SIGKILL the controller; the last position
    commands hold the arms: the simulator goes on publishing joint states (their stamps advance a whole
    second past the kill on both topics) and the arms do not drift in that second; the simulator and
    the trajectory node then stop cleanly (exit 0). A hang guard's failure shows each node's exit code
    and the end of its output."""
    import time

    from sensor_msgs.msg import JointState

    from dualarm_control.ros.node import tool_node

    hang_guard_s = 120.0  # a hang guard, not a timing claim
    latest: dict[str, tuple[int, dict[str, float]]] = {}  # topic -> (stamp ns, positions by name)
    names = ("sim_node", "controller_node", "trajectory_node")
    procs = [dualarm_node(names[0], log=tmp_path / f"{names[0]}.log")]

    def nodes_text() -> str:
        return "\n".join(f"--- {name} (exit {p.poll()}):\n" + "\n".join(
            (tmp_path / f"{name}.log").read_text(errors="replace").splitlines()[-15:])
            for name, p in zip(names, procs, strict=False))

    def on_state(topic: str, m: JointState) -> None:
        latest[topic] = (m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec, dict(zip(m.name, m.position)))

    try:
        with tool_node("hold_probe") as (node, executor, _):
            for topic in ("/left/joint_states", "/right/joint_states"):
                node.create_subscription(JointState, topic, lambda m, t=topic: on_state(t, m), 10)

            def q() -> np.ndarray:
                merged = {**latest["/left/joint_states"][1], **latest["/right/joint_states"][1]}
                return np.array([merged[n] for n in DualArmModel().joint_names])

            def oldest_stamp() -> int:
                return min(stamp for stamp, _ in latest.values())

            def spin_until(cond: Any, what: str) -> None:
                end = time.monotonic() + hang_guard_s
                while not cond():
                    assert time.monotonic() < end, f"hang guard: {what}; saw {latest.keys()}\n{nodes_text()}"
                    executor.spin_once(timeout_sec=0.05)

            # The probe holds the start before the motion can begin: a probe that discovered the simulator
            # late (seconds, on a loaded machine) took its start after the scenario's end and waited for a
            # motion that was over (the hang of issue 38).
            spin_until(lambda: len(latest) == 2, "joint states on both topics")
            start = q()
            procs += [dualarm_node(name, log=tmp_path / f"{name}.log") for name in names[1:]]
            spin_until(lambda: np.abs(q() - start).max() > 5e-3, "the arms moving")
            procs[1].kill()
            procs[1].wait(timeout=30)
            killed = max(stamp for stamp, _ in latest.values())  # the simulator's clock at the kill (or later)
            spin_until(lambda: oldest_stamp() > killed + 200_000_000, "joint states 0.2 s past the kill")
            held = q()
            spin_until(lambda: oldest_stamp() > killed + 1_200_000_000, "joint states 1.2 s past the kill")
            drift = np.abs(q() - held).max()
    finally:
        for p in procs:
            if p.poll() is None:
                p.terminate()
        codes, stuck = [], []
        for name, p in zip(names, procs, strict=False):
            try:
                codes.append(p.wait(timeout=30))
            except subprocess.TimeoutExpired:  # killed, and named below with its output
                p.kill()
                codes.append(p.wait(timeout=30))
                stuck.append(name)
    assert not stuck, f"still running 30 s after SIGTERM (then killed): {stuck}\n{nodes_text()}"
    assert drift < 1e-4, f"the arms drifted {drift:.2e} rad in the second after the controller was killed"
    assert codes[0] == 0 and codes[2] == 0, f"exit codes {codes}\n{nodes_text()}"


@pytest.mark.slow
def test_the_position_profile_in_real_time(tmp_path: Path) -> None:
    """lbr_dual_position in real time (two joint-state topics assembled by stamp, position commands):
    the scenario completes with a final error below 1 mm. ``slow`` (6 s): the default run has the
    profile's lockstep run (Table I equal to the default profile's) and, in real time, the arms driven
    on it until the controller is killed (the test above)."""
    profile = profile_of("lbr_dual_position")
    bag = tmp_path / "bag"
    topics = (*profile.joint_states, *profile.topics, "/diagnostics")
    assert launch_scenario(str(SHORT), [str(profile_file("lbr_dual_position"))], [], False, bag, timeout=240.0,
                           record_topics=topics) == 0
    recorded = read_bag(bag)
    status = [s for d in recorded["/diagnostics"] for s in d.status if s.name == "controller_node"]
    errors = [float(kv.value) for s in status for kv in s.values if kv.key == "position_error_m"]
    assert errors, f"no controller cycle: {[s.message for s in status][-5:]}"
    assert errors[-1] < 1e-3
    assert all(len(recorded[t]) > 100 for t in topics), {t: len(recorded.get(t, [])) for t in topics}
