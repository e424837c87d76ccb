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
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from dualarm_control.controller import CONTROLLER_PARAMETERS, controller_params
from dualarm_control.errors import DualArmError
from dualarm_control.params import read_params_file
from dualarm_control.scenario import load_scenario

FUZZ = settings(max_examples=150, deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
TIME_LIMIT_S = 2.0  # per example: "never a hang"

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
    """Run ``call()``; return 'ok' or the DualArmError's message; any other exception fails the test."""
    start = time.monotonic()
    try:
        call()
        outcome = "ok"
    except DualArmError as exc:
        assert str(exc).strip(), "an error without a message"
        outcome = str(exc)
    assert time.monotonic() - start < TIME_LIMIT_S, "took too long"
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
