"""Tests of the global manipulability planner (paper 003): index, constraint, NLP blocks, pool, execution."""

from __future__ import annotations

import dataclasses
import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from dualarm_control.app.plan.optimise import PlanResult, distinct_best, optimise, plan
from dualarm_control.app.plan.record import plan_record
from dualarm_control.errors import ScenarioError
from dualarm_control.kinematics import DualArmModel
from dualarm_control.planning.baseline import BaselineParams, run_baseline
from dualarm_control.planning.config import PlanConfig, load_plan_config
from dualarm_control.planning.global_opt import (
    POSITION_TOLERANCE,
    ROTATION_TOLERANCE,
    BlockProblem,
    closure_errors,
    inner_block,
    interpolated_start,
    key_block,
    project_to_pose,
    random_feasible_chain,
    solve_block,
)
from dualarm_control.planning.index import (
    chain_terms,
    closure_jacobian,
    closure_residual,
    index_and_gradient,
    performance_index,
)
from dualarm_control.planning.joint_trajectory import JointPathTrajectory, densify
from dualarm_control.planning.path import CornerPath, SampledPath
from dualarm_control.planning.plan_file import PLAN_FORMAT, load_plan
from dualarm_control.scenario import load_scenario

# no ROS node, no wall-clock verdict: make test runs it at idle CPU priority beside the parallel tests (docs/testing.md)
pytestmark = pytest.mark.background

FD_STEP = 1e-6  # central differences: truncation ~1e-12 * |third derivative|, round-off ~1e-10


@pytest.fixture(scope="module")
def model() -> DualArmModel:
    return DualArmModel()


@pytest.fixture(scope="module")
def corner() -> CornerPath:
    return CornerPath()


def random_q(model: DualArmModel, rng: np.random.Generator) -> np.ndarray:
    mid, half = (model.q_max + model.q_min) / 2, (model.q_max - model.q_min) / 2
    return mid + 0.9 * half * rng.uniform(-1.0, 1.0, model.nq)


def unit(rng: np.random.Generator) -> np.ndarray:
    v = rng.standard_normal(3)
    return v / np.linalg.norm(v)


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    q, r = np.linalg.qr(rng.standard_normal((3, 3)))
    q = q @ np.diag(np.sign(np.diag(r)))
    return q if np.linalg.det(q) > 0 else -q


# ---- eq (14): index and its gradient ---------------------------------------------------
def test_chain_terms_jacobian_is_the_models_relative_jacobian(model: DualArmModel) -> None:
    rng = np.random.default_rng(3)
    for _ in range(5):
        q = random_q(model, rng)
        terms = chain_terms(model, q)
        state = model.relative_state(q)
        np.testing.assert_allclose(terms.relative_jacobian, state.jacobian, atol=1e-12)
        np.testing.assert_allclose(terms.position, state.position, atol=1e-12)
        np.testing.assert_allclose(terms.rotation, state.rotation, atol=1e-12)


def test_index_is_u_J_Jt_u_with_u_tangent_and_zero(model: DualArmModel) -> None:
    """eq (14) written out with the model's J_r and u = [t; 0]."""
    rng = np.random.default_rng(4)
    for _ in range(5):
        q, t = random_q(model, rng), unit(rng)
        u = np.concatenate((t, np.zeros(3)))
        jac = model.relative_state(q).jacobian
        assert performance_index(chain_terms(model, q), t) == pytest.approx(u @ jac @ jac.T @ u, rel=1e-12)


def test_index_gradient_matches_central_finite_differences(model: DualArmModel) -> None:
    rng = np.random.default_rng(5)
    for _ in range(8):
        q, t = random_q(model, rng), unit(rng)
        value, grad = index_and_gradient(chain_terms(model, q), t)
        assert value == pytest.approx(performance_index(chain_terms(model, q), t), rel=1e-14)
        fd = np.array([
            (performance_index(chain_terms(model, q + FD_STEP * e), t)
             - performance_index(chain_terms(model, q - FD_STEP * e), t)) / (2 * FD_STEP)
            for e in np.eye(model.nq)
        ])
        np.testing.assert_allclose(grad, fd, atol=1e-7 * max(1.0, float(np.max(np.abs(fd)))))
        assert np.max(np.abs(grad)) > 1e-3  # a real, non-trivial gradient was compared


# ---- eq (17): closure constraint --------------------------------------------------------
def test_closure_jacobian_matches_central_finite_differences(model: DualArmModel) -> None:
    rng = np.random.default_rng(6)
    for k in range(8):
        q = random_q(model, rng)
        if k % 2 == 0:  # target far from the current pose
            p_d, r_d = rng.uniform(-0.5, 0.5, 3), random_rotation(rng)
        else:  # near the solution, where the optimiser works
            p_d, r_d = model.relative_pose(q)
            p_d = p_d + 1e-3 * rng.standard_normal(3)
        jac = closure_jacobian(chain_terms(model, q), r_d)
        fd = np.column_stack([
            (closure_residual(chain_terms(model, q + FD_STEP * e), p_d, r_d)
             - closure_residual(chain_terms(model, q - FD_STEP * e), p_d, r_d)) / (2 * FD_STEP)
            for e in np.eye(model.nq)
        ])
        np.testing.assert_allclose(jac, fd, atol=1e-7)


def test_closure_residual_is_zero_on_the_pose_and_measures_the_error(model: DualArmModel) -> None:
    rng = np.random.default_rng(7)
    q = random_q(model, rng)
    p, r = model.relative_pose(q)
    np.testing.assert_allclose(closure_residual(chain_terms(model, q), p, r), 0.0, atol=1e-12)
    h = closure_residual(chain_terms(model, q), p + np.array([0.01, 0.0, 0.0]), r)
    np.testing.assert_allclose(h[:3], [-0.01, 0.0, 0.0], atol=1e-12)


# ---- the corner path --------------------------------------------------------------------
def test_corner_path_samples_follow_section_iv_b(corner: CornerPath) -> None:
    path = corner.sample()
    assert len(path) == 31
    np.testing.assert_allclose(path.positions[0], [0.15, 0.0, 0.3])
    np.testing.assert_allclose(path.positions[12], [0.15, 0.14, 0.3])
    np.testing.assert_allclose(path.positions[18], [0.14, 0.15, 0.3])
    np.testing.assert_allclose(path.positions[30], [0.0, 0.15, 0.3], atol=1e-15)
    np.testing.assert_allclose(np.linalg.norm(path.tangents, axis=1), 1.0)
    fillet = path.positions[13:18, :2] - 0.14
    np.testing.assert_allclose(np.linalg.norm(fillet, axis=1), 0.01)
    # tangent of the fillet is perpendicular to the radius and turns from +y to -x
    np.testing.assert_allclose(np.sum(fillet * path.tangents[13:18, :2], axis=1), 0.0, atol=1e-15)
    np.testing.assert_allclose(path.rotation, np.diag([1.0, -1.0, -1.0]), atol=1e-15)
    assert corner.length == pytest.approx(0.28 + 0.005 * math.pi)


def test_corner_distance_is_zero_on_the_path_and_the_offset_elsewhere(corner: CornerPath) -> None:
    for p in corner.sample().positions:
        assert corner.distance(p) < 1e-12
    assert corner.distance(np.array([0.15, 0.07, 0.31])) == pytest.approx(0.01)
    assert corner.distance(np.array([0.16, 0.07, 0.3])) == pytest.approx(0.01)
    # inside the fillet's circle, 5 mm from it
    c = 0.14 + 0.005 * math.cos(math.pi / 4)
    assert corner.distance(np.array([c, c, 0.3])) == pytest.approx(0.005)


# ---- NLP blocks (eq 19-20) --------------------------------------------------------------
def test_projection_reaches_the_pose_inside_the_limits(model: DualArmModel, corner: CornerPath) -> None:
    path = corner.sample()
    rng = np.random.default_rng(8)
    for i in (0, 15, 30):
        q = project_to_pose(model, random_q(model, rng), path.positions[i], path.rotation)
        assert q is not None
        e_p, e_r = closure_errors(model, q, path.positions[i], path.rotation)
        assert e_p < POSITION_TOLERANCE and e_r < ROTATION_TOLERANCE
        assert np.all(q >= model.q_min) and np.all(q <= model.q_max)


def test_block_gradient_matches_finite_differences(model: DualArmModel, corner: CornerPath) -> None:
    """Objective of eq (20) (index + smoothness with both fixed ends) vs central differences."""
    path = corner.sample()
    rng = np.random.default_rng(9)
    block = inner_block(0, 3, random_q(model, rng), random_q(model, rng), weight=3.0)
    problem = BlockProblem(model, path, block)
    x = np.concatenate([random_q(model, rng) for _ in block.indices])
    value, grad = problem.objective(x)
    assert value == pytest.approx(problem.value(x), rel=1e-12)
    fd = np.array([(problem.value(x + FD_STEP * e) - problem.value(x - FD_STEP * e)) / (2 * FD_STEP)
                   for e in np.eye(x.size)])
    np.testing.assert_allclose(grad, fd, rtol=1e-6, atol=1e-6 * float(np.max(np.abs(fd))))


@pytest.mark.parametrize("max_iterations", [1, 3, 200])
def test_optimiser_never_returns_worse_than_its_start(model: DualArmModel, corner: CornerPath,
                                                      max_iterations: int) -> None:
    """Key-point block (eq 19) from random feasible starts, also when SLSQP is cut short."""
    path = corner.sample()
    keys = (0, 6, 12)
    for seed in range(3):
        start = random_feasible_chain(model, path, keys, np.random.default_rng(seed))
        result = solve_block(model, path, key_block(keys), start, max_iterations=max_iterations)
        assert result.value <= result.start_value
        assert result.value == pytest.approx(BlockProblem(model, path, key_block(keys)).value(
            result.configurations.ravel()), rel=1e-12)
        for q, i in zip(result.configurations, keys, strict=True):
            e_p, e_r = closure_errors(model, q, path.positions[i], path.rotation)
            assert e_p < POSITION_TOLERANCE and e_r < ROTATION_TOLERANCE
            assert np.all(q >= model.q_min) and np.all(q <= model.q_max)
        if max_iterations == 200:
            assert result.status == "optimised" and result.value < 0.9 * result.start_value


def test_inner_block_improves_on_the_interpolated_start(model: DualArmModel, corner: CornerPath) -> None:
    path = corner.sample()
    keys = (0, 6)
    ends = random_feasible_chain(model, path, keys, np.random.default_rng(11))
    block = inner_block(0, 6, ends[0], ends[1], weight=3.0)
    start = interpolated_start(model, path, block, None, 0.0)
    result = solve_block(model, path, block, start)
    assert result.configurations.shape == (5, model.nq)
    assert result.value <= result.start_value


# ---- multi-start driver: determinism ----------------------------------------------------
def small_config(**changes: object) -> PlanConfig:
    return dataclasses.replace(PlanConfig(starts=3, inner_starts=2), **changes)  # type: ignore[arg-type]


def test_plan_is_deterministic_and_independent_of_the_worker_count() -> None:
    one, details_one = optimise(small_config(), workers=1)
    two, details_two = optimise(small_config(), workers=2)
    np.testing.assert_array_equal(one, two)
    np.testing.assert_array_equal(details_one["key_values"], details_two["key_values"])
    assert np.all(details_one["key_values"] <= details_one["key_start_values"])  # no start got worse
    other, _ = optimise(small_config(seed=1), workers=1)
    assert not np.array_equal(one, other)


def test_distinct_best_skips_repeated_optima() -> None:
    from dualarm_control.planning.global_opt import BlockResult

    def result(value: float, q: float) -> BlockResult:
        qs = np.full((2, 14), q)
        return BlockResult(qs, value, qs, value + 1.0, 10, "optimised")

    results = [result(2.0, 0.0), result(1.0, 0.5), result(1.0, 0.5 + 1e-5), result(1.5, 0.2), result(3.0, 0.9)]
    assert distinct_best(results, 3) == [1, 3, 0]  # 2 repeats 1's optimum; ties go to the lower index
    assert distinct_best(results, 10) == [1, 3, 0, 4]


# ---- baseline (eq 12-13) ----------------------------------------------------------------
def test_baseline_tracks_the_path_and_its_null_space_term_lowers_the_index(model: DualArmModel,
                                                                           corner: CornerPath) -> None:
    path = corner.sample()
    q0 = random_feasible_chain(model, path, [0], np.random.default_rng(12))[0]
    with_gradient = run_baseline(model, path, q0, BaselineParams(k0=1.0))
    without = run_baseline(model, path, q0, BaselineParams(k0=0.0))
    assert with_gradient.configurations.shape == (31, model.nq)
    assert np.max(with_gradient.position_errors) < 1e-4  # m, closed-loop tracking of the path
    assert np.max(with_gradient.rotation_errors) < 1e-3  # rad
    assert np.mean(with_gradient.indices) < 0.9 * np.mean(without.indices)


# ---- joint-space trajectory -------------------------------------------------------------
def test_joint_trajectory_passes_through_the_knots_within_limits(model: DualArmModel, corner: CornerPath) -> None:
    path = corner.sample()
    keys = list(range(0, 31, 3))
    configs = random_feasible_chain(model, path, keys, np.random.default_rng(13))
    coarse = SampledPath(path.positions[keys], path.tangents[keys], path.rotation)
    knots, positions = densify(model, coarse, configs, 3)
    np.testing.assert_array_equal(knots[::3], configs)
    for q, p in zip(knots, positions, strict=True):
        e_p, e_r = closure_errors(model, q, p, path.rotation)
        assert e_p < POSITION_TOLERANCE and e_r < ROTATION_TOLERANCE
    traj = JointPathTrajectory(knots, positions, model.qd_max, velocity_scale=0.5)
    for t, q in zip(traj.sample_times, knots, strict=True):
        np.testing.assert_allclose(traj.sample(t).positions, q, atol=1e-9)
    start, end = traj.sample(0.0), traj.sample(traj.duration)
    assert np.all(start.velocities == 0.0) and np.all(end.velocities == 0.0) and end.done
    times = np.linspace(0.0, traj.duration, 400)
    vel = np.array([traj.sample(t).velocities for t in times])
    assert np.all(np.abs(vel) <= 0.5 * model.qd_max + 1e-9)
    dt = 1e-5
    for t in times[1:-1:40]:
        fd = (traj.sample(t + dt).positions - traj.sample(t - dt).positions) / (2 * dt)
        np.testing.assert_allclose(traj.sample(t).velocities, fd, atol=1e-6)


# ---- configuration and scenario file ----------------------------------------------------
def test_corner_scenario_has_the_paper_settings_and_a_start_on_the_path(model: DualArmModel) -> None:
    cfg = load_plan_config("corner_path")
    assert cfg.key_points == (1, 7, 13, 19, 25, 31)
    assert (cfg.lambda_key, cfg.lambda_inner, cfg.starts, cfg.baseline.k0) == (1.5, 3.0, 100, 1.0)
    assert cfg.candidates == 4 and cfg.inner_starts == 10
    assert cfg.corner == CornerPath()
    scenario = load_scenario("corner_path")
    path = cfg.corner.sample()
    e_p, e_r = closure_errors(model, scenario.initial_positions, path.positions[0], path.rotation)
    assert e_p < 1e-6 and e_r < 1e-6  # degrees with 6 decimals in the file
    ends = [s.position for s in scenario.reference.segments]
    on_path = [path.positions[i] for i in (0, 12, 13, 14, 15, 16, 17, 18, 30)]
    np.testing.assert_allclose(np.array(ends), np.array(on_path), atol=1e-6)


def test_scenario_without_a_corner_is_rejected() -> None:
    with pytest.raises(ScenarioError, match="corner"):
        load_plan_config("assembly")
    with pytest.raises(ScenarioError, match="key_points"):
        PlanConfig(key_points=(1, 7, 30))


# ---- end to end: plan.json and the executed path ----------------------------------------
@pytest.fixture(scope="module")
def small_plan() -> PlanResult:
    return plan(small_config(), workers=1)


def test_plan_record_is_self_describing(small_plan: PlanResult, model: DualArmModel, tmp_path: Path) -> None:
    from dualarm_control.app.record.report import write_json

    doc = plan_record(small_plan, model, None)
    path = write_json(tmp_path / "plan.json", doc, indent=1)
    back = load_plan(path)
    assert back["format"] == PLAN_FORMAT and back["joint_names"] == model.joint_names
    for key in ("average_index", "baseline_average_index", "max_closure_error_m", "max_closure_error_rad",
                "joint_limit_violations", "runtime_s", "starts", "configurations", "points", "path"):
        assert key in back
    assert len(back["configurations"]) == 31 and len(back["points"]) == 31
    assert back["max_closure_error_m"] <= 1e-5 and back["max_closure_error_rad"] <= 1e-4
    assert back["joint_limit_violations"] == 0
    assert back["average_index"] == pytest.approx(np.mean([p["index_value"] for p in back["points"]]))
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"format": "other"}))
    with pytest.raises(ValueError, match="format"):
        load_plan(bad)


COLLISION_FREE_SEED = 5
"""small_config's seed whose plan keeps every link pair 6.7 cm apart (seeds 0-4 pass a link through another:
paper 003's planner does not avoid collisions; seed 0: right_peg (the peg, before issue 40 right_flange) 6.8 cm into left_link_2)."""


def test_executed_plan_stays_on_the_path(model: DualArmModel) -> None:
    """A collision-free plan, executed under every limit (the collision limit included, issue 39) with the
    simulator's contacts on, follows the path within 1 mm / 5 mrad."""
    from dualarm_control.app.plan.execute import execute_plan

    config = small_config(seed=COLLISION_FREE_SEED)
    free = plan(config, workers=1)
    result = execute_plan(config, free.configurations, model)
    assert result.closest_distance_m > 0.05, result.closest_pair
    assert result.duration > 1.0
    assert result.max_error_m < 1e-3  # m: 1 mm along a 30 cm corner
    assert result.max_error_rad < 5e-3
    assert result.reference_max_error_m < 5e-4  # the densified spline itself


def test_a_plan_through_the_other_arm_stops_at_the_safety_distance(small_plan: PlanResult, model: DualArmModel) -> None:
    """Issue 39: small_config's seed-0 plan passes right_peg through left_link_2 (the plan record says so);
    executed, the tracking runs under the collision limit in a simulator with contacts, so the links stay
    at the safety distance (coal, and pybullet's closest points on the URDF's shapes, independently), and
    the path is left rather than the arm pierced. Before, the plan ran inside the eq (23) box alone, with
    the simulator's contacts off."""
    from dualarm_control.app.plan.execute import execute_plan
    from dualarm_control.app.plan.record import plan_record
    from dualarm_control.app.run.experiment import run_scenario
    from dualarm_control.collision import CollisionModel
    from dualarm_control.controller import ControllerParams
    from dualarm_control.drive_monitor import closest_pair
    from dualarm_control.references.plan import PlanSource
    from dualarm_control.scenario import Scenario
    from dualarm_control.trajectory import MotionLimits
    from dualarm_sim.cell_config import robot_collision_pairs
    from dualarm_sim.contacts import min_distances

    doc = plan_record(small_plan, model, None)
    assert doc["closest_pair_m"] < -0.05 and doc["closest_pair"] == "left_link_2 – right_peg", doc["closest_pair"]
    result = execute_plan(small_config(), small_plan.configurations, model)
    assert result.max_error_m > 0.01  # held off the path by the limit
    # and said: the plan's verdict names the pair that held the arms (issue 39)
    # (measured: "plan 1 'corner_path' (t = 15.0762 s): stalled: collision constraint: left_link_1 – right_link_6
    # at 0.032 m; remaining error 80.48 mm, 0.1160 rad at the end of the run; ...")
    assert result.stalled, result.outcome
    assert re.search(r"stalled: collision constraint: left_\w+ – right_\w+ at 0\.03\d m; remaining error", result.outcome), \
        result.outcome
    config = small_config()
    source = PlanSource(model, config, small_plan.configurations)
    scenario = Scenario(name=config.name, description="plan", initial_positions=small_plan.configurations[0],
                        reference=source, limits=MotionLimits(), settle_time=config.execution_settle,
                        source=Path(config.name), robot=config.robot)
    record = run_scenario(scenario, ControllerParams(period=0.005), model)
    # the plan starts with right_peg 5.8 cm inside left_link_1: the limit separates them within 0.5 s
    # (the damper's bound asks the pair to move apart), then holds the safety distance for the rest of the run
    after = record.time >= 0.5
    collision = CollisionModel.shared(model, model.description.collision_allowed)
    closest = closest_pair(collision, record.positions[after])
    assert closest.distance >= 0.03 - 1e-3, (closest.text, closest.distance)
    found = min_distances(model.description, record.positions[after][::10], robot_collision_pairs(model.description))
    assert found.minimum >= 0.03 - 2e-3, found.pair
    assert closest_pair(collision, record.positions[:1]).distance < -0.05  # the plan's own start


def test_cli_plan_writes_plan_json_and_figures(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from dualarm_control.app.cli import main

    out = tmp_path / "plan"
    code = main(["plan", "corner_path", "--starts", "2", "--seed", "4", "--workers", "1", "--no-execute",
                 "--output", str(out)])
    assert code == 0
    doc = load_plan(out / "plan.json")
    assert doc["starts"] == 2 and doc["seed"] == 4
    # seed 4's plan passes right_link_5 10.6 cm into left_link_1 (issue 39): said, and warned about
    printed = capsys.readouterr()
    assert doc["closest_pair"] == "left_link_1 – right_link_5" and doc["closest_pair_m"] < -0.1, doc["closest_pair"]
    assert f"closest link pair        left_link_1 – right_link_5 at {doc['closest_pair_m'] * 1e3:.1f} mm" in printed.out
    assert "warning: the plan brings left_link_1 – right_link_5 closer than the safety distance 30 mm" in printed.err
    assert (out / "index_along_path.png").stat().st_size > 0
    assert (out / "initial_configuration.png").stat().st_size > 0
    assert main(["plan", "assembly", "--output", str(out)]) == 2  # no corner path: usage error


INDEX_RATIO_TARGET = 0.77
"""The documented margin (docs/planner.md): average index of the plan / baseline's <= 0.77, the
paper's 1.17 / 1.52."""
REDUCED_RATIO_BOUND = 0.54
"""The reduced multi-start plan's ratio (deterministic, seed 0): measured 0.494 (index 0.2008 vs baseline 0.4061,
2026-12, the same as docs/planner.md); bound about 10 % above it."""


def test_reduced_multistart_plan_beats_the_baseline_by_the_documented_margin() -> None:
    """The default scenario settings with 10 key-point starts instead of 100 and 2 inner starts
    instead of 10 (the inner NLPs are unimodal: 10 inner starts give the same plan here), seed 0,
    one worker: ratio <= 0.54 (REDUCED_RATIO_BOUND, about 10 % above the measured 0.494; the documented margin of
    the full plan is 0.77) against the baseline from the plan's q_1, closure and joint limits as
    for the full plan. Deterministic (bit-identical for a seed); measured ratio 0.494 (index 0.2008
    vs 0.4061), 14-17 s on the loaded 2-core machine."""
    config = dataclasses.replace(load_plan_config("corner_path"), starts=10, inner_starts=2, seed=0)
    result = plan(config, workers=1)
    ratio = result.average_index / result.baseline_average_index
    print(f"index {result.average_index:.4f} vs baseline {result.baseline_average_index:.4f}: ratio {ratio:.3f}")
    assert config.candidates == 4 and config.lambda_key == 1.5 and config.lambda_inner == 3.0  # the defaults
    assert ratio <= REDUCED_RATIO_BOUND, f"ratio {ratio:.3f} (index {result.average_index:.4f} vs {result.baseline_average_index:.4f})"
    assert np.max(result.closure_position_errors) <= 1e-5
    assert np.max(result.closure_rotation_errors) <= 1e-4
    assert result.joint_limit_violations == 0


@pytest.mark.slow
def test_full_plan_meets_the_issue_targets() -> None:
    """100 starts on every core: index ratio <= 0.77 (paper 1.17 / 1.52), closure, limits."""
    result = plan(load_plan_config("corner_path"))
    assert result.average_index / result.baseline_average_index <= INDEX_RATIO_TARGET
    assert np.max(result.closure_position_errors) <= 1e-5
    assert np.max(result.closure_rotation_errors) <= 1e-4
    assert result.joint_limit_violations == 0


def test_a_plan_runs_in_the_cell_of_its_scenario_file(small_plan: PlanResult, model: DualArmModel, tmp_path: Path,
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    """A plan made from a scenario file runs under that cell's settings: its joint acceleration bound (a
    controller default, as ``dualarm experiment`` and controller_node take it) and its obstacles. Before, the
    execution built its controller from the bare defaults and dropped both. A config with no file (the
    tests' small one) keeps the defaults: the documented plan figures are unchanged."""
    from dualarm_control.app.plan import execute
    from dualarm_control.controller import ControllerParams
    from dualarm_control.references.plan import PlanSource

    text = Path("config/scenarios/corner_path.yaml").read_text()
    assert "      settle_time: 0.5\n" in text
    cell = tmp_path / "corner_in_a_cell.yaml"
    cell.write_text(text.replace("      settle_time: 0.5\n", """      settle_time: 0.5
      acceleration_limit: [2.0]
      obstacles: [post]
      post: {type: box, size: [0.05, 0.05, 0.4], position: [1.5, 0.9, 1.0]}
"""))
    config = dataclasses.replace(load_plan_config(str(cell)), starts=3, inner_starts=2)
    source = PlanSource(model, config, small_plan.configurations)
    scenario, params = execute.plan_cell(config, source)
    assert params.acceleration_limit == (2.0,) and params.period == 0.005  # one value: every joint
    assert [o.name for o in params.collision.obstacles] == ["post"]
    np.testing.assert_array_equal(scenario.initial_positions, small_plan.configurations[0])
    assert scenario.reference is source and scenario.obstacles == params.collision.obstacles
    bare_scenario, bare = execute.plan_cell(small_config(), source)
    assert bare == ControllerParams(period=0.005) and not bare_scenario.obstacles
    # a plan's scenario needs no segments of its own (the planner reads only its corner): its cell still counts
    plain = tmp_path / "corner_only.yaml"
    lines = cell.read_text().splitlines(keepends=True)
    start = next(k for k, line in enumerate(lines) if line.startswith("      segments:"))
    end = next(k for k, line in enumerate(lines) if line.startswith("      side_2:"))
    plain.write_text("".join(lines[:start] + lines[end + 1:]))
    only = dataclasses.replace(load_plan_config(str(plain)), starts=3, inner_starts=2)
    assert execute.plan_cell(only, PlanSource(model, only, small_plan.configurations))[1] == params

    used: list[ControllerParams] = []

    def stop(scenario_run: object, params_run: ControllerParams, *args: object) -> None:
        used.append(params_run)
        raise RuntimeError("stop here")

    monkeypatch.setattr(execute, "run_scenario", stop)
    with pytest.raises(RuntimeError, match="stop here"):
        execute.execute_plan(config, small_plan.configurations, model)
    assert used == [params]
