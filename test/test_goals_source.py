"""The goals reference source (issue 18): scenario file, stream, one in-process run."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from dualarm_control.errors import ScenarioError
from dualarm_control.kinematics import DualArmModel
from dualarm_control.online_trajectory import REACHED
from dualarm_control.references.base import RELATIVE_TARGET, RunOptions
from dualarm_control.references.goals import GoalsSource
from dualarm_control.scenario import load_scenario


@pytest.fixture(scope="module")
def demo() -> tuple:
    return load_scenario("interactive_demo"), DualArmModel()


def test_interactive_demo_loads_as_a_goals_source(demo: tuple) -> None:
    scenario, _ = demo
    assert isinstance(scenario.reference, GoalsSource)
    assert scenario.reference.kind == "goals"
    assert scenario.reference.streams == (RELATIVE_TARGET,)
    assert scenario.reference.describe() == "4 goals, 1 twists"


def test_stream_starts_at_the_measured_pose_and_ends_at_rest_on_the_last_goal(demo: tuple) -> None:
    scenario, model = demo
    q0 = scenario.initial_positions
    options = RunOptions(scenario.limits, scenario.settle_time)
    stream = scenario.reference.stream(model, q0, options, 0.005)
    p0, r0 = model.relative_pose(q0)
    first = stream.sample(0.0)
    assert np.allclose(first.relative.position, p0) and np.allclose(first.relative.rotation, r0)
    assert first.joints is None
    last = stream.sample(stream.end - scenario.settle_time)
    assert last.relative.done and stream.generator.state == REACHED
    assert np.allclose(last.relative.position, [0.0, 0.0, 0.1], atol=1e-12)
    assert np.linalg.norm(last.relative.linear_velocity) == 0.0
    # the last goal is given at t = 12 s: the end is after it, at rest, plus the settle time
    assert stream.end > 12.0 + scenario.settle_time
    end_p, end_r = scenario.end_pose(q0, model, 0.005)
    assert np.allclose(end_p, last.relative.position) and np.allclose(end_r, last.relative.rotation)


def test_bad_goals_entry_is_a_scenario_error_naming_it(tmp_path: Path) -> None:
    text = Path(load_scenario("interactive_demo").source).read_text()
    bad = text.replace("rpy: [3.14159265, 0.0, 0.4]", "rpy: [3.14159265, 0.0]")
    path = tmp_path / "bad.yaml"
    path.write_text(bad)
    with pytest.raises(ScenarioError, match=r"scenario.goals\[1\].rpy: expected 3 numbers"):
        load_scenario(str(path))
