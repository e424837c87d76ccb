"""Property tests (issue 11): every registered solver's command is finite and inside eq (21)-(23), always.

Random configurations (inside, at and beyond the joint limits), random targets (unreachable,
very fast, sometimes NaN), with and without the acceleration bound, through
:meth:`RelativeController.step`; and random problems (singular, rank-deficient Jacobians,
huge references) through each solver's ``solve`` directly. The registry is iterated, so a
solver added later is covered without editing this file.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from dualarm_control.controller import ControllerParams, RelativeController
from dualarm_control.kinematics import DualArmModel
from dualarm_control.limits import JointLimits, velocity_bounds
from dualarm_control.solvers import ControlProblem, make_solver, solver_names
from dualarm_control.solvers.base import FALLBACK_DAMPING, rest_command

PERIOD = 0.005
TOL = 1e-9  # rad/s: floating-point slack on the bounds
FINITE = {"allow_nan": False, "allow_infinity": False}
PROPERTY = settings(max_examples=100, deadline=None, derandomize=True,
                    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])


@dataclass(frozen=True)
class Target:
    """A RelativeTarget (see dualarm_control.controller)."""

    position: np.ndarray
    rotation: np.ndarray
    linear_velocity: np.ndarray
    angular_velocity: np.ndarray


@pytest.fixture(scope="module")
def model() -> DualArmModel:
    return DualArmModel()


@st.composite
def configurations(draw: st.DrawFn, q_min: np.ndarray, q_max: np.ndarray) -> np.ndarray:
    """Joint positions: each joint inside its range, exactly at a limit, or up to 20 % of the range beyond;
    or a singular configuration (an arm stretched: every joint of it at 0, the LWR4's straight-up pose)."""
    margin = draw(st.sampled_from([0.0, 0.2]))  # 0: every joint inside or at a limit
    where = st.one_of(st.floats(-margin, 1.0 + margin, **FINITE), st.sampled_from([0.0, 1.0, -1e-9, 1.0 + 1e-9]))
    shares = np.array(draw(st.lists(where, min_size=q_min.size, max_size=q_min.size)))
    q = q_min + shares * (q_max - q_min)
    stretched = draw(st.sampled_from(["none", "none", "left", "right", "both"]))
    half = q_min.size // 2
    if stretched in ("left", "both"):
        q[:half] = 0.0
    if stretched in ("right", "both"):
        q[half:] = 0.0
    return q


def vectors(scale: float) -> st.SearchStrategy[np.ndarray]:
    """3-vectors with entries up to +-scale (targets far out of reach, very fast twists)."""
    return st.lists(st.floats(-scale, scale, **FINITE), min_size=3, max_size=3).map(np.array)


@st.composite
def targets(draw: st.DrawFn) -> Target:
    """Relative targets: up to 10 m away (the cell reaches ~2 m), twists up to 100 m/s or rad/s, sometimes NaN."""
    position = draw(vectors(10.0))
    rotation = pin.exp3(draw(vectors(4.0)))
    linear, angular = draw(vectors(100.0)), draw(vectors(100.0))
    if draw(st.sampled_from([False] * 9 + [True])):
        position[draw(st.integers(0, 2))] = np.nan
    return Target(position, rotation, linear, angular)


def assert_inside_eq21_23(qd: np.ndarray, q: np.ndarray, limits: JointLimits) -> None:
    """Finite; inside the velocity bounds of eq (23) (as :func:`velocity_bounds` extends them beyond a
    limit); |qd| <= qd_max (eq 20); one step keeps q in [q_min, q_max] (eq 21), or, for a joint already
    beyond a limit by d, brings it back by min(d, qd_max T) (the distance to the range never grows)."""
    assert np.all(np.isfinite(qd)), qd
    lower, upper = velocity_bounds(q, limits, PERIOD)
    assert np.all(qd >= lower - TOL) and np.all(qd <= upper + TOL), (qd, lower, upper)
    assert np.all(np.abs(qd) <= limits.qd_max + TOL)
    q_next = q + qd * PERIOD
    beyond = np.maximum(limits.q_min - q, 0.0) + np.maximum(q - limits.q_max, 0.0)
    beyond_next = np.maximum(limits.q_min - q_next, 0.0) + np.maximum(q_next - limits.q_max, 0.0)
    allowed = np.maximum(beyond - limits.qd_max * PERIOD, 0.0)
    assert np.all(beyond_next <= allowed + TOL * PERIOD + 1e-15), (q, qd)


@pytest.mark.parametrize("name", solver_names())
@pytest.mark.parametrize("acceleration", [(), (10.0,)], ids=["no_acc_bound", "acc_bound"])
def test_controller_command_is_finite_and_inside_eq21_23(name: str, acceleration: tuple[float, ...],
                                                         model: DualArmModel) -> None:
    """RelativeController.step: for any configuration and target, the command satisfies eq (21)-(23)."""
    controller = RelativeController(model, ControllerParams(solver=name, period=PERIOD,
                                                            acceleration_limit=acceleration))

    @PROPERTY
    @given(configurations(model.q_min, model.q_max), targets(), st.integers(1, 3))
    def check(q: np.ndarray, target: Target, cycles: int) -> None:
        controller.reset()
        for _ in range(cycles):  # later cycles use the warm start and the acceleration bound's memory
            out = controller.step(q, target)
            assert_inside_eq21_23(out.velocities, q, controller.limits)
            assert not out.result.failed or out.result.status == "invalid_input", out.result  # NaN targets only

    check()


@st.composite
def problems(draw: st.DrawFn, q_min: np.ndarray, q_max: np.ndarray, qd_max: np.ndarray
             ) -> tuple[ControlProblem, np.ndarray]:
    """Random J (full rank, rank-deficient, zero columns, or zero), reference up to 1e3, eq (23) bounds of q."""
    n = q_min.size
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    kind = draw(st.sampled_from(["full", "rank3", "zero_columns", "zero"]))
    jac = rng.standard_normal((6, n))
    if kind == "rank3":
        jac = rng.standard_normal((6, 3)) @ rng.standard_normal((3, n))
    elif kind == "zero_columns":
        jac[:, rng.random(n) < 0.5] = 0.0
    elif kind == "zero":
        jac[:] = 0.0
    reference = rng.standard_normal(6) * 10.0 ** draw(st.integers(-3, 3))
    q = draw(configurations(q_min, q_max))
    lower, upper = velocity_bounds(q, JointLimits(q_min, q_max, qd_max), PERIOD)
    repulsive = rng.uniform(-1.0, 1.0, n) * qd_max
    return ControlProblem(jac, reference, lower, upper, repulsive), q


@pytest.mark.parametrize("name", solver_names())
def test_solver_command_is_finite_and_inside_the_bounds(name: str, model: DualArmModel) -> None:
    """Solver.solve on random problems: finite, inside [lower, upper] and eq (21), never a failure status."""
    solver = make_solver(name)
    limits = JointLimits(model.q_min, model.q_max, model.qd_max)

    @PROPERTY
    @given(problems(model.q_min, model.q_max, model.qd_max))
    def check(case: tuple[ControlProblem, np.ndarray]) -> None:
        problem, q = case
        result = solver.solve(problem)
        assert_inside_eq21_23(result.velocities, q, limits)
        assert not result.failed, result  # a solver's own degraded statuses are allowed; failures fall back

    check()


@pytest.mark.parametrize("name", solver_names())
def test_fallback_command_is_finite_and_inside_the_bounds(name: str, model: DualArmModel,
                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    """Every solve forced to fail (QP infeasible): the bounded least-squares fallback satisfies eq (21)-(23)
    and, being the box's damped least-squares optimum, it is no worse than the rest command (a point of the box)."""
    solver = make_solver(name)
    monkeypatch.setattr(solver, "_solve", lambda problem: (None, "infeasible", 7, "QP infeasible"))
    limits = JointLimits(model.q_min, model.q_max, model.qd_max)

    @PROPERTY
    @given(problems(model.q_min, model.q_max, model.qd_max))
    def check(case: tuple[ControlProblem, np.ndarray]) -> None:
        problem, q = case
        result = solver.solve(problem)
        assert result.status == "fallback" and "infeasible" in result.detail, result
        assert_inside_eq21_23(result.velocities, q, limits)
        rest = rest_command(problem.lower, problem.upper)  # damped optimum: res^2 <= res_rest^2 + d ||rest||^2
        bound = np.linalg.norm(problem.jacobian @ rest - problem.reference) ** 2 + FALLBACK_DAMPING * rest @ rest
        assert result.task_residual <= np.sqrt(bound) + 1e-9

    check()
