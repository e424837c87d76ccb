"""Fuzzing (issue 11): parameter YAML and raw CDR payloads give the package's own errors, never a crash.

(a) Hypothesis-generated text and YAML structures fed to the params-file reader, to
    ``controller_params`` and to scenario loading: a result, or ParameterError /
    ScenarioError / DualArmError with a message, never another exception, never a hang.
(b) Random and garbled serialized bytes published by a real rclpy publisher on the topics
    that controller_node and sim_node subscribe: the processes keep running, report
    "malformed message on /topic" and still answer a valid message afterwards.
"""

from __future__ import annotations

import math
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from waiting import NodeProcess, exited, tail, wait_until

from dualarm_control.controller_params import CONTROLLER_PARAMETERS, controller_params
from dualarm_control.errors import DualArmError
from dualarm_control.params import read_params_file
from dualarm_control.scenario import load_scenario

FUZZ = settings(max_examples=150, deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
HANG_S = 60
"""Per example: "never a hang". A guard against a hang (a YAML alias bomb, a loop that never ends),
not a speed figure: it must not trip on a loaded machine, where an example takes milliseconds to a second."""


class Hung(Exception):
    """An example did not return within :data:`HANG_S`."""


@contextmanager
def hang_guard(seconds: int = HANG_S) -> Iterator[None]:
    """Raise :class:`Hung` in the main thread if the block runs longer than ``seconds`` (SIGALRM)."""
    def on_alarm(signum: int, frame: Any) -> None:
        raise Hung(f"no result within {seconds} s: a hang")

    previous = signal.signal(signal.SIGALRM, on_alarm)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)

# ---- (a) parameter YAML ------------------------------------------------------------------------

scalars = st.one_of(
    st.none(), st.booleans(), st.integers(-10**12, 10**12), st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=12), st.sampled_from(["hierarchical_sparse_qp", "daqp", "relative", ".nan", "1e400", "~"]),
)
values = st.recursive(scalars, lambda inner: st.one_of(st.lists(inner, max_size=5),
                                                       st.dictionaries(st.text(max_size=8), inner, max_size=4)),
                      max_leaves=12)
CONTROLLER_KEYS = [spec.name for spec in CONTROLLER_PARAMETERS]


def write(tmp_path: Path, name: str, data: str | bytes) -> Path:
    path = tmp_path / name
    path.write_bytes(data if isinstance(data, bytes) else data.encode("utf-8", "surrogatepass"))
    return path


def only_own_errors(call: Any) -> str:
    """Run ``call()``; return 'ok' or the DualArmError's message; any other exception (a hang
    included) fails the test."""
    try:
        with hang_guard():
            call()
        outcome = "ok"
    except DualArmError as exc:
        assert str(exc).strip(), "an error without a message"
        outcome = str(exc)
    return outcome


@FUZZ
@given(st.one_of(st.binary(max_size=300), st.text(max_size=300)))
def test_params_file_reader_on_random_bytes_and_text(tmp_path: Path, data: bytes | str) -> None:
    """Any file content: parameters or ParameterFileError (a ParameterError), nothing else."""
    path = write(tmp_path, "random.yaml", data)
    only_own_errors(lambda: read_params_file(path, "controller_node"))


@st.composite
def controller_files(draw: st.DrawFn) -> str:
    """ROS-style parameter files for controller_node: real keys with random values, random keys, random layout."""
    params = draw(st.dictionaries(st.sampled_from(CONTROLLER_KEYS), values, max_size=6))
    params.update(draw(st.dictionaries(st.text(max_size=6), values, max_size=2)))
    section = draw(st.sampled_from(["controller_node", "/**", "/controller_node"]))
    layout = draw(st.sampled_from(["ok", "no_ros_parameters", "list", "scalar"]))
    doc: Any = {section: {"ros__parameters": params}}
    if layout == "no_ros_parameters":
        doc = {section: params}
    elif layout == "list":
        doc = [doc]
    elif layout == "scalar":
        doc = {section: {"ros__parameters": draw(scalars)}}
    return yaml.safe_dump(doc, allow_unicode=True)


@FUZZ
@given(controller_files())
def test_controller_parameter_files(tmp_path: Path, text: str) -> None:
    """Random controller parameter files through the reader and controller_params: ControllerParams or ParameterError."""
    path = write(tmp_path, "controller.yaml", text)
    only_own_errors(lambda: controller_params(read_params_file(path, "controller_node")))


def scenario_doc(scenario: dict[str, Any]) -> str:
    return yaml.safe_dump({"/**": {"ros__parameters": {"scenario": scenario}}}, allow_unicode=True)


@st.composite
def scenario_files(draw: st.DrawFn) -> str:
    """The assembly scenario with random keys replaced by random values (limits, segments, vectors...)."""
    base = yaml.safe_load(Path(load_scenario("assembly").source).read_text())["/**"]["ros__parameters"]["scenario"]
    keys = ["name", "initial_positions_deg", "settle_time", "limits", "segments", "approach", "insert", "screw"]
    for key in draw(st.lists(st.sampled_from(keys), max_size=3, unique=True)):
        base[key] = draw(values)
    if isinstance(base.get("limits"), dict):
        for limit in draw(st.lists(st.sampled_from([*base["limits"].keys(), "warp"]), max_size=2, unique=True)):
            base["limits"][limit] = draw(scalars)
    if isinstance(base.get("approach"), dict) and draw(st.booleans()):
        base["approach"][draw(st.sampled_from(["type", "position", "rpy_deg", "hold"]))] = draw(values)
    return scenario_doc(base)


@FUZZ
@given(scenario_files())
def test_scenario_files(tmp_path: Path, text: str) -> None:
    """Random scenario files: a Scenario (whose trajectory then builds) or ScenarioError naming a key."""
    path = write(tmp_path, "scenario.yaml", text)
    outcome = only_own_errors(lambda: load_scenario(str(path)))
    if outcome != "ok":
        assert "scenario" in outcome
        return
    scenario = load_scenario(str(path))
    only_own_errors(lambda: scenario.trajectory(np.zeros(3), np.eye(3)))


def test_bad_limit_is_named_with_key_and_value(tmp_path: Path) -> None:
    """Scenario limits: key and value in the message, for each kind of bad value."""
    for bad in (-1.0, 0.0, math.inf, "fast", True):
        base = yaml.safe_load(Path(load_scenario("assembly").source).read_text())["/**"]["ros__parameters"]["scenario"]
        base["limits"]["max_linear_jerk"] = bad
        path = write(tmp_path, "limits.yaml", scenario_doc(base))
        message = only_own_errors(lambda p=path: load_scenario(str(p)))
        assert "scenario.limits.max_linear_jerk" in message and repr(bad) in message, message


@pytest.mark.parametrize("key", ["gain", "control_period", "l1_weight", "qp_eps_abs", "regularization"])
@pytest.mark.parametrize("bad", [math.inf, -math.inf, math.nan])
def test_non_finite_controller_parameters_are_parameter_errors(tmp_path: Path, key: str, bad: float) -> None:
    """inf and NaN in a double parameter: ParameterError naming the key (not a bare ValueError)."""
    path = write(tmp_path, "c.yaml", yaml.safe_dump({"controller_node": {"ros__parameters": {key: bad}}}))
    message = only_own_errors(lambda: controller_params(read_params_file(path, "controller_node")))
    assert key in message, message


# ---- (b) raw CDR payloads on the subscribed topics of running nodes -----------------------------

REPO = Path(__file__).resolve().parents[1]
PAYLOADS_PER_TOPIC = 200


def garbled(rng: np.random.Generator, valid: bytes) -> bytes:
    """Random bytes, a truncated or bit-flipped valid sample, or a valid one with a huge sequence length."""
    kind = rng.integers(0, 4)
    if kind == 0:
        return rng.bytes(int(rng.integers(0, 200)))
    if kind == 1:
        return valid[: int(rng.integers(0, len(valid)))]
    data = bytearray(valid)
    if kind == 2:
        for i in rng.integers(0, len(data), size=int(rng.integers(1, 8))):
            data[i] ^= 1 << int(rng.integers(0, 8))
    else:
        i = int(rng.integers(4, max(len(data) - 4, 5)))
        data[i:i + 4] = b"\xff\xff\xff\x7f"
    return bytes(data)


def bad_messages(names: list[str]) -> dict[str, list[Any]]:
    """Well-formed samples with bad content, per topic: names, counts, NaN, stamps, reach, lengths."""
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray

    from dualarm_control.ros import convert

    q = [0.1] * len(names)
    now = time.time_ns()
    target = SimpleNamespace(position=np.array([5.0, 0.0, 0.0]), rotation=np.eye(3), linear_velocity=np.zeros(3),
                             angular_velocity=np.zeros(3), linear_acceleration=np.zeros(3),
                             angular_acceleration=np.zeros(3))
    nan_target = SimpleNamespace(**{**vars(target), "position": np.array([np.nan, 0.0, 0.0])})
    return {
        "/joint_states": [
            JointState(name=names[:-1], position=q[:-1]),  # a joint missing
            JointState(name=[names[0], *names[:-1]], position=q),  # a duplicate
            JointState(name=names, position=q[:-2]),  # too few positions
            JointState(name=names, position=[np.nan, *q[1:]]),
            JointState(name=names, position=[np.inf, *q[1:]]),
            convert.joint_state(names, 0, np.array(q), np.zeros(len(q))),  # stamp far in the past
        ],
        "/relative_target": [convert.target_message(now, 0, target), convert.target_message(now, 0, nan_target)],
        "/velocity_controller/commands": [Float64MultiArray(data=[0.0] * 13), Float64MultiArray(data=[np.nan] * 14)],
    }


REPORTED = (
    ("controller_node", "malformed message on /joint_states"),
    ("controller_node", "malformed message on /relative_target"),
    ("sim_node", "malformed message on /velocity_controller/commands"),
    *(("controller_node", f) for f in ("missing 1 of the 14", "duplicate joint names", "positions", "NaN or inf",
                                       "older than the last accepted", "beyond the cell's reach",
                                       "time source restarted")),
    *(("sim_node", f) for f in ("13 values rejected", "NaN or inf")),
)
"""(node, fragment): each rejection a node must report on /diagnostics."""
READ_BY = {"sim_node": ("/velocity_controller/commands",), "controller_node": ("/joint_states", "/relative_target")}
"""The topics of the fuzzed ones each node reads."""


def test_garbled_cdr_and_bad_messages_on_running_nodes() -> None:
    """controller_node and sim_node survive random/garbled CDR and bad content on every subscribed topic:
    still running, "malformed message on /topic" and each rejection on /diagnostics, and still working
    afterwards (the controller commands, the simulator publishes states). A valid state from the future
    makes the simulator's states older: after 3 of them the controller logs "time source restarted"."""
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray
    from trajectory_msgs.msg import MultiDOFJointTrajectory

    from dualarm_control.kinematics import DualArmModel
    from dualarm_control.ros import convert
    from dualarm_control.ros.node import init_rclpy

    names = DualArmModel().joint_names
    sim = NodeProcess("sim_node", "-p", "command_timeout:=0.2")
    controller = NodeProcess("controller_node")
    context = init_rclpy([])
    node = rclpy.create_node("fuzzer", context=context)
    executor = rclpy.executors.SingleThreadedExecutor(context=context)
    executor.add_node(node)
    diagnostics: list[tuple[str, str]] = []
    commands: list[float] = []
    node.create_subscription(DiagnosticArray, "/diagnostics",
                             lambda m: diagnostics.extend((s.name, s.message) for s in m.status), 1000)
    node.create_subscription(Float64MultiArray, "/velocity_controller/commands",
                             lambda m: commands.append(time.monotonic()), 100)
    types = {"/joint_states": JointState, "/relative_target": MultiDOFJointTrajectory,
             "/velocity_controller/commands": Float64MultiArray}
    pubs = {topic: node.create_publisher(kind, topic, 1000) for topic, kind in types.items()}
    valid = {"/joint_states": convert.joint_state(names, time.time_ns(), np.zeros(14), np.zeros(14)),  # CDR bytes
             "/relative_target": bad_messages(names)["/relative_target"][0],
             "/velocity_controller/commands": serialize_message(Float64MultiArray(data=[0.0] * 14))}

    def spin(seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            executor.spin_once(timeout_sec=0.01)

    def both_tails() -> str:
        return f"sim_node:\n{tail(sim.lines, 10)}\ncontroller_node:\n{tail(controller.lines, 10)}"

    def died() -> str | None:
        return exited(sim.popen, "sim_node")() or exited(controller.popen, "controller_node")()

    try:
        wait_until(lambda: all(p.get_subscription_count() >= 1 for p in pubs.values()) and commands, both_tails,
                   what="the nodes up (every topic subscribed, a command)", step=lambda: spin(0.1), gone=died)
        rng = np.random.default_rng(11)
        for topic, pub in pubs.items():
            for _ in range(PAYLOADS_PER_TOPIC):
                pub.publish(garbled(rng, valid[topic]))
                spin(0.002)
            for msg in bad_messages(names)[topic]:
                pub.publish(msg)
                spin(0.01)

        def future() -> bytes:
            return convert.joint_state(names, time.time_ns() + 1000 * convert.NS, np.zeros(14), np.zeros(14))

        pubs["/joint_states"].publish(future())

        def missing() -> list[tuple[str, str]]:
            return [(node, f) for node, f in REPORTED if not any(f in m for n, m in diagnostics if n == node)]

        def again() -> None:
            """The bad samples whose rejection is not reported yet, once more: a node's subscription keeps its last
            few samples (keep-last), and the node's own peer publishes on the same topic at 200 Hz (the controller
            its commands, the simulator its states), so on a loaded machine a sample can be replaced before the
            node takes it (seen beside stress-ng: the simulator never took the 13-value command). What is tested is
            that each rejection is reported, not that every sample of a burst is delivered."""
            gone = missing()
            for topic in sorted({t for node, _ in gone for t in READ_BY[node]}):
                pubs[topic].publish(garbled(rng, valid[topic]))
                for msg in bad_messages(names)[topic]:
                    pubs[topic].publish(msg)
            if any(fragment == "time source restarted" for _, fragment in gone):
                pubs["/joint_states"].publish(future())
            spin(0.1)

        wait_until(lambda: not missing(), missing, what="every rejection on /diagnostics", step=again, gone=died)
        after = time.monotonic()
        # still commanding after it all: 50 commands more (0.25 s at 200 Hz; the deadline is not a rate)
        wait_until(lambda: sum(t > after for t in commands) >= 50, lambda: f"{sum(t > after for t in commands)} "
                   "commands\n" + both_tails(), what="50 more commands", step=lambda: spin(0.1), gone=died)
        assert died() is None, "a node died:\n" + both_tails()
    finally:
        node.destroy_node()
        context.try_shutdown()
        codes = controller.stop(), sim.stop()
    by_node = {name: [m for n, m in diagnostics if n == name] for name in ("controller_node", "sim_node")}
    for node, fragment in REPORTED:  # waited for above; each one here again, named
        assert any(fragment in m for m in by_node[node]), (node, fragment)
    assert any("time source restarted" in line for line in controller.lines)
    assert codes == (0, 0), (controller.lines[-20:], sim.lines[-20:])
    assert not any("Traceback" in line for line in controller.lines + sim.lines)


def alias_bomb(levels: int = 9) -> str:
    """A parameter file of 'billion laughs' shape: each level a map of 9 aliases of the level below; under
    900 bytes, 9^9 (387 million) maps once expanded."""
    lines = ["controller_node:", "  ros__parameters:", "    l0: &l0 {a: 1, b: 1, c: 1, d: 1, e: 1, f: 1, g: 1, h: 1, i: 1}"]
    for k in range(1, levels):
        lines.append(f"    l{k}: &l{k} {{" + ", ".join(f"k{j}: *l{k - 1}" for j in range(9)) + "}")
    return "\n".join([*lines, f"    gain: *l{levels - 1}", ""])


@pytest.mark.parametrize(("text", "words"), [(alias_bomb(), "its aliases expand to 1852354213 values"),
                                              ("controller_node:\n  ros__parameters:\n    loop: &a [1, *a]\n",
                                               "its aliases expand to a recursive structure")])
def test_an_alias_bomb_is_refused_at_once(tmp_path: Path, text: str, words: str) -> None:
    """The reader refuses a file whose aliases expand beyond MAX_EXPANDED_VALUES (or forever), naming the file,
    within the hang guard (before the bound: no result after 20 s of flattening); files using a few aliases load."""
    path = write(tmp_path, "bomb.yaml", text)
    message = only_own_errors(lambda: read_params_file(path, "controller_node"))
    assert str(path) in message and words in message, message
    segments = read_params_file(Path(__file__).parent / "data" / "back_and_forth.yaml", "trajectory_node")
    assert segments["scenario.there4.position"] == [0.05, 0.0, 0.12]  # its 40 segments are aliases


def test_the_commands_refuse_an_alias_bomb_with_exit_2(tmp_path: Path) -> None:
    path = write(tmp_path, "bomb.yaml", alias_bomb())
    out = tmp_path / "out"
    done = subprocess.run([sys.executable, "-m", "dualarm_control.app.cli", "experiment", "assembly", "--params",
                           str(path), "--output", str(out)], cwd=REPO, capture_output=True, text=True, timeout=300,
                          check=False)
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr[-3000:]
    assert f"parameter file {path}: its aliases expand to" in done.stderr and not out.exists(), done.stderr
