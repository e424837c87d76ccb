"""Tests of ROS-style parameter files (dualarm_control.params, controller_params) and scenarios (dualarm_control.scenario)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from dualarm_control.controller_params import controller_params
from dualarm_control.errors import ParameterError, ScenarioError
from dualarm_control.kinematics import rotation_angle
from dualarm_control.params import (
    ParameterFileError,
    flatten,
    read_params_file,
    read_params_files,
)
from dualarm_control.scenario import load_scenario, scenario_names
from dualarm_control.solvers import solver_names

PARAMS = """\
/**:
  ros__parameters:
    gain: 5.0
    alpha: 0.2
    shared:
      depth: 1
/ns/**:
  ros__parameters:
    alpha: 0.3
controller_node:
  ros__parameters:
    gain: 20.0
    scenario:
      limits:
        max_linear_velocity: 0.04
      segments: [a, b]
other_node:
  ros__parameters:
    gain: 99.0
/ns/controller_node:
  ros__parameters:
    solver: sparse_qp
"""


def write(tmp_path: Path, text: str, name: str = "p.yaml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def rot_x(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


# ---- parameter files ----------------------------------------------------------------------------


def test_wildcard_then_node_section_node_wins_and_keys_are_flattened(tmp_path: Path) -> None:
    """Hand-derived expected dict: /** applied first, the node's own section overrides, nested keys dotted."""
    got = read_params_file(write(tmp_path, PARAMS), "controller_node")
    assert got == {
        "gain": 20.0,
        "alpha": 0.2,
        "shared.depth": 1,
        "scenario.limits.max_linear_velocity": 0.04,
        "scenario.segments": ["a", "b"],
    }


def test_namespaced_sections_apply_in_their_namespace(tmp_path: Path) -> None:
    """In /ns: /** < /ns/** < controller_node < /ns/controller_node; other nodes' sections never apply."""
    got = read_params_file(write(tmp_path, PARAMS), "controller_node", namespace="/ns")
    assert got["alpha"] == 0.3 and got["gain"] == 20.0 and got["solver"] == "sparse_qp"
    other = read_params_file(write(tmp_path, PARAMS), "other_node")
    assert other == {"gain": 99.0, "alpha": 0.2, "shared.depth": 1}
    assert read_params_file(write(tmp_path, PARAMS), "unknown_node") == {"gain": 5.0, "alpha": 0.2, "shared.depth": 1}


def test_flatten_nested_maps() -> None:
    """flatten vs a hand-written dotted dict (lists are leaves)."""
    assert flatten({"a": {"b": {"c": 1}, "d": [1, 2]}, "e": "x"}) == {"a.b.c": 1, "a.d": [1, 2], "e": "x"}


def test_later_files_win(tmp_path: Path) -> None:
    """read_params_files merges in order, like repeated --params-file."""
    a = write(tmp_path, "/**:\n  ros__parameters:\n    gain: 1.0\n    alpha: 0.5\n", "a.yaml")
    b = write(tmp_path, "/**:\n  ros__parameters:\n    gain: 2.0\n", "b.yaml")
    assert read_params_files([a, b], "n") == {"gain": 2.0, "alpha": 0.5}


def test_empty_file_gives_no_parameters(tmp_path: Path) -> None:
    """An empty YAML document is an empty parameter set."""
    assert read_params_file(write(tmp_path, ""), "n") == {}


def test_malformed_yaml_error_names_the_line(tmp_path: Path) -> None:
    """A tab on line 4 (YAML forbids tabs for indentation): the error names line 4 and the file."""
    path = write(tmp_path, "/**:\n  ros__parameters:\n    gain: 1.0\n\talpha: 0.1\n")
    with pytest.raises(ParameterFileError, match="line 4") as info:
        read_params_file(path, "n")
    assert str(path) in str(info.value) and "malformed YAML" in str(info.value)


def test_missing_file_error(tmp_path: Path) -> None:
    """A missing file raises ParameterFileError (a ParameterError) saying 'file not found'."""
    path = tmp_path / "absent.yaml"
    with pytest.raises(ParameterFileError, match="file not found") as info:
        read_params_file(path, "n")
    assert isinstance(info.value, ParameterError) and str(path) in str(info.value)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("- 1\n- 2\n", "top level"),
        ("n:\n  gain: 1.0\n", "ros__parameters"),
        ("n:\n  ros__parameters: [1, 2]\n", "must be a map"),
    ],
)
def test_wrong_layout_errors(tmp_path: Path, text: str, message: str) -> None:
    """Not a map of nodes / no ros__parameters / parameters not a map: ParameterFileError explaining it."""
    with pytest.raises(ParameterFileError, match=message):
        read_params_file(write(tmp_path, text), "n")


def test_integer_for_a_double_parameter_says_write_200_point_0(tmp_path: Path) -> None:
    """ROS 2 typing: 'gain: 200' (an integer) for a double is refused with the hint '200.0'."""
    values = read_params_file(write(tmp_path, "controller_node:\n  ros__parameters:\n    gain: 200\n"), "controller_node")
    with pytest.raises(ParameterError, match="200.0") as info:
        controller_params(values)
    assert info.value.key == "controller_node.gain" and info.value.value == 200
    assert controller_params({"gain": 200.0}).gain == 200.0


def test_unknown_solver_parameter_lists_valid_solvers() -> None:
    """solver 'nope' -> ParameterError listing every registered solver."""
    with pytest.raises(ParameterError) as info:
        controller_params({"solver": "nope"})
    for name in solver_names():
        assert name in str(info.value)
    assert "'nope'" in str(info.value)


@pytest.mark.parametrize(
    ("key", "value", "fragment"),
    [("alpha", 1.5, "[0, 1]"), ("control_period", 0.0, "> 0"), ("velocity_scale", 0.0, "(0, 1]"),
     ("qp_backend", "nope", "proxsuite"), ("qp_max_iter", 1.5, "integer"), ("solver", 3, "string"),
     ("acceleration_limit", [-1.0], "values > 0"), ("acceleration_limit", 10.0, "double array"),
     ("proximal_weight", -1e-6, ">= 0")],
)
def test_controller_params_validation(key: str, value: object, fragment: str) -> None:
    """Range, choice and type checks name the parameter and the expectation."""
    with pytest.raises(ParameterError, match=key) as info:
        controller_params({key: value})
    assert fragment in str(info.value)


def test_controller_params_map_to_the_dataclasses() -> None:
    """File names (control_period, qp_eps_abs, ...) land in the right ControllerParams/SolverParams fields."""
    p = controller_params({"solver": "sparse_qp", "control_period": 0.01, "alpha": 0.0, "l1_weight": 1e-5,
                           "regularization": 0.0, "qp_eps_abs": 1e-8, "qp_max_iter": 50, "velocity_scale": 0.5})
    assert (p.solver, p.period, p.alpha, p.velocity_scale, p.gain) == ("sparse_qp", 0.01, 0.0, 0.5, 10.0)
    sp = p.solver_params
    assert (sp.l1_weight, sp.regularization, sp.qp.eps_abs, sp.qp.max_iter) == (1e-5, 0.0, 1e-8, 50)
    assert (sp.qp_backend, sp.proximal_weight, p.acceleration_limit) == ("daqp", 1e-6, ())  # defaults


def test_acceleration_limit_one_value_or_one_per_joint() -> None:
    """[0.0] = no bound; [a] for every joint; 14 values per joint; another length is refused by the controller."""
    from dualarm_control.controller import RelativeController
    from dualarm_control.kinematics import DualArmModel

    assert controller_params({"acceleration_limit": [0.0]}).acceleration_limit == ()
    assert controller_params({"acceleration_limit": [10.0]}).acceleration_limit == (10.0,)
    per_joint = [float(v) for v in range(1, 15)]
    model = DualArmModel()
    RelativeController(model, controller_params({"acceleration_limit": per_joint}))
    with pytest.raises(ValueError, match="0, 1 or 14 values"):
        RelativeController(model, controller_params({"acceleration_limit": [1.0, 2.0]}))


# ---- scenarios ------------------------------------------------------------------------------------


def test_assembly_scenario_loads_with_the_file_values() -> None:
    """load_scenario('assembly') vs the numbers written in config/scenarios/assembly.yaml."""
    sc = load_scenario("assembly")
    assert "assembly" in scenario_names()
    assert sc.name == "assembly" and sc.settle_time == 1.0
    deg = [19.0, -31.0, -54.0, 16.0, 98.0, -56.0, 100.0, -12.0, -27.0, 55.0, 19.0, -90.0, -70.0, 105.0]
    np.testing.assert_allclose(sc.initial_positions, np.radians(deg), atol=1e-15)
    assert [s.name for s in sc.reference.segments] == ["approach", "insert", "screw"]
    assert [s.kind for s in sc.reference.segments] == ["pose", "pose", "screw"]
    np.testing.assert_allclose(sc.reference.segments[0].rotation, rot_x(math.pi), atol=1e-12)
    assert sc.reference.segments[2].angle == pytest.approx(2 * math.pi) and sc.reference.segments[2].advance == -0.01
    assert sc.limits.max_linear_velocity == 0.05 and sc.limits.max_angular_jerk == 5.0


def test_assembly_trajectory_starts_at_the_given_pose_and_chains_segments() -> None:
    """sample(0) is the given start pose; segment ends are the file's poses (screw: insert + pitch along z)."""
    sc = load_scenario("assembly")
    p0 = np.array([0.1, -0.05, 0.3])
    r0 = rot_x(0.4)
    traj = sc.trajectory(p0, r0)
    first = traj.sample(0.0)
    np.testing.assert_allclose(first.position, p0, atol=1e-15)
    np.testing.assert_allclose(first.rotation, r0, atol=1e-15)
    p_end, r_end = traj.segment_end_pose(0)
    np.testing.assert_allclose(p_end, [0.0, 0.0, 0.05], atol=1e-15)
    assert rotation_angle(r_end, rot_x(math.pi)) < 1e-9
    p_end, r_end = traj.segment_end_pose(2)
    np.testing.assert_allclose(p_end, [0.0, 0.0, -0.03], atol=1e-15)
    assert rotation_angle(r_end, rot_x(math.pi)) < 1e-9  # one full turn about z
    assert traj.duration > 0.5 + 0.5  # two holds


def test_unknown_scenario_lists_valid_names() -> None:
    """An unknown registry name -> ScenarioError listing the shipped scenarios."""
    with pytest.raises(ScenarioError, match="valid choices: .*assembly"):
        load_scenario("nope")
    with pytest.raises(ScenarioError, match="not found"):
        load_scenario("/nonexistent/x.yaml")


def scenario_text(approach_type: str = "pose", initial: str = "[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, "
                  "0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]", extra: str = "") -> str:
    return f"""\
/**:
  ros__parameters:
    scenario:
      name: tiny
      initial_positions_deg: {initial}
      segments: [approach]
      approach:
        type: {approach_type}
        position: [0.0, 0.0, 0.05]
        rpy_deg: [180.0, 0.0, 0.0]
{extra}"""


def test_scenario_file_by_path_loads(tmp_path: Path) -> None:
    """A valid scenario file given by path; defaults: settle 1 s, default limits, hold 0."""
    sc = load_scenario(str(write(tmp_path, scenario_text(), "tiny.yaml")))
    assert sc.name == "tiny" and sc.settle_time == 1.0 and sc.reference.segments[0].hold == 0.0
    np.testing.assert_array_equal(sc.initial_positions, np.zeros(14))


def test_unknown_segment_type_names_the_key(tmp_path: Path) -> None:
    """type: fly -> ScenarioError naming 'scenario.approach.type' and the valid types."""
    with pytest.raises(ScenarioError, match=r"scenario\.approach\.type.*'fly'.*pose, screw"):
        load_scenario(str(write(tmp_path, scenario_text("fly"), "fly.yaml")))


@pytest.mark.parametrize(
    ("initial", "extra", "fragment"),
    [
        ("[0.0, 1.0]", "", "initial_positions_deg"),
        ("[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, .nan]", "", "initial_positions_deg"),
        (None, "      settle_time: -1.0\n", "settle_time"),
        (None, "      limits:\n        max_linear_velocity: -1.0\n", "max_linear_velocity"),
        (None, "      limits:\n        warp: 1.0\n", "warp"),
    ],
)
def test_bad_scenario_values_name_the_key(tmp_path: Path, initial: str | None, extra: str, fragment: str) -> None:
    """Wrong length / NaN / negative settle / bad or unknown limit: ScenarioError naming the offending key."""
    text = scenario_text(extra=extra) if initial is None else scenario_text(initial=initial, extra=extra)
    with pytest.raises(ScenarioError, match=fragment):
        load_scenario(str(write(tmp_path, text, "bad.yaml")))


def test_malformed_scenario_yaml_is_a_scenario_error(tmp_path: Path) -> None:
    """A YAML error in a scenario file surfaces as ScenarioError with the line."""
    with pytest.raises(ScenarioError, match="line 2"):
        load_scenario(str(write(tmp_path, "/**:\n\tros__parameters: {}\n", "broken.yaml")))


def test_thread_priority_comes_from_a_params_file_and_minus_p_wins(tmp_path: Path) -> None:
    """The scheduling is chosen before rclpy starts: the node's params-file entry counts, -p overrides it."""
    from dualarm_control.ros.priority import priority_from_args

    f = tmp_path / "p.yaml"
    f.write_text("trajectory_node:\n  ros__parameters:\n    thread_priority: 0\n")
    args = ["trajectory_node", "--ros-args", "--params-file", str(f)]
    assert priority_from_args(args, 40, "trajectory_node") == 0
    assert priority_from_args(args, 50, "controller_node") == 50  # another node's entry
    assert priority_from_args([*args, "-p", "thread_priority:=7"], 40, "trajectory_node") == 7
    bad = tmp_path / "bad.yaml"
    bad.write_text("trajectory_node: [")
    assert priority_from_args(["x", "--ros-args", "--params-file", str(bad)], 40, "trajectory_node") == 40


def test_a_lockstep_node_asks_for_normal_scheduling(tmp_path: Path) -> None:
    """A lockstep run keeps no deadline: its nodes run under normal scheduling whatever thread_priority says
    (-p or the node's params-file entry); in real time thread_priority 0 is "disabled" and a positive one is
    requested (granted or refused with the reason, as this machine allows)."""
    from dualarm_control.ros.priority import LOCKSTEP_NOTE, node_scheduling

    f = tmp_path / "p.yaml"
    f.write_text("sim_node:\n  ros__parameters:\n    lockstep: true\n    thread_priority: 60\n")
    for args in (["sim_node", "--ros-args", "-p", "lockstep:=true", "-p", "thread_priority:=60"],
                 ["sim_node", "--ros-args", "--params-file", str(f)],
                 ["sim_node", "--ros-args", "-p", "sim_node:lockstep:=true"]):
        request = node_scheduling(args, 50, "sim_node")
        assert (request.granted, request.note) == (0, LOCKSTEP_NOTE), args
    assert node_scheduling(["sim_node", "--ros-args", "--params-file", str(f), "-p", "lockstep:=false",
                            "-p", "thread_priority:=0"], 50, "sim_node").note == "disabled"
    real_time = node_scheduling(["sim_node", "--ros-args", "-p", "lockstep:=false"], 50, "sim_node")
    assert real_time.note != LOCKSTEP_NOTE and (real_time.granted == 50) == (real_time.note == "")
