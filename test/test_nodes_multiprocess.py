"""The three nodes as real processes over loopback DDS.

Lockstep runs must reproduce the in-process experiment exactly (same physics, same solver
path), bags must be readable by rosbags, and bad parameters must exit 2 with a message
that names the key, the value and the valid choices.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from dualarm_control.app.experiment import run_scenario
from dualarm_control.app.launcher import launch_scenario
from dualarm_control.controller import controller_params
from dualarm_control.kinematics import DualArmModel
from dualarm_control.scenario import load_scenario

SHORT = Path(__file__).parent / "data" / "short.yaml"


def run_cli(*args: str, timeout: float = 60.0) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "dualarm_control.app.cli", *args], capture_output=True, text=True,
                          timeout=timeout, check=False)


@pytest.mark.parametrize(
    ("node", "ros_args", "expected"),
    [
        ("controller_node", ["-p", "solver:=nope"], ["solver", "nope", "sparse_qp", "standard_qp"]),
        ("controller_node", ["-p", "gain:=10"], ["gain", "10.0"]),
        ("controller_node", ["--params-file", "/nonexistent/params.yaml"], ["/nonexistent/params.yaml"]),
        ("sim_node", ["-p", "scenario:=mars"], ["mars", "assembly"]),
        ("trajectory_node", ["-p", "control_period:=-0.005"], ["control_period", "-0.005", "> 0"]),
    ],
)
def test_bad_parameters_exit_2(node: str, ros_args: list[str], expected: list[str]) -> None:
    """A bad value exits with code 2 and a message naming the key, value and valid values."""
    result = run_cli("run", node, "--ros-args", *ros_args)
    assert result.returncode == 2, result.stderr
    for word in expected:
        assert word in result.stderr


def test_malformed_params_file_exits_2(tmp_path: Path) -> None:
    """A params file that is not valid YAML exits 2 and says where."""
    bad = tmp_path / "bad.yaml"
    bad.write_text("controller_node:\n  ros__parameters:\n    solver: [sparse_qp\n")
    result = run_cli("run", "controller_node", "--ros-args", "--params-file", str(bad))
    assert result.returncode == 2
    assert "bad.yaml" in result.stderr


def _read_bag(bag: Path) -> dict[str, list[object]]:
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    out: dict[str, list[object]] = {}
    with AnyReader([bag], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        for conn, _, raw in reader.messages():
            out.setdefault(conn.topic, []).append(reader.deserialize(raw, conn.msgtype))
    return out


@pytest.fixture(scope="module")
def lockstep_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    bag = tmp_path_factory.mktemp("lockstep") / "bag"
    params = [str(Path(__file__).parents[1] / "config" / "solvers" / "sparse_qp.yaml")]
    assert launch_scenario(str(SHORT), params, [], True, bag, timeout=240.0) == 0
    return bag


def test_lockstep_run_matches_in_process_experiment(lockstep_bag: Path) -> None:
    """Commands and joint states over DDS equal the in-process lockstep run of the same scenario."""
    scenario = load_scenario(str(SHORT))
    log = run_scenario(scenario, controller_params({"solver": "sparse_qp"}), DualArmModel())
    topics = _read_bag(lockstep_bag)
    commands = np.array([m.data for m in topics["/velocity_controller/commands"]])  # type: ignore[attr-defined]
    n = min(len(commands), len(log.commands))
    assert n >= len(log.commands) - 2, (len(commands), len(log.commands))
    np.testing.assert_allclose(commands[:n], log.commands[:n], atol=1e-9)
    states = topics["/joint_states"]
    positions = np.array([s.position for s in states[:n]])  # type: ignore[attr-defined]
    np.testing.assert_allclose(positions, log.positions[:n], atol=1e-9)


def test_bag_has_the_graph_with_standard_types(lockstep_bag: Path) -> None:
    """Every graph topic is in the bag with its common_interfaces type; diagnostics name the solver."""
    from rosbags.highlevel import AnyReader

    with AnyReader([lockstep_bag]) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
    assert types["/joint_states"] == "sensor_msgs/msg/JointState"
    assert types["/velocity_controller/commands"] == "std_msgs/msg/Float64MultiArray"
    assert types["/relative_target"] == "trajectory_msgs/msg/MultiDOFJointTrajectory"
    assert types["/relative_pose"] == "geometry_msgs/msg/PoseStamped"
    assert types["/diagnostics"] == "diagnostic_msgs/msg/DiagnosticArray"
    diags = _read_bag(lockstep_bag)["/diagnostics"]
    solvers = {kv.value for d in diags for s in d.status if s.name == "controller_node"  # type: ignore[attr-defined]
               for kv in s.values if kv.key == "solver"}
    assert solvers == {"sparse_qp"}
