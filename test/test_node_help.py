"""``dualarm run NODE --help``: the node's usage with its parameters, exit 0, no node (issue 38, item 6).

``-h``/``--help`` counts anywhere on a node's command line, before ``--ros-args`` or among the ROS
arguments (``ros2 run PKG NODE --ros-args --help``; ``dualarm run NODE --help`` passes ``--ros-args
--help`` to the node), except as the value of a ROS argument that takes one (``-p``, ``--params-file``).
Each node of ``dualarm run`` (``app.run.launcher.NODES``) and ``cell_container`` is checked in this
process with rclpy's initialisation replaced by a failure (a node that would start fails the test),
and once through the real ``dualarm run`` command line in a subprocess.
"""

from __future__ import annotations

import importlib
import subprocess
import sys

import pytest

from dualarm_control.app.run.launcher import CONTAINER, CONTAINER_MODULE, NODES
from dualarm_control.ros import node as shell
from dualarm_control.ros.node import wants_help

HELP_FORMS = (
    ["--help"],
    ["-h"],
    ["--ros-args", "--help"],
    ["--ros-args", "-h"],
    ["--ros-args", "-p", "rate:=100.0", "--help"],
    ["--ros-args", "--params-file", "config/solvers/sparse_qp.yaml", "-r", "__ns:=/cell", "-h"],
)
"""Command lines (after the node's name) that ask for the usage."""

PARAMETERS = {
    "controller_node": ("dualarm_control.nodes.controller_node", "ALL_PARAMETERS"),
    "trajectory_node": ("dualarm_control.nodes.trajectory_node", "PARAMETERS"),
    "sim_node": ("dualarm_sim.sim_node", "PARAMETERS"),
}
"""Where each node of ``dualarm run`` keeps its declared parameters (every one must be in its usage)."""


def test_wants_help_anywhere_but_as_a_value() -> None:
    for form in HELP_FORMS:
        assert wants_help(["node", *form]), form
    for argv in (["node"], [], ["node", "--ros-args", "-p", "rate:=100.0"],
                 ["node", "--ros-args", "--params-file", "--help"], ["node", "--ros-args", "-r", "-h"]):
        assert not wants_help(argv), argv
    assert wants_help(["node", "--ros-args", "--params-file", "--help", "--help"])


def test_every_run_node_has_its_parameters_listed() -> None:
    assert set(PARAMETERS) == set(NODES), "a node of 'dualarm run' without a help test"


@pytest.mark.parametrize("form", HELP_FORMS, ids=" ".join)
@pytest.mark.parametrize("node", [*NODES, CONTAINER])
def test_node_help_prints_usage_and_starts_no_node(node: str, form: list[str], monkeypatch: pytest.MonkeyPatch,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    def no_node(argv: object) -> None:
        raise AssertionError(f"{node} {' '.join(form)} initialised rclpy (a node would start)")

    monkeypatch.setattr(shell, "init_rclpy", no_node)
    module = importlib.import_module(NODES.get(node, CONTAINER_MODULE))
    assert module.main([node, *form]) == 0
    out = capsys.readouterr().out
    assert out.lstrip().startswith(f"usage: {node}") or f"\nusage: {node}" in out, out
    if node in PARAMETERS:
        path, attribute = PARAMETERS[node]
        specs = getattr(importlib.import_module(path), attribute)
        missing = [spec.name for spec in specs if f"  {spec.name} (" not in out]
        assert not missing, f"{node} --help does not list {missing}"
    else:
        assert "parameters: each node's own" in out


@pytest.mark.parametrize("node", list(NODES))
def test_dualarm_run_ros_args_help(node: str) -> None:
    """The real command line: ``dualarm run NODE --ros-args --help`` execs the node, which prints its usage."""
    done = subprocess.run([sys.executable, "-m", "dualarm_control.app.cli", "run", node, "--ros-args", "--help"],
                          check=False, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert f"usage: {node} [--ros-args" in done.stdout
    assert "\nparameters:\n" in done.stdout
    assert "use_sim_time (bool" in done.stdout
