"""The cell's controller defaults (a robot's or a scenario's joint acceleration bound) reach every path that
builds a controller: ``dualarm experiment``, a sweep's grid cell and controller_node (docs/obstacles.md,
docs/robots.md). busy_cell sets 10 rad/s^2: without it, its two tools pressed on one plate from both sides
make the commands alternate from cycle to cycle (930-1285 rad/s^2 measured)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest
import rclpy
from rclpy.node import Node

from dualarm_control.app.run.command import cell_values
from dualarm_control.app.sweep.spec import SweepSpec
from dualarm_control.errors import ScenarioError
from dualarm_control.nodes.controller_setup import ALL_PARAMETERS, with_cell_defaults
from dualarm_control.ros.node import declare
from dualarm_control.scenario import load_scenario

SCENARIOS = Path(__file__).parents[1] / "config" / "scenarios"


def test_busy_cell_sets_its_acceleration_bound_and_the_assembly_none() -> None:
    assert load_scenario("busy_cell").controller_defaults() == {"acceleration_limit": [10.0]}
    assert load_scenario("assembly").controller_defaults() == {}  # Table I's runs unchanged


def test_the_scenarios_bound_takes_the_robots_place() -> None:
    assembly, busy = load_scenario("assembly"), load_scenario("busy_cell")
    robot = replace(assembly.robot, acceleration_limit=(5.0,))
    assert replace(assembly, robot=robot).controller_defaults() == {"acceleration_limit": [5.0]}
    assert replace(busy, robot=robot).controller_defaults() == {"acceleration_limit": [10.0]}


@pytest.mark.parametrize("value", ["[0.0]", "[-1.0]", "[.nan]", "[true]", "[1.0, 2.0]", "'fast'"])
def test_a_bad_scenario_bound_is_refused_naming_the_key(tmp_path: Path, value: str) -> None:
    text = (SCENARIOS / "busy_cell.yaml").read_text()
    path = tmp_path / "bad.yaml"
    path.write_text(text.replace("acceleration_limit: [10.0]", f"acceleration_limit: {value}", 1))
    with pytest.raises(ScenarioError, match=r"scenario parameter 'scenario\.acceleration_limit': got .*one for all "
                                            r"joints or 14"):
        load_scenario(str(path))


def test_dualarm_experiment_takes_the_cells_bound_and_a_params_file_overrides_it(tmp_path: Path) -> None:
    busy = load_scenario("busy_cell")
    assert cell_values(busy, [])["acceleration_limit"] == [10.0]
    off = tmp_path / "off.yaml"
    off.write_text("controller_node:\n  ros__parameters:\n    acceleration_limit: [0.0]\n")
    assert cell_values(busy, [str(off)])["acceleration_limit"] == [0.0]
    assert "acceleration_limit" not in cell_values(load_scenario("assembly"), [])


def test_a_sweeps_grid_cell_takes_the_cells_bound() -> None:
    spec = SweepSpec(name="t", scenario="busy_cell")
    assert spec.params("lwr4_cell", "sparse_qp", spec.variants[0][0]).acceleration_limit == (10.0,)
    assert replace(spec, scenario="assembly").params("lwr4_cell", "sparse_qp",
                                                     spec.variants[0][0]).acceleration_limit == ()


@pytest.fixture()
def context():  # type: ignore[no-untyped-def]
    context = rclpy.Context()
    rclpy.init(context=context)
    yield context
    context.try_shutdown()


@pytest.mark.parametrize(("args", "expected"), [([], [10.0]), (["-p", "acceleration_limit:=[0.0]"], [0.0]),
                                                (["-p", "acceleration_limit:=[4.0]"], [4.0])])
def test_controller_node_takes_the_cells_bound_unless_given_one(context: object, args: list[str],
                                                                  expected: list[float]) -> None:
    """On a real rclpy node: the parameter holds the value in use (``dualarm param get`` shows it)."""
    node = Node("controller_node", context=context, cli_args=["--ros-args", *args] if args else None)
    try:
        values = declare(node, [spec for spec in ALL_PARAMETERS if spec.name == "acceleration_limit"])
        values = with_cell_defaults(node, load_scenario("busy_cell"), values)
        assert list(values["acceleration_limit"]) == expected
        assert list(node.get_parameter("acceleration_limit").value) == expected
        assert list(with_cell_defaults(node, load_scenario("assembly"), values)["acceleration_limit"]) == expected
    finally:
        node.destroy_node()


def test_a_controller_node_process_runs_busy_cell_with_its_bound() -> None:
    """``dualarm run controller_node -p scenario:=busy_cell``: its start line names the scenario's bound (before
    this, the node ran busy_cell without one while ``dualarm experiment`` could be given it)."""
    from waiting import NodeProcess, tail

    controller = NodeProcess("controller_node", "-p", "scenario:=busy_cell")
    try:
        start = controller.lines[controller.wait_for("on scenario 'busy_cell'")]
    finally:
        code = controller.stop()
    assert "joint acceleration bound 10 rad/s^2 on every joint" in start, start
    assert code == 0, tail(controller.lines)
