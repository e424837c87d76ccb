"""Closed loop (paper 000, Fig. 3): RelativeController + pybullet cell in lockstep on a short relative motion."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin
import pytest

from dualarm_control.controller import ControllerParams, RelativeController
from dualarm_control.errors import DimensionError
from dualarm_control.kinematics import DualArmModel, rotation_angle
from dualarm_control.scenario import load_scenario
from dualarm_control.solvers import solver_names
from dualarm_control.trajectory import RelativeTrajectory, Segment
from dualarm_sim.cell import DualArmCell
from dualarm_sim.cell_config import CellConfig

PERIOD = 0.005
SETTLE = 0.5  # s after the trajectory ends
MOVE = np.array([0.03, -0.02, 0.02 * math.sqrt(3)])  # 5 cm in F1
TURN_AXIS = np.array([1.0, 1.0, 1.0]) / math.sqrt(3)
TURN = math.radians(20.0)


@dataclass(frozen=True)
class Run:
    """What a closed-loop run recorded (per cycle unless stated)."""

    positions: np.ndarray  # measured q before each command, (N, 14)
    commands: np.ndarray  # (N, 14)
    raw: np.ndarray  # the solver's own result before the clip (SolverResult.raw_velocities), (N, 14)
    tolerance: float  # the solver's bound tolerance [rad/s]
    lower: np.ndarray  # eq (23) bounds recomputed here from the measured q, (N, 14)
    upper: np.ndarray
    statuses: list[str]
    active: np.ndarray  # active joints per cycle, (N,)
    final_q: np.ndarray
    end_position: np.ndarray  # trajectory end pose (exact)
    end_rotation: np.ndarray


@pytest.fixture(scope="module")
def model() -> DualArmModel:
    return DualArmModel()


@pytest.fixture(scope="module")
def start_q() -> np.ndarray:
    return load_scenario("assembly").initial_positions


def trajectory_from(model: DualArmModel, q: np.ndarray) -> RelativeTrajectory:
    """One pose segment: translate 5 cm and turn 20 degrees about (1,1,1)/sqrt(3), both in F1."""
    p0, r0 = model.relative_pose(q)
    r1 = pin.exp3(TURN_AXIS * TURN) @ r0
    limits = load_scenario("assembly").limits
    return RelativeTrajectory(p0, r0, [Segment.to_pose("move", r0, p0 + MOVE, r1)], limits)


def run_closed_loop(model: DualArmModel, q0: np.ndarray, solver: str) -> Run:
    controller = RelativeController(model, ControllerParams(solver=solver, period=PERIOD))
    traj = trajectory_from(model, q0)
    steps = math.ceil((traj.duration + SETTLE) / PERIOD)
    assert steps * PERIOD <= 4.0, "keep the run short"
    qd_max = model.qd_max  # velocity_scale 1
    rec: dict[str, list] = {k: [] for k in ("positions", "commands", "raw", "lower", "upper", "statuses", "active")}
    with DualArmCell(CellConfig(control_period=PERIOD), initial_positions=q0) as cell:
        state = cell.state()
        for k in range(steps):
            q = np.array(state.positions)
            out = controller.step(q, traj.sample(k * PERIOD))
            cell.apply_command(out.velocities)
            rec["positions"].append(q)
            rec["commands"].append(out.velocities)
            rec["raw"].append(out.result.raw_velocities)
            rec["lower"].append(np.maximum(-qd_max, (model.q_min - q) / PERIOD))  # eq (23), written here
            rec["upper"].append(np.minimum(qd_max, (model.q_max - q) / PERIOD))
            rec["statuses"].append(out.result.status)
            rec["active"].append(out.result.active_joints)
            state = cell.step()
    end = traj.sample(traj.duration)
    arrays = {k: np.array(v) for k, v in rec.items() if k != "statuses"}
    return Run(statuses=rec["statuses"], final_q=np.array(state.positions), end_position=end.position,
               end_rotation=end.rotation, tolerance=controller.solver.bound_tolerance, **arrays)


@pytest.fixture(scope="module")
def runs(model: DualArmModel, start_q: np.ndarray) -> dict[str, Run]:
    return {name: run_closed_loop(model, start_q, name) for name in solver_names()}


@pytest.mark.parametrize("solver", solver_names())
def test_closed_loop_reaches_the_target(solver: str, runs: dict[str, Run], model: DualArmModel) -> None:
    """Final relative pose from pinocchio FK of the measured q vs the trajectory's exact end pose."""
    run = runs[solver]
    p, r = model.relative_pose(run.final_q)
    # measured 2026-12 (deterministic): 8.8e-8 m / 6.2e-7 rad (standard_qp, pseudo_inverse, constraint_based),
    # 3.0e-7 m / 7.8e-7 rad (sparse_qp, hierarchical_sparse_qp); bounds 10 x the largest
    position_error, rotation_error = float(np.linalg.norm(p - run.end_position)), rotation_angle(r, run.end_rotation)
    assert position_error < 3e-6 and rotation_error < 8e-6, (position_error, rotation_error)
    p0, r0 = model.relative_pose(run.positions[0])  # and the motion really happened
    assert np.linalg.norm(p - p0) == pytest.approx(0.05, abs=2e-3)
    assert rotation_angle(r, r0) == pytest.approx(TURN, abs=1e-2)


def check_safe_run(run: Run, model: DualArmModel) -> None:
    """No solver failure; the solver's own result (before the clip) within its bound tolerance of the eq (23)
    bounds of the measured q, and every command inside them; q inside the URDF limits."""
    assert set(run.statuses) == {"solved"}, sorted(set(run.statuses))
    assert np.all(np.isfinite(run.raw)) and np.all(np.isfinite(run.commands))
    assert np.all(run.raw >= run.lower - run.tolerance - 1e-12) and np.all(run.raw <= run.upper + run.tolerance + 1e-12)
    assert np.all(run.commands >= run.lower - 1e-12) and np.all(run.commands <= run.upper + 1e-12)
    assert np.all(run.positions >= model.q_min) and np.all(run.positions <= model.q_max)
    assert np.all(run.final_q >= model.q_min) and np.all(run.final_q <= model.q_max)


@pytest.mark.parametrize("solver", solver_names())
def test_closed_loop_commands_are_safe(solver: str, runs: dict[str, Run], model: DualArmModel) -> None:
    """:func:`check_safe_run` on each solver's run."""
    check_safe_run(runs[solver], model)


def test_a_solver_ignoring_its_bounds_fails_the_safety_check(bound_ignoring_solver: str, model: DualArmModel,
                                                             start_q: np.ndarray) -> None:
    """The check above can fail: with test/bound_ignoring.py's solver every cycle is "bounds_violated" (the
    fallback's commands keep the cell inside its limits, but its own results leave the bounds)."""
    run = run_closed_loop(model, start_q, bound_ignoring_solver)
    assert set(run.statuses) == {"bounds_violated"}
    assert np.all(run.commands >= run.lower - 1e-12) and np.all(run.commands <= run.upper + 1e-12)
    with pytest.raises(AssertionError, match="bounds_violated"):
        check_safe_run(run, model)


def test_sparse_methods_move_fewer_joints(runs: dict[str, Run]) -> None:
    """Paper's claim (Table I, l0): the lasso methods use fewer active joints than eq (13)/(14) on the same motion."""
    moving = runs["standard_qp"].active > 0
    mean = {name: float(run.active[moving].mean()) for name, run in runs.items()}
    for sparse in ("sparse_qp", "hierarchical_sparse_qp"):
        assert mean[sparse] <= 6.0
        for dense in ("standard_qp", "pseudo_inverse"):
            assert mean[sparse] < mean[dense] - 2.0, mean


@dataclass
class Target:
    """A RelativeTarget built by hand."""

    position: np.ndarray
    rotation: np.ndarray
    linear_velocity: np.ndarray
    angular_velocity: np.ndarray


@pytest.mark.parametrize("solver", solver_names())
def test_nan_joint_positions_give_invalid_input_and_zero_command(
    solver: str, model: DualArmModel, start_q: np.ndarray
) -> None:
    """NaN in q: no raise, status invalid_input, zero command, NaN errors; the next valid cycle works again."""
    controller = RelativeController(model, ControllerParams(solver=solver))
    p0, r0 = model.relative_pose(start_q)
    target = Target(p0 + 0.01, r0, np.zeros(3), np.zeros(3))
    q = start_q.copy()
    q[5] = np.nan
    out = controller.step(q, target)
    assert out.result.status == "invalid_input" and "joint positions" in out.result.detail
    np.testing.assert_array_equal(out.velocities, np.zeros(14))
    assert math.isnan(out.position_error)
    ok = controller.step(start_q, target)
    assert ok.result.status == "solved" and np.any(ok.velocities != 0)
    assert ok.position_error == pytest.approx(0.01 * math.sqrt(3), rel=1e-9)


@pytest.mark.parametrize("field", ["position", "rotation", "linear_velocity", "angular_velocity"])
def test_nan_target_gives_invalid_input_and_zero_command(field: str, model: DualArmModel, start_q: np.ndarray) -> None:
    """NaN anywhere in the target: no raise, status invalid_input naming the target, zero command."""
    controller = RelativeController(model)
    p0, r0 = model.relative_pose(start_q)
    parts = {"position": p0.copy(), "rotation": r0.copy(), "linear_velocity": np.zeros(3), "angular_velocity": np.zeros(3)}
    parts[field].flat[0] = np.nan
    out = controller.step(start_q, Target(**parts))
    assert out.result.status == "invalid_input" and "relative target" in out.result.detail
    np.testing.assert_array_equal(out.velocities, np.zeros(14))


def test_wrong_joint_count_raises_dimension_error(model: DualArmModel, start_q: np.ndarray) -> None:
    """A 13-joint state is a programming error: DimensionError (not a silent command)."""
    p0, r0 = model.relative_pose(start_q)
    with pytest.raises(DimensionError, match="14"):
        RelativeController(model).step(start_q[:13], Target(p0, r0, np.zeros(3), np.zeros(3)))


def test_one_cycle_reference_is_feedforward_plus_gain_times_error(model: DualArmModel, start_q: np.ndarray) -> None:
    """Eq (13) input: with pseudo_inverse, J qd equals xd* + K e (e from eq 8-10 computed here)."""
    controller = RelativeController(model, ControllerParams(solver="pseudo_inverse", gain=10.0))
    p0, r0 = model.relative_pose(start_q)
    r_des = pin.exp3(np.array([0.0, 0.0, 0.01])) @ r0
    target = Target(p0 + np.array([0.001, 0.0, -0.002]), r_des, np.array([0.01, 0.0, 0.0]), np.array([0.0, 0.02, 0.0]))
    out = controller.step(start_q, target)
    a = r_des @ r0.T
    e_o = 0.5 * np.array([a[2, 1] - a[1, 2], a[0, 2] - a[2, 0], a[1, 0] - a[0, 1]])
    expected = np.concatenate(([0.01, 0.0, 0.0], [0.0, 0.02, 0.0])) + 10.0 * np.concatenate(([0.001, 0.0, -0.002], e_o))
    jac = model.relative_state(start_q).jacobian
    np.testing.assert_allclose(jac @ out.velocities, expected, atol=1e-9)
    assert out.orientation_error == pytest.approx(0.01, abs=1e-9)


@pytest.mark.parametrize("joint", [3, 9])
def test_hierarchical_pushes_a_joint_out_of_the_limit_band_while_holding_the_pose(
    joint: int, model: DualArmModel, start_q: np.ndarray
) -> None:
    """Joint at 2 % of its range from q_max, target = start pose: eq (26)-(28) moves it toward the 5 % threshold
    (alpha = 0.1) through the null space; sparse_qp alone leaves it there. Pose from pinocchio FK of measured q."""
    q0 = start_q.copy()
    span = model.q_max[joint] - model.q_min[joint]
    q0[joint] = model.q_max[joint] - 0.02 * span
    p0, r0 = model.relative_pose(q0)
    hold = Target(p0, r0, np.zeros(3), np.zeros(3))
    margin = {}
    for solver in ("sparse_qp", "hierarchical_sparse_qp"):
        controller = RelativeController(model, ControllerParams(solver=solver, alpha=0.1))
        with DualArmCell(CellConfig(control_period=PERIOD), initial_positions=q0) as cell:
            state = cell.state()
            for _ in range(200):  # 1 s
                out = controller.step(np.array(state.positions), hold)
                assert out.result.status == "solved"
                cell.apply_command(out.velocities)
                state = cell.step()
        q = np.array(state.positions)
        p, r = model.relative_pose(q)
        assert np.linalg.norm(p - p0) < 1e-3 and rotation_angle(r, r0) < 1e-2
        margin[solver] = (model.q_max[joint] - q[joint]) / span
    assert margin["sparse_qp"] < 0.021
    assert 0.035 < margin["hierarchical_sparse_qp"] <= 0.05 + 1e-4  # the repulsion vanishes at the threshold
