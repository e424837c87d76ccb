"""The three nodes as real rclpy processes (localhost discovery, a private ROS_DOMAIN_ID).

Lockstep runs must reproduce the in-process experiment exactly (same physics, same solver
path), bags must be readable by rosbags, and bad parameters must exit 2 with a message
that names the key, the value and the valid choices.
"""

from __future__ import annotations

import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest
from launching import selected_tests, side_by_side

from dualarm_control.app.run.experiment import run_scenario
from dualarm_control.app.run.launcher import launch_scenario
from dualarm_control.controller_params import controller_params
from dualarm_control.kinematics import DualArmModel
from dualarm_control.params import read_params_files
from dualarm_control.scenario import load_scenario

SHORT = Path(__file__).parent / "data" / "short.yaml"
SOLVERS = ("pseudo_inverse", "standard_qp", "sparse_qp", "hierarchical_sparse_qp")


def run_cli(*args: str, timeout: float = 60.0) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "dualarm_control.app.cli", *args], capture_output=True, text=True,
                          timeout=timeout, check=False)


BAD_PARAMETERS = [
    ("controller_node", ["-p", "solver:=nope"], ["solver", "nope", "sparse_qp", "standard_qp"]),
    ("controller_node", ["-p", "gain:=10"], ["gain", "10.0"]),
    ("controller_node", ["--params-file", "/nonexistent/params.yaml"], ["/nonexistent/params.yaml"]),
    ("sim_node", ["-p", "scenario:=mars"], ["mars", "assembly"]),
    ("trajectory_node", ["-p", "control_period:=-0.005"], ["control_period", "-0.005", "> 0"]),
]
"""(node, ROS arguments, words of the message): bad values of the nodes' parameters."""


@pytest.fixture(scope="module")
def bad_parameter_runs() -> list[subprocess.CompletedProcess[str]]:
    """``dualarm run NODE --ros-args ...`` for each of :data:`BAD_PARAMETERS`, all at once (each refuses
    its parameters and exits at its start); the results in that order."""
    with ThreadPoolExecutor(max_workers=len(BAD_PARAMETERS)) as pool:
        return list(pool.map(lambda case: run_cli("run", case[0], "--ros-args", *case[1]), BAD_PARAMETERS))


@pytest.mark.parametrize(("node", "ros_args", "expected"), BAD_PARAMETERS)
def test_bad_parameters_exit_2(bad_parameter_runs: list[subprocess.CompletedProcess[str]], node: str,
                               ros_args: list[str], expected: list[str]) -> None:
    """A bad value exits with code 2 and a message naming the key, value and valid values."""
    result = bad_parameter_runs[BAD_PARAMETERS.index((node, ros_args, expected))]
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


PLAN_TEST = "test_plan_run_by_the_nodes"


@pytest.fixture(scope="module")
def launches(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The module's recorded lockstep launches that the run's selected tests use, side by side (each on a
    ROS domain of its own): the short scenario per solver (its solver parameter file; the ``solver``
    parameter of the tests using ``lockstep_bags``, sparse_qp otherwise), and the plan of
    :data:`PLAN_TEST` (planned first); bag paths by solver name, and "plan"."""
    solvers = {getattr(item, "callspec", None) and item.callspec.params.get("solver") or "sparse_qp"
               for item in request.session.items
               if item.module is request.module and "lockstep_bags" in item.fixturenames}
    out = tmp_path_factory.mktemp("lockstep")

    def solver_run(solver: str, env: dict[str, str]) -> Path:
        params = [str(Path(__file__).parents[1] / "config" / "solvers" / f"{solver}.yaml")]
        assert launch_scenario(str(SHORT), params, [], True, out / solver, timeout=240.0, env=env) == 0
        return out / solver

    def plan_run(env: dict[str, str]) -> Path:
        """``dualarm plan corner_path`` (2 key-point starts, no execution in one process: the plan's quality
        is test_planner.py's), then the lockstep launch that runs it. Seed 2: a plan that keeps every link
        pair 51.5 mm apart (seed 0's passes right_link_6 6.4 cm into left_link_1, and since issue 39 a plan is
        tracked under the collision limit: it would stall there, docs/planner.md)."""
        plan = run_cli("plan", "corner_path", "--starts", "2", "--seed", "2", "--no-execute", "--output",
                       str(out / "plan"), timeout=300)
        assert plan.returncode == 0, plan.stderr
        assert "warning: the plan brings" not in plan.stderr, plan.stderr
        assert launch_scenario("corner_path", [], [], True, out / "plan_bag", timeout=240.0,
                               plan=out / "plan" / "plan.json", env=env) == 0
        return out / "plan_bag"

    jobs = {solver: lambda env, solver=solver: solver_run(solver, env) for solver in sorted(solvers)}
    if PLAN_TEST in selected_tests(request):
        jobs["plan"] = plan_run
    return side_by_side(jobs)


@pytest.fixture(scope="module")
def lockstep_bags(launches: dict[str, Path]) -> dict[str, Path]:
    """One recorded lockstep launch of the short scenario per solver (its solver parameter file)."""
    return launches


@pytest.mark.parametrize("solver", SOLVERS)
def test_lockstep_run_matches_in_process_experiment(lockstep_bags: dict[str, Path], solver: str) -> None:
    """Commands and joint states over ROS equal the in-process lockstep run of the same scenario."""
    scenario = load_scenario(str(SHORT))
    values = read_params_files([Path(__file__).parents[1] / "config" / "solvers" / f"{solver}.yaml"],
                               "controller_node")
    log = run_scenario(scenario, controller_params(values), DualArmModel())
    topics = _read_bag(lockstep_bags[solver])
    commands = np.array([m.data for m in topics["/velocity_controller/commands"]])  # type: ignore[attr-defined]
    n = len(log.commands)
    assert len(commands) == n
    np.testing.assert_allclose(commands, log.commands, atol=1e-9, rtol=0)
    # one state per stamp: in lockstep the simulator re-sends the pending state (same stamp, same values) after
    # lockstep_resend (0.5 s) without a command, e.g. while a loaded machine starts the controller
    states: dict[int, object] = {}
    for s in topics["/joint_states"]:
        states.setdefault(s.header.stamp.sec * 10**9 + s.header.stamp.nanosec, s)  # type: ignore[attr-defined]
    stamps = sorted(states)[:n]
    np.testing.assert_array_equal(np.diff(stamps), 5_000_000)  # no state missing in between
    positions = np.array([states[t].position for t in stamps])  # type: ignore[attr-defined]
    np.testing.assert_allclose(positions, log.positions, atol=1e-9, rtol=0)


def test_lockstep_bag_is_on_the_simulation_clock(lockstep_bags: dict[str, Path]) -> None:
    """Stamps and the bag's receive times are simulation time: k * 5 ms from zero, /clock included."""
    from rosbags.highlevel import AnyReader

    bag = lockstep_bags["sparse_qp"]
    topics = _read_bag(bag)
    stamps = [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for m in topics["/joint_states"]]  # type: ignore[attr-defined]
    # The first state may be there more than once: the simulator re-sends it every lockstep_resend (0.5 s) until
    # the first command comes (sim_node.lockstep_watchdog; a loaded machine's controller answered it later once).
    # After the first step no state repeats on reliable streams.
    first = next(i for i, stamp in enumerate(stamps) if stamp != 0)
    assert first >= 1 and stamps[first - 1:first + 2] == [0, 5_000_000, 10_000_000], stamps[:first + 3]
    np.testing.assert_array_equal(np.diff(stamps[first - 1:]), 5_000_000)
    clock = [m.clock.sec * 10**9 + m.clock.nanosec for m in topics["/clock"]]  # type: ignore[attr-defined]
    assert clock == stamps
    with AnyReader([bag]) as reader:
        assert reader.end_time - 1 <= stamps[-1] + 5_000_000  # receive times on the sim clock, not the wall


def test_bag_has_the_graph_with_standard_types(lockstep_bags: dict[str, Path]) -> None:
    """Every graph topic is in the bag with its common_interfaces type; diagnostics name the solver."""
    from rosbags.highlevel import AnyReader

    bag = lockstep_bags["sparse_qp"]
    with AnyReader([bag]) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
    assert types["/joint_states"] == "sensor_msgs/msg/JointState"
    assert types["/velocity_controller/commands"] == "std_msgs/msg/Float64MultiArray"
    assert types["/relative_target"] == "trajectory_msgs/msg/MultiDOFJointTrajectory"
    assert types["/relative_pose"] == "geometry_msgs/msg/PoseStamped"
    assert types["/diagnostics"] == "diagnostic_msgs/msg/DiagnosticArray"
    assert types["/clock"] == "rosgraph_msgs/msg/Clock"
    diags = _read_bag(bag)["/diagnostics"]
    solvers = {kv.value for d in diags for s in d.status if s.name == "controller_node"  # type: ignore[attr-defined]
               for kv in s.values if kv.key == "solver"}
    assert solvers == {"sparse_qp"}


@pytest.mark.parametrize("solver", ("standard_qp", "hierarchical_sparse_qp"))
def test_table_one_means_from_the_bag_equal_in_process(lockstep_bags: dict[str, Path], solver: str,
                                                       tmp_path: Path) -> None:
    """``dualarm report`` on the lockstep bag gives the in-process experiment's Table I means."""
    from dualarm_control.app.record.bag_runs import report
    from dualarm_control.app.record.report import summarize_run

    scenario = load_scenario(str(SHORT))
    model = DualArmModel()
    log = run_scenario(scenario, controller_params({"solver": solver}), model)
    expected = summarize_run(log, scenario, model)
    got = report(lockstep_bags[solver], tmp_path)[0][solver]
    for key in ("l0_mean", "l1_mean", "l2_mean"):
        assert got[key] == pytest.approx(expected[key], rel=1e-9, abs=1e-12), key


def test_plan_run_by_the_nodes(launches: dict[str, Path], tmp_path: Path) -> None:
    """``dualarm launch corner_path --plan``: the trajectory node streams the plan's joint trajectory,
    the controller tracks it; the executed relative pose stays within 1 mm / 5 mrad of the reference.
    The plan's quality is test_planner.py's: 2 key-point starts and no execution in one process
    (``--no-execute``) are enough for a plan to track (``launches`` plans and runs it)."""
    from dualarm_control.app.record.bag_runs import report

    bag = launches["plan"]
    metrics = report(bag, tmp_path / "report")[0]["joint_tracking"]
    assert metrics["solver_failures"] == 0 and metrics["joint_velocity_limit_violations"] == 0
    assert metrics["max_tracking_error_m"] < 1e-3 and metrics["max_tracking_error_rad"] < 5e-3
    assert metrics["duration_s"] > 5.0
    topics = _read_bag(bag)
    assert len(topics["/joint_reference"]) == len(topics["/velocity_controller/commands"])


def test_launch_refuses_a_plan_of_another_scenario(tmp_path: Path) -> None:
    bad = tmp_path / "plan.json"
    bad.write_text('{"format": "something else"}')
    out = run_cli("launch", "corner_path", "--plan", str(bad), "--lockstep")
    assert out.returncode == 2 and "not a dualarm_control/plan/1 document" in out.stderr
