"""Issue 8: the exact, fast lasso (daqp on the box form of eq 19), back-end refusal, tie-break.

References are independent of daqp: proxsuite at eps 1e-12 made exact on its own active
set and verified by the KKT conditions (:func:`lasso_on_active_set`), and the eq (19)
constraints as written (constraint rows [I, -I], z >= 0) solved by proxsuite.
"""

from __future__ import annotations

import itertools
from dataclasses import replace
from typing import Any

import numpy as np
import pytest

from dualarm_control.app.bench.random_set import (
    active_sets,
    control_problem,
    exactness,
    lasso_objective,
    lasso_on_active_set,
    random_cases,
)
from dualarm_control.controller import ControllerParams, RelativeController
from dualarm_control.errors import ParameterError
from dualarm_control.kinematics import DualArmModel
from dualarm_control.qp import (
    QPProblem,
    QPSettings,
    QpsolversBackend,
    available_backends,
    make_backend,
)
from dualarm_control.solvers import ControlProblem, Solver, SolverParams, make_solver
from dualarm_control.solvers.methods import (
    damped_least_squares,
    lasso_box,
    null_space_projection,
)

LAMBDA = 1e-6
EXACT = SolverParams(proximal_weight=0.0)
QP_SOLVERS = ("standard_qp", "sparse_qp", "hierarchical_sparse_qp")


@pytest.fixture(scope="module")
def model() -> DualArmModel:
    return DualArmModel()


@pytest.fixture(scope="module")
def problems(model: DualArmModel) -> list[ControlProblem]:
    controller = RelativeController(model, ControllerParams())
    return [control_problem(model, controller, case) for case in random_cases(model, 60, seed=8)]


def test_lasso_is_exact_on_the_random_set(model: DualArmModel) -> None:
    """Objective within 1e-9 relative of KKT-verified references, same active set, on 80 random cases."""
    record = exactness(model, random_cases(model, 80, seed=9), ControllerParams())
    assert record["verified_references"] >= 75  # proxsuite's active set is occasionally off; those are skipped
    assert record["objective_abs_rel_diff_max"] <= 1e-9
    assert record["same_active_set"] == record["verified_references"]


def test_lasso_on_active_set_rejects_a_non_optimal_guess(problems: list[ControlProblem]) -> None:
    """The reference builder is a real check: the zero command or a wrong support is not certified."""
    p = problems[0]
    assert lasso_on_active_set(p, np.zeros(14), LAMBDA) is None
    qd = make_solver("sparse_qp", EXACT).solve(p).velocities
    assert lasso_on_active_set(p, qd, LAMBDA) is not None
    wrong = qd.copy()
    off = int(np.flatnonzero(np.abs(qd) < 1e-9)[0])
    wrong[off] = 0.05  # a joint that must be at rest is moved
    assert lasso_on_active_set(p, wrong, LAMBDA) is None


def test_box_form_equals_eq19_as_written(problems: list[ControlProblem]) -> None:
    """Eq (19) with rows [I, -I] and z >= 0 (proxsuite, 1e-12) has the box form's optimum, also when 0 is outside the bounds."""
    solver = make_solver("sparse_qp", EXACT)
    reference = make_backend("proxsuite", QPSettings(eps_abs=1e-12, max_iter=1_000_000))
    rng = np.random.default_rng(3)
    for k, p in enumerate(problems[:12]):
        if k % 3 == 2:  # a range above zero on some joints, as an acceleration bound can make
            shifted = rng.uniform(0.0, 0.05, 14)
            p = ControlProblem(p.jacobian, p.reference, np.maximum(p.lower, shifted), p.upper, p.repulsive)
        solver.reset()
        qd = solver.solve(p).velocities
        b = np.hstack((p.jacobian, -p.jacobian))
        written = QPProblem(H=b.T @ b, g=LAMBDA - b.T @ p.reference, C=np.hstack((np.eye(14), -np.eye(14))),
                            l=p.lower, u=p.upper, lb=np.zeros(28), ub=np.full(28, 10.0))
        reference.reset()
        z = reference.solve(written).x
        assert z is not None
        f, f_ref = lasso_objective(p, qd, LAMBDA), lasso_objective(p, z[:14] - z[14:], LAMBDA)
        assert f <= f_ref * (1 + 1e-9)  # never worse than eq (19) as written
        assert f_ref <= f * (1 + 1e-4)  # proxsuite stops within 1e-4 of it on these


def test_lasso_box_maps_bounds() -> None:
    """Bounds around 0, above 0 and below 0 give the boxes of qd+ and qd- stated in lasso_box."""
    lb, ub = lasso_box(np.array([-1.0, 0.2, -0.5]), np.array([2.0, 0.7, -0.1]))
    np.testing.assert_array_equal(lb, [0.0, 0.2, 0.0, 0.0, 0.0, 0.1])
    np.testing.assert_array_equal(ub, [2.0, 0.7, 0.0, 1.0, 0.0, 0.5])


def test_basic_solution_has_at_most_six_active_joints(problems: list[ControlProblem]) -> None:
    """The exact lasso picks a basic solution: <= 6 joints with |qd| > 1e-3 on every random case."""
    solver = make_solver("sparse_qp", EXACT)
    for p in problems:
        solver.reset()
        assert solver.solve(p).active_joints <= 6


def tight(p: ControlProblem) -> ControlProblem:
    """The problem with a 20 x reference and bounds within +-0.05 rad/s: bounds active, the QP really solved."""
    return ControlProblem(p.jacobian, p.reference * 20, np.maximum(p.lower, -0.05), np.minimum(p.upper, 0.05),
                          p.repulsive)


def check_backend_solutions(under_test: Solver, exact: Solver, problems: list[ControlProblem]) -> None:
    """Status "solved", a non-zero command; the solver's own result (before the clip) within its bound
    tolerance of the bounds; the objective of the first QP (eq 14 or eq 17) within 2 % of ``exact``'s
    (proxsuite at eps 1e-9 stops up to ~1 % above the lasso optimum; daqp is exact)."""
    for p in map(tight, problems):
        res, ref = under_test.solve(p), exact.solve(p)
        assert res.status == "solved", res
        assert np.any(np.abs(res.velocities) > 1e-3)
        assert res.raw_velocities is not None and res.bound_excess <= under_test.bound_tolerance
        assert np.all(res.raw_velocities >= p.lower - under_test.bound_tolerance)
        assert np.all(res.raw_velocities <= p.upper + under_test.bound_tolerance)
        lasso = exact.name != "standard_qp"
        f = lasso_objective(p, res.velocities, LAMBDA) if lasso else res.task_residual
        f_ref = lasso_objective(p, ref.velocities, LAMBDA) if lasso else ref.task_residual
        assert f <= f_ref * 1.02 + 1e-12


@pytest.mark.parametrize("backend", available_backends())
@pytest.mark.parametrize("solver", QP_SOLVERS)
def test_every_backend_solves_or_refuses_every_solver(
    backend: str, solver: str, problems: list[ControlProblem]
) -> None:
    """Each back-end is refused at construction (definite H needed) or solves with bounds active, never a
    zero command, its own result within its bound tolerance (:func:`check_backend_solutions`)."""
    params = replace(EXACT, qp_backend=backend)
    try:
        under_test = make_solver(solver, params)
    except ParameterError as exc:
        assert isinstance(make_backend(backend), QpsolversBackend) and make_backend(backend).needs_positive_definite
        assert "semi-definite" in str(exc) and "daqp" in str(exc)
        return
    check_backend_solutions(under_test, make_solver(solver, EXACT), problems[:5])


def test_a_solver_ignoring_its_bounds_fails_the_backend_check(bound_ignoring_solver: str,
                                                              problems: list[ControlProblem]) -> None:
    """The check above can fail: test/bound_ignoring.py's solver gives "bounds_violated"."""
    with pytest.raises(AssertionError, match="bounds_violated"):
        check_backend_solutions(make_solver(bound_ignoring_solver), make_solver("sparse_qp", EXACT), problems[:5])


def test_quadprog_refusal_names_the_key_and_the_alternatives() -> None:
    with pytest.raises(ParameterError, match=r"parameter 'qp_backend': got 'quadprog'.*one of daqp, proxsuite"):
        make_solver("sparse_qp", SolverParams(qp_backend="quadprog", proximal_weight=0.0))


def test_closed_forms_equal_the_qps_when_no_bound_is_active(problems: list[ControlProblem]) -> None:
    """Eq (14) and eq (27) without active bounds: the closed forms equal daqp's QP solutions to 1e-9."""
    daqp = make_backend("daqp")
    for p in problems[:10]:
        j, r = p.jacobian, p.reference
        x = damped_least_squares(j, r, 1e-6)
        assert x is not None
        h = j.T @ j + 1e-6 * np.eye(14)
        qp = daqp.solve(QPProblem(H=h, g=-j.T @ r, lb=np.full(14, -10.0), ub=np.full(14, 10.0))).x
        np.testing.assert_allclose(x, qp, atol=1e-9)
        v = np.linspace(-0.3, 0.3, 14)
        y = null_space_projection(j, v)
        assert y is not None
        qp2 = daqp.solve(QPProblem(H=np.eye(14), g=-v, A=j, b=np.zeros(6), lb=np.full(14, -10.0),
                                   ub=np.full(14, 10.0))).x
        np.testing.assert_allclose(y, qp2, atol=1e-9)
        np.testing.assert_allclose(j @ y, 0.0, atol=1e-12)


# ---- the proximal tie-break ------------------------------------------------------------------


def test_proximal_term_is_off_after_a_reset(problems: list[ControlProblem]) -> None:
    """First solve after construction or reset = the exact lasso, whatever proximal_weight."""
    smooth, exact = make_solver("sparse_qp", SolverParams(proximal_weight=1e-4)), make_solver("sparse_qp", EXACT)
    for p in problems[:5]:
        smooth.reset()
        np.testing.assert_allclose(smooth.solve(p).velocities, exact.solve(p).velocities, atol=1e-12)


def test_proximal_excess_is_bounded(problems: list[ControlProblem]) -> None:
    """f(qd_mu) - f* <= mu/2 ||z* - z_prev||^2 (z_prev from another problem), and repeating converges to f*."""
    mu = 1e-6
    smooth, exact = make_solver("sparse_qp", SolverParams(proximal_weight=mu)), make_solver("sparse_qp", EXACT)
    for a, b in itertools.pairwise(problems[:7]):
        smooth.reset()
        prev = smooth.solve(a).velocities
        z_prev = np.concatenate((np.maximum(prev, 0), np.maximum(-prev, 0)))
        exact.reset()
        best = exact.solve(b).velocities
        z_best = np.concatenate((np.maximum(best, 0), np.maximum(-best, 0)))
        f_star = lasso_objective(b, best, LAMBDA)
        qd = smooth.solve(b).velocities
        bound = 0.5 * mu * float(np.sum((z_best - z_prev) ** 2))
        assert f_star * (1 - 1e-9) <= lasso_objective(b, qd, LAMBDA) <= f_star + bound + 1e-15
        for _ in range(200):  # proximal-point iterations on a fixed problem
            qd = smooth.solve(b).velocities
        assert lasso_objective(b, qd, LAMBDA) <= f_star * (1 + 1e-6)


def test_proximal_term_makes_h_definite_only_with_a_previous_solution() -> None:
    """The sparse QPs always refuse quadprog: the first cycle (no previous solution) is the semi-definite lasso."""
    with pytest.raises(ParameterError):
        make_solver("hierarchical_sparse_qp", SolverParams(qp_backend="quadprog", proximal_weight=1e-3))


def test_active_sets_helper() -> None:
    p = ControlProblem(np.eye(6, 3), np.zeros(6), np.array([-1.0, -1.0, -1.0]), np.array([1.0, 1.0, 1.0]), np.zeros(3))
    nonzero, at_bound = active_sets(p, np.array([0.0, 0.5, 1.0]), 1e-7)
    assert nonzero == {1, 2} and at_bound == {2}


# ---- the lasso through its dual (eq 17 without bounds) ------------------------------------------


def _box_qp_only(params: SolverParams = EXACT) -> Any:
    """A sparse_qp that always solves eq (19)'s box QP (its dual path switched off)."""
    solver = make_solver("sparse_qp", params)
    solver._dual = None  # type: ignore[attr-defined]
    return solver


@pytest.mark.parametrize("backend", ["daqp", "proxsuite"])
def test_qp_multipliers_satisfy_the_kkt_conditions(backend: str) -> None:
    """QPSolution.multipliers of the C rows: H x + g + C^T z + (box multipliers) = 0, z > 0 only at u, < 0 only at l."""
    rng = np.random.default_rng(11)
    for _ in range(10):
        m = rng.normal(size=(6, 6))
        h, g = m @ m.T + np.eye(6), rng.normal(size=6) * 5
        c = rng.normal(size=(14, 6))
        lb, ub = np.full(6, -0.3), np.full(6, 0.3)
        sol = make_backend(backend).solve(QPProblem(H=h, g=g, C=c, l=-np.ones(14), u=np.ones(14), lb=lb, ub=ub))
        assert sol.ok and sol.multipliers is not None and sol.x is not None
        x, z = sol.x, sol.multipliers
        rows = c @ x
        assert np.all((z <= 1e-9) | (np.abs(rows - 1.0) < 1e-7)) and np.all((z >= -1e-9) | (np.abs(rows + 1.0) < 1e-7))
        stationarity = h @ x + g + c.T @ z  # = -(box multipliers): zero where x is strictly inside the box
        free = (x > lb + 1e-7) & (x < ub - 1e-7)
        np.testing.assert_allclose(stationarity[free], 0.0, atol=1e-6)


def test_dual_equals_the_box_qp_of_eq19(problems: list[ControlProblem]) -> None:
    """LassoDual (daqp multipliers) = eq (19)'s box QP (daqp): objective within 1e-9 relative, same support, <= 6 joints."""
    dual, box = make_solver("sparse_qp", EXACT), _box_qp_only()
    inside_bounds = 0
    for p in problems:
        dual.reset()
        box.reset()
        qd_dual = dual._dual.solve(p.jacobian, p.reference, LAMBDA)[0]  # type: ignore[attr-defined]
        assert qd_dual is not None
        if not (np.all(qd_dual >= p.lower) and np.all(qd_dual <= p.upper)):
            continue
        inside_bounds += 1
        qd_box = box.solve(p).velocities
        f_dual, f_box = lasso_objective(p, qd_dual, LAMBDA), lasso_objective(p, qd_box, LAMBDA)
        assert abs(f_dual - f_box) <= 1e-9 * f_box
        assert active_sets(p, qd_dual, 1e-7) == active_sets(p, qd_box, 1e-7)
        assert np.count_nonzero(np.abs(qd_dual) > 1e-9) <= 6
        np.testing.assert_allclose(dual.solve(p).velocities, qd_dual, atol=0.0)  # the solver uses it as is
    assert inside_bounds >= 50


def test_a_dual_solution_outside_the_bounds_falls_back_to_the_box_qp(problems: list[ControlProblem]) -> None:
    """Bounds that cut the unbounded lasso: sparse_qp returns eq (19)'s box-QP optimum, its own result
    within its bound tolerance of the bounds."""
    solver, box = make_solver("sparse_qp", EXACT), _box_qp_only()
    for p in map(tight, problems[:10]):
        solver.reset()
        qd_dual = solver._dual.solve(p.jacobian, p.reference, LAMBDA)[0]  # type: ignore[attr-defined]
        assert qd_dual is not None and (np.any(qd_dual < p.lower) or np.any(qd_dual > p.upper))
        solver.reset()
        box.reset()
        res, ref = solver.solve(p), box.solve(p)
        assert res.status == "solved" and res.bound_excess <= solver.bound_tolerance
        np.testing.assert_allclose(res.velocities, ref.velocities, atol=1e-12)


def test_dual_path_is_skipped_by_tolerance_based_backends() -> None:
    """Only an active-set back-end that reports multipliers (daqp) gets the dual path; proxsuite keeps eq (19)."""
    assert make_solver("sparse_qp", EXACT)._dual is not None  # type: ignore[attr-defined]
    assert make_solver("sparse_qp", replace(EXACT, qp_backend="proxsuite"))._dual is None  # type: ignore[attr-defined]
