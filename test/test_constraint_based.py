"""Tests of the constraint_based solver (paper 001, eq 12-14 with weighted slacks)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import minimize

from dualarm_control.controller_params import controller_params
from dualarm_control.params import read_params_files
from dualarm_control.paths import config_path
from dualarm_control.qp import QPSettings
from dualarm_control.solvers import (
    ControlProblem,
    SolverParams,
    make_solver,
    solver_names,
)

N = 14
EPS = 1e-6


def random_problem(seed: int) -> ControlProblem:
    """3 equality rows, 4 inequality rows, a box; feasible (u = 0 satisfies the inequalities)."""
    rng = np.random.default_rng(seed)
    a = rng.standard_normal((3, N))
    c = rng.standard_normal((4, N))
    return ControlProblem(a, rng.standard_normal(3), -np.ones(N), np.ones(N), np.zeros(N),
                          inequality_jacobian=c, inequality_bound=np.abs(rng.standard_normal(4)) * 0.1,
                          equality_weights=np.ones(3), inequality_weights=np.full(4, 1e3))


def test_registered_and_selected_by_its_parameter_file() -> None:
    assert "constraint_based" in solver_names()
    params = controller_params(read_params_files([str(config_path("solvers", "constraint_based.yaml"))],
                                                 "controller_node"))
    assert params.solver == "constraint_based"


@pytest.mark.parametrize("seed", range(3))
def test_matches_an_independent_solution(seed: int) -> None:
    """daqp vs proxsuite, and vs scipy (SLSQP) on the hard-constrained QP (slacks are 0 when feasible)."""
    problem = random_problem(seed)
    tight = QPSettings(eps_abs=1e-12)
    daqp = make_solver("constraint_based", SolverParams(qp=tight)).solve(problem)
    prox = make_solver("constraint_based", SolverParams(qp_backend="proxsuite", qp=tight)).solve(problem)
    assert daqp.status == prox.status == "solved"
    np.testing.assert_allclose(daqp.velocities, prox.velocities, atol=2e-6)  # flat directions: curvature 2 eps
    assert problem.inequality_jacobian is not None and problem.inequality_bound is not None
    a_ie, h = problem.inequality_jacobian, problem.inequality_bound
    assert np.all(a_ie @ daqp.velocities <= h + 1e-10)

    def cost(u: np.ndarray) -> float:
        d = problem.jacobian @ u - problem.reference
        return float(EPS * u @ u + 0.5 * d @ d)

    def grad(u: np.ndarray) -> np.ndarray:
        return 2 * EPS * u + problem.jacobian.T @ (problem.jacobian @ u - problem.reference)

    ref = minimize(cost, np.zeros(N), jac=grad, method="SLSQP", bounds=[(-1, 1)] * N,
                   constraints=[{"type": "ineq", "fun": lambda u: h - a_ie @ u, "jac": lambda u: -a_ie}],
                   options={"ftol": 1e-14, "maxiter": 1000})
    assert ref.success
    assert cost(daqp.velocities) <= cost(ref.x) + 1e-9
    np.testing.assert_allclose(problem.jacobian @ daqp.velocities, problem.jacobian @ ref.x, atol=1e-5)


def conflict(inequality_weight: float) -> ControlProblem:
    """Equality u_0 = 1 against the inequality u_0 <= 0."""
    row = np.zeros((1, N))
    row[0, 0] = 1.0
    return ControlProblem(row, np.array([1.0]), -np.ones(N), np.ones(N), np.zeros(N),
                          inequality_jacobian=row, inequality_bound=np.array([0.0]),
                          equality_weights=np.ones(1), inequality_weights=np.array([inequality_weight]))


def test_conflict_the_expensive_inequality_wins_the_cheap_equality_gives_way() -> None:
    result = make_solver("constraint_based").solve(conflict(1e3))
    assert result.status == "solved" and not result.failed
    assert abs(result.velocities[0]) < 1e-9  # inequality kept exactly (exact penalty)
    assert result.task_residual == pytest.approx(1.0, abs=1e-6)  # equality relaxed


def test_conflict_a_cheap_inequality_is_relaxed_and_reported() -> None:
    """With rho = 0.5 < the equality's pull (w_e * 1), the inequality slack is 0.5: u_0 = 1 - rho / w_e."""
    result = make_solver("constraint_based").solve(conflict(0.5))
    assert result.velocities[0] == pytest.approx(0.5, abs=1e-5)
    assert "inequality relaxed" in result.detail


def test_infeasible_inequalities_still_give_a_bounded_command() -> None:
    """u_0 <= -0.5 and -u_0 <= -0.5 (u_0 >= 0.5) cannot both hold: slacks share the violation."""
    rows = np.zeros((2, N))
    rows[0, 0], rows[1, 0] = 1.0, -1.0
    eq = np.zeros((1, N))
    eq[0, 1] = 1.0
    problem = ControlProblem(eq, np.array([0.2]), -np.ones(N), np.ones(N), np.zeros(N),
                             inequality_jacobian=rows, inequality_bound=np.array([-0.5, -0.5]),
                             inequality_weights=np.array([1e3, 1e3]))
    result = make_solver("constraint_based").solve(problem)
    assert result.status == "solved"
    assert abs(result.velocities[0]) < 1e-6  # the two equally weighted violations balance
    assert result.velocities[1] == pytest.approx(0.2, abs=1e-6)
    assert "inequality relaxed" in result.detail


def test_equality_only_is_paper_000s_least_squares() -> None:
    """Without inequality rows: J qd = r up to the eps regularisation, like standard_qp."""
    rng = np.random.default_rng(4)
    jac = rng.standard_normal((6, N))
    problem = ControlProblem(jac, rng.standard_normal(6) * 0.1, -np.ones(N), np.ones(N), np.zeros(N))
    ours = make_solver("constraint_based").solve(problem)
    standard = make_solver("standard_qp").solve(problem)
    assert ours.task_residual < 1e-5
    np.testing.assert_allclose(ours.velocities, standard.velocities, atol=1e-5)


def test_bad_inequality_shapes_give_the_safe_command() -> None:
    problem = random_problem(0)
    bad = ControlProblem(problem.jacobian, problem.reference, problem.lower, problem.upper, problem.repulsive,
                         inequality_jacobian=np.ones((2, N)), inequality_bound=np.ones(3))
    result = make_solver("constraint_based").solve(bad)
    assert result.status == "invalid_input" and np.all(result.velocities == 0)
