"""Random relative tasks (issue 28): reproducible, task i independent of N, every start and goal feasible."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from dualarm_control.app.sweep.spec import SpecError, load_spec, parse_spec
from dualarm_control.app.sweep.tasks import (
    IK_TOLERANCE,
    TaskSampler,
    TaskSampling,
    task_generator,
)
from dualarm_control.kinematics import DualArmModel
from dualarm_control.scenario import load_scenario

SAMPLING = TaskSampling(goal_translation=0.03, goal_rotation=np.radians(8.0))


def sampler(robot: str = "lwr4_cell") -> TaskSampler:
    base = load_scenario("assembly", robot)
    return TaskSampler(DualArmModel(base.robot), SAMPLING, base.limits, 0.2, base.collision_allowed)


def test_generator_is_the_spawned_child_whatever_the_count() -> None:
    """task_generator(s, i) draws what SeedSequence(s).spawn(N)[i] would, for every N > i."""
    for n in (4, 50):
        child = np.random.SeedSequence(7).spawn(n)[3]
        assert np.array_equal(np.random.Generator(np.random.PCG64(child)).random(5), task_generator(7, 3).random(5))


def test_same_seed_same_tasks_in_any_order() -> None:
    """Two samplers (as two machines would build them) give identical tasks, in any order of the indices."""
    a, b = sampler(), sampler()
    forward = [a.sample(3, i) for i in range(4)]
    backward = [b.sample(3, i) for i in reversed(range(4))][::-1]
    for x, y in zip(forward, backward, strict=True):
        assert np.array_equal(x.start, y.start) and np.array_equal(x.goal_position, y.goal_position)
        assert np.array_equal(x.goal_rotation, y.goal_rotation) and x.duration == y.duration
    assert not np.array_equal(forward[0].start, forward[1].start)
    assert not np.array_equal(forward[0].start, sampler().sample(4, 0).start)  # another seed, another task


def test_every_task_is_feasible() -> None:
    """Start in the shrunk limits, manipulable, collision-free, tools in reach; the goal reached by the IK
    solution (collision-free too); duration within the bound."""
    s = sampler()
    for i in range(6):
        task = s.sample(0, i)
        for q in (task.start, task.goal_configuration):
            assert np.all(q >= s.lower) and np.all(q <= s.upper)
            assert s.collision.closest(q).distance >= SAMPLING.clearance
        assert s.manipulability(task.start) >= SAMPLING.manipulability_floor
        assert np.linalg.norm(s.model.relative_pose(task.start)[0]) <= SAMPLING.max_tool_distance
        p, r = s.model.relative_pose(task.goal_configuration)
        error = pin.log6(pin.SE3(task.goal_rotation, task.goal_position).actInv(pin.SE3(r, p))).vector
        assert np.linalg.norm(error) <= IK_TOLERANCE
        assert 0.2 < task.duration <= SAMPLING.max_duration


def test_spec_errors_name_the_key(tmp_path: Path) -> None:
    with pytest.raises(SpecError, match=r"sweep\.bogus: unknown key"):
        parse_spec({"bogus": 1})
    with pytest.raises(SpecError, match=r"sweep\.sampling\.clerance: unknown key"):
        parse_spec({"sampling": {"clerance": 0.1}})
    with pytest.raises(SpecError, match=r"sweep\.sampling\.clearance: got -1"):
        parse_spec({"sampling": {"clearance": -1}})
    with pytest.raises(SpecError, match=r"sweep\.sampling\.clearance: 0\.02 m is below the collision limit's safety "
                       r"distance 0\.032 m .* 'standard_qp' on 'lwr4_cell'"):
        parse_spec({"robots": ["lwr4_cell"], "solvers": ["standard_qp"], "sampling": {"clearance": 0.02}})
    assert parse_spec({"robots": ["lwr4_cell"], "solvers": ["standard_qp"], "sampling": {"clearance": 0.02},
                       "variants": {"off": {"collision.enabled": False}}}).sampling.clearance == 0.02
    with pytest.raises(SpecError, match=r"sweep\.tasks: got 0"):
        parse_spec({"tasks": 0})
    with pytest.raises(SpecError, match=r"sweep\.variants\.fast .*nonexistent_qp"):
        parse_spec({"solvers": ["nonexistent_qp"], "variants": {"fast": {}}})
    with pytest.raises(SpecError, match=r"sweep\.variants\.bad"):
        parse_spec({"variants": {"bad": {"gain": -3.0}}})
    bad = tmp_path / "bad.yaml"
    bad.write_text("other: {}\n")
    with pytest.raises(SpecError, match="top-level 'sweep:'"):
        load_spec(bad)


def test_shipped_specs_load() -> None:
    config = Path(__file__).resolve().parents[1] / "config" / "sweeps"
    assert load_spec(config / "smoke.yaml").tasks <= 5
    big = load_spec(config / "table1_distribution.yaml")
    assert big.tasks == 1000 and "lwr4_cell" in big.robots and len(big.solvers) == 3
    assert big.with_robots("ur5_pair,lwr4_cell").robots == ("ur5_pair", "lwr4_cell")
    with pytest.raises(SpecError, match="--robots 'nao'"):
        big.with_robots("nao")
    assert load_spec(config / "table1_near_limits.yaml").sampling.joint_margin < big.sampling.joint_margin
