"""Tests of the kinematic solvers (eq 13, 14, 17-19, 26-28) against independent solvers and brute force.

Independent references: numpy's pseudo-inverse, quadprog through qpsolvers (a dual active-set
method, unrelated to proxsuite's proximal method), scipy's HiGHS LP solver, and brute-force
vertex enumeration of the l1 problem.

Accuracy note (measured, explains the tolerances below): proxsuite stops when the primal and
dual residuals are below ``eps_abs`` (1e-9 by default) and the duality gap is too. The
standard QP's Hessian J^T J + eps I has curvature eps = 1e-6 in the 8-dimensional null space
of J, so a dual residual of 1e-9 leaves up to eps_abs / eps = 1e-3 rad/s of error in the
null-space component: the task part J qd and the objective are exact to ~1e-9, but the
"minimum-norm" tie-break is resolved only to ~1e-3 with the default settings and to ~1e-6
with eps_abs = 1e-12. Likewise the lasso objective is flat to 1e-9 between l1-optimal and
near-optimal supports, so l1 optimality is checked on well-scaled problems.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable

import numpy as np
import pytest
import qpsolvers
from scipy.optimize import linprog

from dualarm_control.app.bench.suite import solver_configs
from dualarm_control.controller import ControllerParams
from dualarm_control.errors import ParameterError, UnknownSolverError
from dualarm_control.kinematics import DualArmModel
from dualarm_control.limits import JointLimits, repulsive_velocity, velocity_bounds
from dualarm_control.qp import QPSettings, QPSolution, available_backends
from dualarm_control.solvers import (
    ACTIVITY_THRESHOLD,
    ControlProblem,
    Solver,
    SolverParams,
    make_solver,
    methods,
    solver_names,
)

LAMBDA = 1e-6  # default l1 weight (paper)
EPS = 1e-6  # default standard-QP regularization
ACCURATE = SolverParams(qp=QPSettings(eps_abs=1e-12))  # for checks of the formulation itself
EXACT = SolverParams(proximal_weight=0.0)  # the lasso of eq (19) at every call, no tie-break toward the last solution
PERIOD = 0.005
CONFIGS = solver_configs(ControllerParams(period=PERIOD), solver_names(), available_backends())[0]
"""Every registered solver with every QP back-end it accepts, as "solver | back-end"."""

Problem = ControlProblem


@pytest.fixture(scope="module")
def model() -> DualArmModel:
    return DualArmModel()


@pytest.fixture(scope="module")
def limits(model: DualArmModel) -> JointLimits:
    return JointLimits(model.q_min, model.q_max, model.qd_max)


# ---- problem generators and independent references -----------------------------------------


def random_problem(rng: np.random.Generator, width: float, n: int = 14) -> Problem:
    """Gaussian J (6, n) and reference; bounds [-U(0.05, width), U(0.05, width)] contain 0."""
    j = rng.standard_normal((6, n))
    lower, upper = -rng.uniform(0.05, width, n), rng.uniform(0.05, width, n)
    return Problem(j, rng.standard_normal(6), lower, upper, np.zeros(n))


def real_problem(
    model: DualArmModel, limits: JointLimits, rng: np.random.Generator, bound_scale: float = 1.0, ref: float = 0.2
) -> Problem:
    """Relative Jacobian at a random configuration, eq (23) bounds (optionally shrunk), random reference."""
    q = rng.uniform(0.8 * model.q_min, 0.8 * model.q_max)
    lower, upper = velocity_bounds(q, limits, PERIOD)
    jac = model.relative_state(q).jacobian
    return Problem(jac, ref * rng.standard_normal(6), bound_scale * lower, bound_scale * upper, np.zeros(14))


def mixed_problems(model: DualArmModel, limits: JointLimits, count: int, seed: int) -> list[Problem]:
    """Alternate random/real Jacobians, with wide bounds and with bounds that become active."""
    rng = np.random.default_rng(seed)
    out = []
    for k in range(count):
        if k % 2 == 0:
            out.append(random_problem(rng, 0.3 if k % 4 == 0 else 5.0))
        else:
            out.append(real_problem(model, limits, rng, 0.05 if k % 4 == 1 else 1.0))
    return out


def quadprog_standard(p: Problem, eps: float = EPS) -> np.ndarray:
    """Eq (14) solved by quadprog: min 1/2 ||J x - r||^2 + eps/2 ||x||^2 s.t. lower <= x <= upper."""
    h = p.jacobian.T @ p.jacobian + eps * np.eye(p.jacobian.shape[1])
    x = qpsolvers.solve_qp(h, -p.jacobian.T @ p.reference, lb=p.lower, ub=p.upper, solver="quadprog")
    assert x is not None
    return x


def standard_objective(p: Problem, x: np.ndarray, eps: float = EPS) -> float:
    return 0.5 * float(np.sum((p.jacobian @ x - p.reference) ** 2)) + 0.5 * eps * float(x @ x)


def lasso_objective(p: Problem, x: np.ndarray, lam: float = LAMBDA) -> float:
    """Eq (17): 1/2 ||J x - r||^2 + lambda ||x||_1."""
    return 0.5 * float(np.sum((p.jacobian @ x - p.reference) ** 2)) + lam * float(np.abs(x).sum())


def brute_force_min_l1(j: np.ndarray, r: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> tuple[float, np.ndarray]:
    """min ||x||_1 s.t. J x = r, lower <= x <= upper, by enumerating the LP's vertices.

    In the split form x = x+ - x- every vertex has 6 basic variables (a support S of size 6,
    x_S = J_S^-1 (r - J_N x_N)) and every other variable at 0 or at one of its bounds. With
    x_N = 0 this is the plain support enumeration (smaller supports appear as basic variables
    that happen to be 0); the bound values cover optima where a joint is saturated.
    """
    n = j.shape[1]
    best, best_x = math.inf, np.full(n, np.nan)
    for basis in itertools.combinations(range(n), 6):
        b = list(basis)
        rest = [i for i in range(n) if i not in basis]
        jb = j[:, b]
        if abs(np.linalg.det(jb)) < 1e-10:
            continue
        jb_inv = np.linalg.inv(jb)
        for values in itertools.product(*[(0.0, lower[i], upper[i]) for i in rest]):
            x = np.zeros(n)
            x[rest] = values
            x[b] = jb_inv @ (r - j[:, rest] @ np.asarray(values))
            if np.all(x >= lower - 1e-12) and np.all(x <= upper + 1e-12) and np.abs(x).sum() < best:
                best, best_x = float(np.abs(x).sum()), x
    return best, best_x


def lp_min_l1(j: np.ndarray, r: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> tuple[float, np.ndarray]:
    """Same LP by scipy/HiGHS in split form; returns the optimum and the equality duals y."""
    n = j.shape[1]
    bounds = [(0.0, max(u, 0.0)) for u in upper] + [(0.0, max(-lo, 0.0)) for lo in lower]
    lp = linprog(np.ones(2 * n), A_eq=np.hstack((j, -j)), b_eq=r, bounds=bounds, method="highs")
    assert lp.status == 0, lp.message
    return float(lp.fun), np.asarray(lp.eqlin.marginals)


def eq19_by_quadprog(p: Problem, delta: float = 1e-9) -> np.ndarray:
    """Eq (19) in 2n variables solved by quadprog, returning qd = z+ - z-.

    quadprog (Goldfarb-Idnani) needs a strictly positive definite Hessian, but eq (19)'s
    [[J^T J, -J^T J], [-J^T J, J^T J]] has rank <= 6; delta/2 ||z||^2 is added. It changes the
    optimal value by at most delta/2 ||z*||^2, which bounds the comparison tolerance below.
    """
    j, r = p.jacobian, p.reference
    n = j.shape[1]
    jtj, jtr = j.T @ j, j.T @ r
    h = np.block([[jtj, -jtj], [-jtj, jtj]]) + delta * np.eye(2 * n)
    g = LAMBDA * np.ones(2 * n) - np.concatenate((jtr, -jtr))
    c = np.hstack((np.eye(n), -np.eye(n)))
    z = qpsolvers.solve_qp(
        h, g, G=np.vstack((c, -c)), h=np.concatenate((p.upper, -p.lower)), lb=np.zeros(2 * n), solver="quadprog"
    )
    assert z is not None
    return np.clip(z[:n] - z[n:], p.lower, p.upper)


def near_limit_problem(model: DualArmModel, limits: JointLimits, joint: int, seed: int) -> tuple[Problem, np.ndarray]:
    """Real problem with joint ``joint`` at 98 % of its upper range (inside alpha = 0.1's band)."""
    rng = np.random.default_rng(seed)
    q = rng.uniform(0.5 * model.q_min, 0.5 * model.q_max)
    q[joint] = model.q_max[joint] - 0.01 * (model.q_max[joint] - model.q_min[joint])
    lower, upper = velocity_bounds(q, limits, PERIOD)
    rep = repulsive_velocity(q, limits, 0.1)
    jac = model.relative_state(q).jacobian
    return Problem(jac, 0.05 * rng.standard_normal(6), lower, upper, rep), q


# ---- registry ---------------------------------------------------------------------------------


def test_registry_lists_the_four_methods_of_the_paper() -> None:
    """solver_names() holds eq (13), (14), (17)-(19) and (26)-(28) of paper 000 and paper 001's
    constraint_based (eq 12-14), sorted; make_solver sets .name."""
    assert solver_names() == ["constraint_based", "hierarchical_sparse_l1_qp", "hierarchical_sparse_qp",
                              "pseudo_inverse", "sparse_qp", "standard_qp"]
    for name in solver_names():
        assert make_solver(name).name == name


def test_unknown_solver_raises_with_valid_names() -> None:
    """make_solver('nope') raises UnknownSolverError (a KeyError) whose message lists every valid name."""
    with pytest.raises(UnknownSolverError) as info:
        make_solver("nope")
    message = str(info.value)
    assert "'nope'" in message
    for name in solver_names():
        assert name in message
    assert isinstance(info.value, KeyError)


def test_unknown_qp_backend_raises_with_valid_names() -> None:
    """A QP solver with an unknown back-end name fails at construction, listing proxsuite and quadprog."""
    with pytest.raises(UnknownSolverError, match="proxsuite.*quadprog"):
        make_solver("sparse_qp", SolverParams(qp_backend="nope"))


# ---- per-solver contract (one test factory, parametrized over the registry) --------------------


def check_result_records(solver: Solver, problems: list[Problem]) -> None:
    """solve_time > 0, iterations >= 0, active_joints == count(|qd| > 1e-3), residual == ||J qd - r||, no
    failure; the solver's own result (before the clip) within its bound tolerance of the bounds, and the
    command inside them."""
    for p in problems:
        res = solver.solve(p)
        assert not res.failed, res.detail
        assert res.solve_time > 0 and res.iterations >= 0
        assert res.active_joints == int(np.sum(np.abs(res.velocities) > 1e-3))
        assert ACTIVITY_THRESHOLD == 1e-3
        assert res.task_residual == pytest.approx(np.linalg.norm(p.jacobian @ res.velocities - p.reference), abs=1e-12)
        assert np.all(np.isfinite(res.velocities))
        assert res.raw_velocities is not None
        assert np.all(res.raw_velocities >= p.lower - solver.bound_tolerance), res.raw_velocities - p.lower
        assert np.all(res.raw_velocities <= p.upper + solver.bound_tolerance), res.raw_velocities - p.upper
        assert res.bound_excess == max(0.0, float(np.max(np.maximum(p.lower - res.raw_velocities,
                                                                    res.raw_velocities - p.upper))))
        assert np.all(res.velocities >= p.lower) and np.all(res.velocities <= p.upper)


@pytest.mark.parametrize("config", list(CONFIGS))
def test_result_record_is_consistent(config: str, model: DualArmModel, limits: JointLimits) -> None:
    """Every solver and back-end: the record of :func:`check_result_records` on 8 mixed problems."""
    check_result_records(make_solver(CONFIGS[config].solver, CONFIGS[config].solver_params),
                         mixed_problems(model, limits, 8, seed=21))


def test_a_solver_ignoring_its_bounds_fails_the_record_check(bound_ignoring_solver: str, model: DualArmModel,
                                                            limits: JointLimits) -> None:
    """The check above can fail: test/bound_ignoring.py's solver is a failure ("bounds_violated")."""
    with pytest.raises(AssertionError, match="bounds_violated"):
        check_result_records(make_solver(bound_ignoring_solver), mixed_problems(model, limits, 8, seed=21))


# ---- the clip absorbs the back-end's tolerance, nothing more (issue 20) ---------------------------------


@pytest.mark.parametrize(("config", "tolerance"), [
    ("pseudo_inverse | -", 1e-12), ("standard_qp | daqp", 5e-9 + 1e-12), ("standard_qp | proxsuite", 5e-9 + 1e-12),
    ("standard_qp | quadprog", 5e-9 + 1e-12), ("constraint_based | daqp", 5e-9 + 1e-12),
    ("constraint_based | quadprog", 5e-9 + 1e-12), ("sparse_qp | daqp", 1e-8 + 1e-12),
    ("sparse_qp | proxsuite", 1e-8 + 1e-12), ("hierarchical_sparse_qp | daqp", 1e-8 + 1e-12)])
def test_bound_tolerances_are_the_documented_figures(config: str, tolerance: float) -> None:
    """docs/safety.md G1: round-off 1e-12 rad/s, plus 5 eps_abs (eps_abs = 1e-9) for a QP's x, twice that for the
    lasso's qd = qd+ - qd-; it follows eps_abs."""
    params = CONFIGS[config].solver_params
    assert make_solver(CONFIGS[config].solver, params).bound_tolerance == pytest.approx(tolerance, rel=1e-12)
    if CONFIGS[config].solver != "pseudo_inverse":
        coarse = SolverParams(qp_backend=params.qp_backend, qp=QPSettings(eps_abs=1e-6))
        assert make_solver(CONFIGS[config].solver, coarse).bound_tolerance == pytest.approx(
            1e-12 + (tolerance - 1e-12) * 1e3, rel=1e-9)


def overshooting(problem: Problem, joint: int, excess: float) -> np.ndarray:
    """A result inside the bounds except joint ``joint``, ``excess`` rad/s above its upper bound."""
    qd = 0.5 * (problem.lower + problem.upper)
    qd[joint] = problem.upper[joint] + excess
    return qd


@pytest.mark.parametrize("name", solver_names())
def test_an_overshoot_within_the_tolerance_is_clipped(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """_solve returns a result 0.9 x the solver's tolerance above a bound: status "solved", the command is
    the result clipped into the bounds, the raw result and its excess are in the record."""
    solver = make_solver(name)
    p = random_problem(np.random.default_rng(29), 1.0)
    raw = overshooting(p, 5, 0.9 * solver.bound_tolerance)
    monkeypatch.setattr(solver, "_solve", lambda problem: (raw.copy(), "solved", 3, ""))
    res = solver.solve(p)
    assert res.status == "solved" and not res.failed and res.iterations == 3
    np.testing.assert_array_equal(res.raw_velocities, raw)
    assert res.bound_excess == pytest.approx(0.9 * solver.bound_tolerance, rel=1e-3)
    np.testing.assert_array_equal(res.velocities, np.minimum(raw, p.upper))


@pytest.mark.parametrize("name", solver_names())
def test_an_overshoot_beyond_the_tolerance_is_a_failure_with_the_fallback_command(
        name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """_solve returns a result 1.1 x the solver's tolerance above a bound (status "solved"): status
    "bounds_violated" (a failure), the bounded least-squares step as command (as for an infeasible QP),
    the joint and the excess in detail; warm-start memory reset."""
    solver = make_solver(name)
    p = random_problem(np.random.default_rng(29), 1.0)
    raw = overshooting(p, 5, 1.1 * solver.bound_tolerance)
    monkeypatch.setattr(solver, "_solve", lambda problem: (raw.copy(), "solved", 3, ""))
    resets = []
    monkeypatch.setattr(solver, "reset", lambda: resets.append(1))
    res = solver.solve(p)
    assert res.status == "bounds_violated" and res.failed and not res.fell_back
    assert res.detail.startswith("bounds_violated: joint 5 at") and "beyond its upper bound" in res.detail
    assert "bounded least-squares step used" in res.detail and resets == [1]
    np.testing.assert_array_equal(res.raw_velocities, raw)
    monkeypatch.setattr(solver, "_solve", return_nothing)
    np.testing.assert_array_equal(res.velocities, solver.solve(p).velocities)  # the fallback command


def test_a_bound_violation_whose_fallback_fails_gives_the_command_nearest_to_rest(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """If the bounded least squares fails too: status "bounds_violated" and clip(0, lower, upper)."""
    from dualarm_control.solvers import policy

    solver = make_solver("standard_qp")
    p = random_problem(np.random.default_rng(29), 1.0)
    monkeypatch.setattr(solver, "_solve", lambda problem: (overshooting(p, 2, 0.1), "solved", 0, ""))
    monkeypatch.setattr(policy, "bounded_least_squares", lambda *args: None)
    res = solver.solve(p)
    assert res.status == "bounds_violated" and "nearest-to-rest" in res.detail
    np.testing.assert_array_equal(res.velocities, np.zeros(14))


def test_hierarchical_does_not_hide_a_primary_beyond_its_bounds(model: DualArmModel, limits: JointLimits,
                                                                monkeypatch: pytest.MonkeyPatch) -> None:
    """QP2 starts from qd1 clipped into the bounds; a qd1 beyond them by more than QP1's tolerance is not
    clipped there but reported: status "bounds_violated"; within the tolerance QP2 runs as usual."""
    p, _ = near_limit_problem(model, limits, 3, seed=74)
    for excess, status in ((1e-6, "bounds_violated"), (0.5e-9, "solved")):
        solver = make_solver("hierarchical_sparse_qp")
        qd1 = make_solver("sparse_qp").solve(p).velocities
        qd1[9] = p.upper[9] + excess
        monkeypatch.setattr(solver._primary, "_solve", lambda problem, qd1=qd1: (qd1.copy(), "solved", 1, ""))
        res = solver.solve(p)
        assert res.status == status, res.detail
        if status == "solved":
            assert np.all(res.raw_velocities <= p.upper + solver.bound_tolerance)
            assert np.any(res.raw_velocities != qd1)  # the secondary motion was added


@pytest.mark.parametrize("name", solver_names())
def test_task_met_up_to_each_methods_optimality_condition(name: str, model: DualArmModel, limits: JointLimits) -> None:
    """Wide bounds, real J: J^T (r - J qd) equals 0 (eq 13), eps qd (eq 14), or lies in lambda d||qd||_1 (eq 17, 26)."""
    rng = np.random.default_rng(22)
    solver = make_solver(name, EXACT)
    for _ in range(5):
        p = real_problem(model, limits, rng, ref=0.02)
        res = solver.solve(p)
        assert res.status == "solved"
        qd = res.velocities
        grad = p.jacobian.T @ (p.reference - p.jacobian @ qd)
        if name == "pseudo_inverse":
            assert res.task_residual < 1e-9
        elif name == "standard_qp":
            np.testing.assert_allclose(grad, EPS * qd, atol=2e-9)  # dual residual tolerance 1e-9
        elif name == "constraint_based":  # Q = eps I in u^T Q u (paper 001, eq 12): gradient 2 eps qd
            np.testing.assert_allclose(grad, 2 * EPS * qd, atol=2e-9)
        else:  # lasso KKT: |grad_i| <= lambda, and grad_i = lambda sign(qd_i) on the support
            assert np.max(np.abs(grad)) <= LAMBDA + 2e-9
            on = np.abs(qd) > 1e-6
            np.testing.assert_allclose(grad[on], LAMBDA * np.sign(qd[on]), atol=2e-9)
        assert res.task_residual < 1e-3 * np.linalg.norm(p.reference)


@pytest.mark.parametrize("name", solver_names())
def test_crossing_bounds_give_invalid_input_and_zero(name: str) -> None:
    """lower > upper (inconsistent input: velocity_bounds never gives it): status invalid_input, zero velocities."""
    rng = np.random.default_rng(23)
    p = random_problem(rng, 1.0)
    lower = p.lower.copy()
    lower[4] = p.upper[4] + 0.1
    res = make_solver(name).solve(Problem(p.jacobian, p.reference, lower, p.upper, p.repulsive))
    assert res.status == "invalid_input" and res.failed
    assert "joint 4" in res.detail
    np.testing.assert_array_equal(res.velocities, np.zeros(14))


@pytest.mark.parametrize("name", solver_names())
@pytest.mark.parametrize("field", ["jacobian", "reference", "lower", "upper", "repulsive"])
def test_non_finite_input_gives_invalid_input_and_zero(name: str, field: str) -> None:
    """A NaN in any input: status invalid_input naming the field, finite zero velocities."""
    rng = np.random.default_rng(24)
    p = random_problem(rng, 1.0)
    values = {f: np.array(getattr(p, f), dtype=float) for f in ("jacobian", "reference", "lower", "upper", "repulsive")}
    values[field].flat[3] = np.nan
    res = make_solver(name).solve(Problem(**values))
    assert res.status == "invalid_input"
    assert field in res.detail
    np.testing.assert_array_equal(res.velocities, np.zeros(14))
    assert res.active_joints == 0


@pytest.mark.parametrize("name", solver_names())
def test_wrong_shapes_give_invalid_input(name: str) -> None:
    """Mismatched shapes never raise: status invalid_input with a description."""
    rng = np.random.default_rng(25)
    p = random_problem(rng, 1.0)
    res = make_solver(name).solve(Problem(p.jacobian, p.reference[:5], p.lower, p.upper, p.repulsive))
    assert res.status == "invalid_input" and "shape" in res.detail
    res = make_solver(name).solve(Problem(p.jacobian, p.reference, p.lower[:13], p.upper, p.repulsive))
    assert res.status == "invalid_input" and "lower" in res.detail


def raise_linalg_error(problem: Problem) -> tuple:
    raise np.linalg.LinAlgError("singular matrix")


def raise_runtime_error(problem: Problem) -> tuple:
    raise RuntimeError("backend crashed")


def return_infinite(problem: Problem) -> tuple:
    return np.full(problem.jacobian.shape[1], np.inf), "solved", 1, ""


def return_nothing(problem: Problem) -> tuple:
    return None, "infeasible", 4, "QP infeasible"


def return_max_iter(problem: Problem) -> tuple:
    return np.full(problem.jacobian.shape[1], 1e3), "max_iter", 10000, "QP max_iter"


def return_wrong_shape(problem: Problem) -> tuple:
    return np.zeros(problem.jacobian.shape[1] - 1), "solved", 1, ""


@pytest.mark.parametrize("name", solver_names())
@pytest.mark.parametrize("failure", [raise_linalg_error, raise_runtime_error, return_infinite, return_nothing,
                                     return_max_iter, return_wrong_shape])
def test_numerical_failures_give_the_bounded_least_squares_fallback(name: str, failure: Callable,
                                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    """Whatever _solve does (raise, inf, no solution, iteration cap, a wrong shape), solve() returns status "fallback" with
    the reason in detail and the bounded least-squares step: inside the bounds, and its residual no worse
    than any other point of the box sampled here (it is the box's least-squares optimum)."""
    solver = make_solver(name)
    monkeypatch.setattr(solver, "_solve", failure)
    p = random_problem(np.random.default_rng(26), 1.0)
    res = solver.solve(p)
    assert res.status == "fallback" and res.fell_back and not res.failed
    assert "bounded least-squares step" in res.detail and res.detail.split(":")[0] in ("failed", "infeasible",
                                                                                      "max_iter")
    assert np.all(res.velocities >= p.lower) and np.all(res.velocities <= p.upper)
    rng = np.random.default_rng(27)
    for _ in range(50):
        other = rng.uniform(p.lower, p.upper)
        assert res.task_residual <= np.linalg.norm(p.jacobian @ other - p.reference) + 1e-9


@pytest.mark.parametrize("name", solver_names())
def test_failed_fallback_gives_the_command_nearest_to_rest(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """If the bounded least squares fails too: the original failure status and clip(0, lower, upper)."""
    from dualarm_control.solvers import policy

    solver = make_solver(name)
    monkeypatch.setattr(solver, "_solve", return_nothing)
    monkeypatch.setattr(policy, "bounded_least_squares", lambda *args: None)
    p = random_problem(np.random.default_rng(28), 1.0)
    lower = p.lower.copy()
    lower[2] = 0.3  # a joint that must move (beyond its lower limit): rest is not inside its bounds
    upper = np.maximum(p.upper, lower)
    res = solver.solve(Problem(p.jacobian, p.reference, lower, upper, p.repulsive))
    assert res.status == "infeasible" and res.failed and "nearest-to-rest" in res.detail
    expected = np.zeros(14)
    expected[2] = 0.3
    np.testing.assert_array_equal(res.velocities, expected)


@pytest.mark.parametrize("solver", ["sparse_qp", "hierarchical_sparse_qp"])
def test_backend_needing_a_definite_hessian_is_refused_at_start(solver: str) -> None:
    """sparse QPs on quadprog: eq (19)'s H is only semi-definite -> refused when built, naming valid back-ends."""
    with pytest.raises(ParameterError, match=r"qp_backend.*quadprog.*semi-definite.*daqp"):
        make_solver(solver, SolverParams(qp_backend="quadprog"))


def test_standard_qp_on_quadprog_needs_its_regularization() -> None:
    """standard_qp's H = J^T J + eps I is definite only with eps > 0: quadprog solves it, or is refused at eps = 0."""
    rng = np.random.default_rng(27)
    p = random_problem(rng, 1.0)
    res = make_solver("standard_qp", SolverParams(qp_backend="quadprog")).solve(p)
    ref = make_solver("standard_qp", SolverParams(qp_backend="daqp")).solve(p)
    assert res.status == "solved"
    np.testing.assert_allclose(res.velocities, ref.velocities, atol=1e-9)  # two exact active-set methods
    with pytest.raises(ParameterError, match="qp_backend"):
        make_solver("standard_qp", SolverParams(qp_backend="quadprog", regularization=0.0))


# ---- pseudo-inverse, eq (13) -------------------------------------------------------------------


def test_pseudo_inverse_equals_numpy_pinv_inside_bounds(model: DualArmModel, limits: JointLimits) -> None:
    """Eq (13) vs J^+ r from an SVD computed here, when it fits the bounds."""
    rng = np.random.default_rng(31)
    solver = make_solver("pseudo_inverse")
    for _ in range(5):
        p = real_problem(model, limits, rng, ref=0.02)
        u, s, vt = np.linalg.svd(p.jacobian, full_matrices=False)
        expected = vt.T @ ((u.T @ p.reference) / s)
        res = solver.solve(p)
        assert res.status == "solved"
        np.testing.assert_allclose(res.velocities, expected, atol=1e-9)


def test_pseudo_inverse_is_scaled_into_the_bounds() -> None:
    """Too fast: the J^+ r direction is kept and shrunk by the largest factor that fits (status scaled)."""
    rng = np.random.default_rng(32)
    p = random_problem(rng, 0.05)
    p = Problem(p.jacobian, 10 * p.reference, p.lower, p.upper, p.repulsive)
    full = np.linalg.pinv(p.jacobian) @ p.reference
    factor = 1.0
    for v, lo, u in zip(full, p.lower, p.upper, strict=True):
        factor = min(factor, u / v if v > u else (lo / v if v < lo else 1.0))
    assert factor < 0.5
    res = make_solver("pseudo_inverse").solve(p)
    assert res.status == "scaled" and not res.failed
    np.testing.assert_allclose(res.velocities, factor * full, rtol=1e-9, atol=1e-12)
    assert np.any(np.isclose(res.velocities, p.lower) | np.isclose(res.velocities, p.upper))


# ---- standard QP, eq (14) ----------------------------------------------------------------------


def test_standard_qp_formulation_matches_quadprog(model: DualArmModel, limits: JointLimits) -> None:
    """Eq (14) with eps_abs = 1e-12 vs quadprog on 24 problems (half with active bounds): qd within 5e-6."""
    worst = 0.0
    active = 0
    for p in mixed_problems(model, limits, 24, seed=41):
        ref = quadprog_standard(p)
        active += bool(np.any((ref <= p.lower + 1e-9) | (ref >= p.upper - 1e-9)))
        res = make_solver("standard_qp", ACCURATE).solve(p)
        assert res.status == "solved"
        worst = max(worst, float(np.max(np.abs(res.velocities - ref))))
    assert active >= 10, "the set must include problems with active bounds"
    assert worst < 5e-6, f"max |qd - qd_quadprog| = {worst:.3g}"  # null-space error ~ eps_abs / eps = 1e-6


def test_standard_qp_default_settings_accuracy(model: DualArmModel, limits: JointLimits) -> None:
    """Default settings vs quadprog: objective within 1e-8, task part J qd within 1e-5, qd within 3e-3 (see module doc)."""
    solver = make_solver("standard_qp")  # one object: warm-started from the previous problem each time
    for p in mixed_problems(model, limits, 24, seed=42):
        ref = quadprog_standard(p)
        res = solver.solve(p)
        assert res.status == "solved"
        assert standard_objective(p, res.velocities) <= standard_objective(p, ref) + 1e-8
        assert np.linalg.norm(p.jacobian @ (res.velocities - ref)) < 1e-5
        assert np.max(np.abs(res.velocities - ref)) < 3e-3


def test_standard_qp_is_minimum_norm_with_wide_bounds() -> None:
    """Wide bounds: eq (14) with eps = 1e-6 -> J^+ r (numpy pinv) within 1e-4 (accurate settings), 3e-3 (default)."""
    rng = np.random.default_rng(43)
    for _ in range(10):
        p = random_problem(rng, 1.0)
        p = Problem(p.jacobian, p.reference, np.full(14, -50.0), np.full(14, 50.0), p.repulsive)
        expected = np.linalg.pinv(p.jacobian) @ p.reference
        assert np.all(np.abs(expected) < 0.9 * np.minimum(-p.lower, p.upper))
        np.testing.assert_allclose(make_solver("standard_qp", ACCURATE).solve(p).velocities, expected, atol=1e-4)
        np.testing.assert_allclose(make_solver("standard_qp").solve(p).velocities, expected, atol=3e-3)


def test_standard_qp_warm_start_from_another_problem_is_still_optimal() -> None:
    """Regression: a proxsuite solve warm-started from problem A must reach B's optimum (quadprog) in objective.

    Without proxsuite's duality-gap test, this pair (seed 220) was reported "solved" with an
    objective 9e-4 above the optimum (bounds active); 29 of 300 such pairs were off by > 1e-8.
    """
    for seed in (220, 1, 50, 217):
        rng = np.random.default_rng(seed)
        a, b = (
            Problem(rng.standard_normal((6, 14)), rng.standard_normal(6), -rng.uniform(0, 0.2, 14),
                    rng.uniform(0, 0.2, 14), np.zeros(14))
            for _ in range(2)
        )
        solver = make_solver("standard_qp")
        solver.solve(a)
        res = solver.solve(b)
        assert standard_objective(b, res.velocities) <= standard_objective(b, quadprog_standard(b)) + 1e-8


# ---- sparse QP, eq (17)-(19) -------------------------------------------------------------------


@pytest.mark.parametrize("n", [8, 9])
def test_sparse_qp_attains_the_brute_force_minimum_l1(n: int) -> None:
    """Lasso eq (17) vs vertex enumeration of min ||x||_1 s.t. J x = r, bounds: l1 within 1e-4 relative, sparse support."""
    rng = np.random.default_rng(50 + n)
    solver = make_solver("sparse_qp", EXACT)
    for k in range(6):
        j = rng.standard_normal((6, n))
        width = 5.0 if k < 3 else 0.4
        lower, upper = -rng.uniform(0.1, width, n), rng.uniform(0.1, width, n)
        x0 = np.zeros(n)
        support = rng.choice(n, size=4 if k < 2 else n, replace=False)
        x0[support] = 0.9 * rng.uniform(lower[support], upper[support])
        r = j @ x0  # r in range(J), feasible within the bounds
        l1_min, x_min = brute_force_min_l1(j, r, lower, upper)
        l1_lp, y = lp_min_l1(j, r, lower, upper)
        assert l1_lp == pytest.approx(l1_min, rel=1e-9), "brute force and HiGHS disagree"
        res = solver.solve(Problem(j, r, lower, upper, np.zeros(n)))
        qd = res.velocities
        l1 = float(np.abs(qd).sum())
        assert abs(l1 - l1_min) <= 1e-4 * l1_min
        # Lasso vs LP: l1 <= l1* (the lasso trades residual for l1), and by weak duality with the
        # LP multipliers y: l1* <= l1 + ||y|| ||J qd - r||.
        assert l1 <= l1_min + 1e-7
        assert l1_min <= l1 + np.linalg.norm(y) * res.task_residual + 1e-7
        assert res.task_residual <= 1.5 * LAMBDA * np.linalg.norm(y) + 1e-8  # residual = lambda y at the optimum
        # Sparsity: the active set is a vertex's support, at most 6 joints plus saturated ones.
        saturated = int(np.sum(np.isclose(x_min, lower, atol=1e-9) | np.isclose(x_min, upper, atol=1e-9)))
        active = np.abs(qd) > 1e-6
        assert active.sum() <= 6 + saturated
        if saturated == 0:
            assert set(np.flatnonzero(active)) == set(np.flatnonzero(np.abs(x_min) > 1e-9))


def test_sparse_qp_uses_less_l1_and_few_joints_on_the_real_jacobian(model: DualArmModel, limits: JointLimits) -> None:
    """Real relative Jacobian, bounds far: ||qd_sparse||_1 <= ||qd_standard||_1 and <= 6 joints with |qd| > 1e-3.

    Fresh (cold-started) solvers: warm-starting from an unrelated problem can stop on a
    near-optimal support (lasso objective within ~1e-7, l1 up to ~20 % higher, 7 joints).
    """
    rng = np.random.default_rng(60)
    for _ in range(20):
        sparse, standard = make_solver("sparse_qp"), make_solver("standard_qp")
        p = real_problem(model, limits, rng, ref=0.05)
        qs, qn = sparse.solve(p), standard.solve(p)
        assert qs.status == "solved" and qn.status == "solved"
        assert np.all(np.abs(qs.velocities) < 0.9 * np.minimum(-p.lower, p.upper)), "bounds must be inactive"
        # Lasso optimality against the standard QP's point: l1_s <= l1_n + res_n^2 / (2 lambda).
        slack = qn.task_residual**2 / (2 * LAMBDA) + 1e-6
        assert np.abs(qs.velocities).sum() <= np.abs(qn.velocities).sum() + slack
        assert qs.active_joints <= 6
        assert qn.active_joints >= 6


def test_sparse_qp_objective_matches_eq19_solved_by_quadprog(model: DualArmModel, limits: JointLimits) -> None:
    """Eq (17) objective of sparse_qp vs eq (19) (2n variables) by quadprog with delta = 1e-9 added to H."""
    delta = 1e-9
    solver = make_solver("sparse_qp", EXACT)
    problems = mixed_problems(model, limits, 12, seed=61)
    for p in problems:
        qd = solver.solve(p).velocities
        ref = eq19_by_quadprog(p, delta)
        f_s, f_q = lasso_objective(p, qd), lasso_objective(p, ref)
        # f* <= f_s <= f* + solver tolerance; f* <= f_q <= f* + delta/2 ||z*||^2 (z* ~ |qd|).
        assert f_s <= f_q + 1e-8
        assert f_q <= f_s + 0.5 * delta * float(qd @ qd) + 1e-8


# ---- hierarchical sparse QP, eq (26)-(28) --------------------------------------------------------


def test_hierarchical_without_repulsion_equals_sparse_qp(model: DualArmModel, limits: JointLimits) -> None:
    """qd_r = 0: QP2's optimum is 0, so eq (28) gives QP1's (sparse_qp's) solution."""
    for p in mixed_problems(model, limits, 6, seed=70):
        a = make_solver("hierarchical_sparse_qp").solve(p)
        b = make_solver("sparse_qp").solve(p)
        np.testing.assert_allclose(a.velocities, b.velocities, atol=1e-12)
        assert a.status == b.status == "solved"


@pytest.mark.parametrize("joint", [1, 3, 10])
def test_hierarchical_secondary_motion_is_in_the_null_space_and_repulsive(
    joint: int, model: DualArmModel, limits: JointLimits
) -> None:
    """Joint near its upper limit: qd - qd1 in null(J), equals the projection (I - J^+ J) qd_r, pushes the joint down."""
    p, _ = near_limit_problem(model, limits, joint, seed=71 + joint)
    assert p.repulsive[joint] < 0 and np.count_nonzero(p.repulsive) == 1
    qd1 = make_solver("sparse_qp").solve(p).velocities
    res = make_solver("hierarchical_sparse_qp").solve(p)
    assert res.status == "solved" and res.detail == ""
    secondary = res.velocities - qd1
    assert np.linalg.norm(p.jacobian @ secondary) < 1e-6
    projection = (np.eye(14) - np.linalg.pinv(p.jacobian) @ p.jacobian) @ p.repulsive
    np.testing.assert_allclose(secondary, projection, atol=1e-6)
    assert secondary[joint] < 0
    assert secondary @ p.repulsive > 0
    assert np.all(res.velocities >= p.lower) and np.all(res.velocities <= p.upper)
    assert res.task_residual == pytest.approx(np.linalg.norm(p.jacobian @ qd1 - p.reference), abs=1e-6)


def test_hierarchical_secondary_respects_bounds_when_they_bind(model: DualArmModel, limits: JointLimits) -> None:
    """Large synthetic repulsion with tight bounds: result within bounds, secondary still in null(J) (quadprog QP2)."""
    rng = np.random.default_rng(72)
    p = real_problem(model, limits, rng, bound_scale=0.05, ref=0.005)
    rep = np.zeros(14)
    rep[2], rep[9] = 2.0, -2.0
    p = Problem(p.jacobian, p.reference, p.lower, p.upper, rep)
    qd1 = make_solver("sparse_qp").solve(p).velocities
    res = make_solver("hierarchical_sparse_qp").solve(p)
    secondary = res.velocities - qd1
    assert np.all(res.velocities >= p.lower) and np.all(res.velocities <= p.upper)
    assert np.linalg.norm(p.jacobian @ secondary) < 1e-6
    ref = qpsolvers.solve_qp(
        np.eye(14), -rep, A=p.jacobian, b=np.zeros(6), lb=p.lower - qd1, ub=p.upper - qd1, solver="quadprog"
    )
    np.testing.assert_allclose(secondary, ref, atol=1e-6)
    assert np.any(np.isclose(res.velocities, p.lower) | np.isclose(res.velocities, p.upper))


def test_hierarchical_qp2_is_always_feasible(model: DualArmModel, limits: JointLimits) -> None:
    """qd2 = 0 satisfies eq (27)'s constraints whenever qd1 is in bounds, so QP2 never fails on valid input."""
    rng = np.random.default_rng(73)
    solver = make_solver("hierarchical_sparse_qp")
    for _ in range(10):
        p = real_problem(model, limits, rng, bound_scale=rng.uniform(0.02, 1.0))
        p = Problem(p.jacobian, p.reference, p.lower, p.upper, rng.uniform(-1.0, 1.0, 14))
        res = solver.solve(p)
        assert res.status == "solved" and "secondary" not in res.detail


def test_hierarchical_falls_back_to_primary_when_qp2_fails(
    model: DualArmModel, limits: JointLimits, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A failing QP2 (forced) keeps the primary solution qd1 and says so in detail; nothing raises."""
    p, _ = near_limit_problem(model, limits, 3, seed=74)
    solver = make_solver("hierarchical_sparse_qp")
    monkeypatch.setattr(methods, "null_space_projection", lambda jacobian, velocity: None)  # force the QP
    monkeypatch.setattr(solver._secondary, "solve", lambda qp: QPSolution(None, "infeasible", 7, 1e-6))
    res = solver.solve(p)
    qd1 = make_solver("sparse_qp").solve(p).velocities
    assert res.status == "solved" and "secondary QP infeasible" in res.detail
    np.testing.assert_allclose(res.velocities, qd1, atol=1e-12)


# ---- warm start ----------------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["standard_qp", "sparse_qp", "hierarchical_sparse_qp"])
def test_warm_start_repeats_the_answer_with_no_more_iterations(
    name: str, model: DualArmModel, limits: JointLimits
) -> None:
    """Default back-end: solving the same problem twice gives the same qd (1e-8); for standard_qp in <=
    the first solve's iterations (the sparse solvers' second solve is the proximal step of eq (19), a
    different QP, whose optimum from an optimal z_prev is z_prev itself)."""
    p, _ = near_limit_problem(model, limits, 3, seed=80)
    solver = make_solver(name)
    first, second = solver.solve(p), solver.solve(p)
    assert first.status == second.status == "solved"
    np.testing.assert_allclose(second.velocities, first.velocities, atol=1e-8)
    if name == "standard_qp":
        assert second.iterations <= first.iterations
    solver.reset()
    third = solver.solve(p)
    assert third.iterations == first.iterations  # reset: cold start again, deterministic


def test_quadprog_backend_gives_the_same_standard_qp() -> None:
    """standard_qp on the quadprog back-end equals the direct quadprog solve (iterations reported as 0)."""
    rng = np.random.default_rng(81)
    solver = make_solver("standard_qp", SolverParams(qp_backend="quadprog"))
    for _ in range(4):
        p = random_problem(rng, 0.3)
        res = solver.solve(p)
        assert res.status == "solved" and res.iterations == 0
        np.testing.assert_allclose(res.velocities, quadprog_standard(p), atol=1e-12)


def test_a_solver_imports_what_its_cycles_need_when_built_and_never_scipy_optimize() -> None:
    """scipy.optimize cost every controller process 0.45-0.5 s of CPU to import (it was the fallback's BVLS);
    the fallback is a daqp box QP now: a solver built and a fallback taken leave it unimported. LAPACK's dposv
    (scipy's extension module alone, without scipy.linalg's package: 0.02 s and 4 MiB, test_lapack.py) is loaded
    when the solver is built, not in a first cycle (where the soak saw scipy.linalg's import as a deadline burst
    and 14 % RSS growth); the simulator node loads neither."""
    import subprocess
    import sys

    probe = ("import sys, numpy as np, dualarm_sim.sim_node; "
             "print('scipy.linalg._flapack' in sys.modules, 'scipy.linalg' in sys.modules); "
             "from dualarm_control.solvers import make_solver; "
             "from dualarm_control.solvers.policy import bounded_least_squares; make_solver('sparse_qp'); "
             "print('scipy.linalg._flapack' in sys.modules, 'scipy.linalg' in sys.modules); "
             "qd = bounded_least_squares(np.ones((6, 14)), np.ones(6), -np.ones(14), np.ones(14)); "
             "print(qd is not None, 'scipy.optimize' in sys.modules)")
    lines = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True,
                           timeout=120).stdout.split()
    assert lines[-6:] == ["False", "False", "True", "False", "True", "False"], lines


@pytest.mark.parametrize("seed", range(40))
def test_the_fallback_step_is_scipys_bounded_least_squares(seed: int) -> None:
    """The fallback's box QP (daqp) against scipy's BVLS (``lsq_linear``) on the stacked system
    [J; sqrt(eps) I] qd = [r; 0]: random J (some rank-deficient), references that push several joints
    onto their bounds, some joints fixed (lower == upper). The same minimiser to 1e-7 rad/s and the same
    objective to 1e-9 (relative)."""
    from scipy.optimize import lsq_linear

    from dualarm_control.solvers.policy import FALLBACK_DAMPING, bounded_least_squares

    rng = np.random.default_rng(seed)
    n = 14
    jac = rng.standard_normal((6, n))
    if seed % 4 == 0:
        jac[:, 3] = jac[:, 2]  # a repeated column: J^T J singular, the damping decides
    r = rng.standard_normal(6) * (0.5 + 3.0 * (seed % 3))
    upper = rng.uniform(0.05, 1.0, n)
    lower = -rng.uniform(0.05, 1.0, n)
    if seed % 5 == 0:
        lower[5] = upper[5] = 0.2  # a fixed joint
    qd = bounded_least_squares(jac, r, lower, upper)
    assert qd is not None and np.all(qd >= lower) and np.all(qd <= upper)
    free = upper - lower > 1e-12
    fixed = np.where(free, 0.0, lower)
    a = np.vstack((jac[:, free], np.sqrt(FALLBACK_DAMPING) * np.eye(int(free.sum()))))
    b = np.concatenate((r - jac @ fixed, np.zeros(int(free.sum()))))
    ref = np.where(free, 0.0, lower)
    ref[free] = lsq_linear(a, b, bounds=(lower[free], upper[free]), method="bvls", tol=1e-14).x

    def cost(x: np.ndarray) -> float:
        return float(np.sum((jac @ x - r) ** 2) + FALLBACK_DAMPING * np.sum(x[free] ** 2))

    np.testing.assert_allclose(qd, ref, atol=1e-7)
    assert abs(cost(qd) - cost(ref)) <= 1e-9 * max(1.0, cost(ref))


@pytest.mark.parametrize("name", ["hierarchical_sparse_qp", "hierarchical_sparse_l1_qp"])
@pytest.mark.parametrize("status", ["max_iter", "infeasible"])
def test_a_second_level_that_does_not_solve_leaves_the_primary_task(name: str, status: str,
                                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    """The second level's QP ends at its iteration cap (its x an iterate far beyond the bounds) or infeasible: the
    command is the first level's, inside the bounds, its detail naming the second level's status. Before, a
    "max_iter" iterate was commanded and reported "bounds_violated" (proxsuite in the property tests, once the
    cap was 1,000)."""
    from dualarm_control.status import Status

    rng = np.random.default_rng(43)
    p = random_problem(rng, 0.5)
    p = Problem(p.jacobian, p.reference, p.lower, p.upper, 3.0 * p.upper * np.sign(rng.standard_normal(14)))
    solver = make_solver(name)
    primary = make_solver("sparse_qp").solve(Problem(p.jacobian, p.reference, p.lower, p.upper, np.zeros(14)))
    calls: list[int] = []

    def unsolved(problem: object) -> QPSolution:
        calls.append(1)
        n = problem.H.shape[0]  # type: ignore[attr-defined]
        return QPSolution(x=np.full(n, 50.0) if status == "max_iter" else None, status=Status(status), iterations=1000,
                          solve_time=0.0)

    monkeypatch.setattr(solver._secondary, "solve", unsolved)
    res = solver.solve(p)
    assert calls, "the second level was not reached: the test's problem needs a larger repulsive velocity"
    assert res.status == "solved" and f"QP {status}; primary task only" in res.detail, res
    assert np.allclose(res.velocities, primary.velocities, atol=1e-12), (res.velocities, primary.velocities)
    assert np.all(res.velocities >= p.lower - 1e-12) and np.all(res.velocities <= p.upper + 1e-12)


def test_quadprog_called_directly_solves_what_proxsuite_solves() -> None:
    """The separating step's last back-end (policy.quadprog_solve: quadprog without qpsolvers) on 60 random QPs with
    equality rows, two-sided and one-sided rows and a box: the same minimiser as proxsuite to 1e-7; an infeasible
    one gives None."""
    from dualarm_control.qp import QPProblem, make_backend
    from dualarm_control.solvers.policy import quadprog_solve

    rng = np.random.default_rng(0)
    for k in range(60):
        n, p, equalities = 8, 5, k % 3
        m = rng.standard_normal((n, n))
        a = rng.standard_normal((equalities, n)) if equalities else None
        qp = QPProblem(H=m @ m.T + 0.1 * np.eye(n), g=rng.standard_normal(n), A=a,
                       b=None if a is None else a @ rng.uniform(-0.1, 0.1, n), C=rng.standard_normal((p, n)),
                       l=np.where(rng.random(p) < 0.5, -np.inf, -rng.random(p)), u=rng.random(p) + 0.1,
                       lb=-np.ones(n), ub=np.ones(n))
        x, reference = quadprog_solve(qp), make_backend("proxsuite").solve(qp).x
        assert x is not None and reference is not None
        np.testing.assert_allclose(x, reference, atol=1e-7)
    infeasible = QPProblem(H=np.eye(2), g=np.zeros(2), C=np.array([[1.0, 0.0]]), l=np.array([2.0]), u=np.array([3.0]),
                           lb=-np.ones(2), ub=np.ones(2))
    assert quadprog_solve(infeasible) is None


def test_daqp_is_held_to_its_own_tolerance_in_x_and_no_further() -> None:
    """DaqpBackend.onto_box: daqp tests a bound in its normalised dual space, so in x a bound holds to
    primal_tol sqrt((H^-1)_ii). Against an independent inverse (numpy's inv of H, not its Cholesky factor): an x
    beyond the box within bound_tolerance * sqrt((H^-1)_ii) is moved onto it; one beyond that, or any x when H is
    not positive definite, is returned as it is (the solver's bounds check reports it)."""
    from dualarm_control.qp import DaqpBackend

    backend = DaqpBackend(QPSettings())
    rng = np.random.default_rng(7)
    b = rng.standard_normal((6, 28))
    h = b.T @ b + 1e-6 * np.eye(28)  # the sparse QP's lasso H with its proximal weight
    scale = np.sqrt(np.diag(np.linalg.inv(h)))
    assert scale.min() > 100.0, scale.min()  # ill-conditioned: daqp's tolerance in x is 100x its primal_tol and more
    lower, upper = np.zeros(28), np.full(28, 2.0)
    x = np.linspace(0.0, 2.0, 28)
    inside = backend.onto_box(h, x, lower, upper)
    assert inside is x  # within the plain tolerance: untouched, no work
    near = x.copy()
    near[5] = 2.0 + 0.5 * backend.bound_tolerance * scale[5]
    near[9] = -0.5 * backend.bound_tolerance * scale[9]
    moved = backend.onto_box(h, near, lower, upper)
    assert moved[5] == 2.0 and moved[9] == 0.0 and np.array_equal(np.delete(moved, [5, 9]), np.delete(x, [5, 9]))
    far = x.copy()
    far[5] = 2.0 + 2.0 * backend.bound_tolerance * scale[5]
    assert backend.onto_box(h, far, lower, upper) is far
    singular = b.T @ b  # rank 6: the proximal loop's lasso, no tolerance to read off
    assert backend.onto_box(singular, near, lower, upper) is near
