"""The limits' hard rows ``A qd <= b`` (the collision limit) in every solver (issue 27, docs/collision.md).

Each solver's own result (``raw_velocities``, beneath the clip and the failure policy) must meet the
rows; the standard QP with rows is checked against quadprog (an independent dual active-set
solver, through qpsolvers) on the same QP, the lasso against quadprog on its split form, and
rows a solver cannot meet go to the separating step, never to a command that breaks them where
the box allows meeting them.
"""

from __future__ import annotations

import numpy as np
import pytest
import qpsolvers

from dualarm_control.limits import DeferredRows
from dualarm_control.solvers import (
    ControlProblem,
    SolverParams,
    make_solver,
    solver_names,
)
from dualarm_control.solvers.policy import separating_step
from dualarm_control.status import Status

N = 14
SOLVERS = solver_names()


def problem_with_rows(seed: int, rows: int = 3, bound: float = 0.0) -> ControlProblem:
    """Random J and reference, a box containing 0, and ``rows`` rows that the unconstrained
    least-squares step breaks by construction: a_i = -(its normalised direction) rotated a little,
    b_i = ``bound`` (0: no approach at all along a_i; > 0: some; < 0: must move apart)."""
    rng = np.random.default_rng(seed)
    j = rng.standard_normal((6, N))
    r = rng.standard_normal(6)
    free = np.linalg.pinv(j) @ r
    a = np.array([free / np.linalg.norm(free) + 0.3 * rng.standard_normal(N) for _ in range(rows)])
    a /= np.linalg.norm(a, axis=1)[:, None]
    lower, upper = -rng.uniform(1.0, 3.0, N), rng.uniform(1.0, 3.0, N)
    return ControlProblem(j, r, lower, upper, 0.1 * rng.standard_normal(N), limit_rows=a,
                          limit_bound=np.full(rows, bound), limit_labels=tuple(f"pair {i}" for i in range(rows)))


@pytest.mark.parametrize("name", SOLVERS)
@pytest.mark.parametrize("seed", range(6))
def test_every_solver_meets_the_rows_itself(name: str, seed: int) -> None:
    problem = problem_with_rows(seed, bound=0.05)
    assert problem.limit_excess(np.linalg.pinv(problem.jacobian) @ problem.reference) > 0.01  # the rows matter
    result = make_solver(name).solve(problem)
    assert result.status in ("solved", "scaled"), (result.status, result.detail)
    assert result.raw_velocities is not None
    assert problem.limit_excess(result.raw_velocities) <= 1e-7, result.detail
    assert problem.limit_excess(result.velocities) <= 1e-7
    assert np.all(result.velocities >= problem.lower) and np.all(result.velocities <= problem.upper)


@pytest.mark.parametrize("seed", range(6))
def test_standard_qp_with_rows_equals_quadprog(seed: int) -> None:
    problem = problem_with_rows(seed, bound=0.05)
    eps = 1e-3  # a well-conditioned H: the minimiser is unique to well below the tolerance
    params = SolverParams(regularization=eps)
    ours = make_solver("standard_qp", params).solve(problem).velocities
    j = problem.jacobian
    ref = qpsolvers.solve_qp(j.T @ j + eps * np.eye(N), -j.T @ problem.reference, G=problem.limit_rows,
                             h=problem.limit_bound, lb=problem.lower, ub=problem.upper, solver="quadprog")
    assert ref is not None
    np.testing.assert_allclose(ours, ref, atol=1e-6)


@pytest.mark.parametrize("seed", range(4))
def test_sparse_qp_with_rows_equals_quadprog_on_the_split(seed: int) -> None:
    """Eq (19) with the rows written on z = [qd+; qd-] as [A, -A] z <= b, against quadprog on the
    same split with a small proximal-free definite term (quadprog needs H > 0)."""
    problem = problem_with_rows(seed, bound=0.05)
    lam, mu = 1e-3, 1e-4
    ours = make_solver("sparse_qp", SolverParams(l1_weight=lam, proximal_weight=0.0)).solve(problem)
    b = np.hstack((problem.jacobian, -problem.jacobian))
    lb = np.concatenate((np.maximum(problem.lower, 0), np.maximum(-problem.upper, 0)))
    ub = np.concatenate((np.maximum(problem.upper, 0), np.maximum(-problem.lower, 0)))
    g_rows = np.hstack((problem.limit_rows, -problem.limit_rows))
    z = qpsolvers.solve_qp(b.T @ b + mu * np.eye(2 * N), lam - b.T @ problem.reference, G=g_rows,
                           h=problem.limit_bound, lb=lb, ub=ub, solver="quadprog")
    assert z is not None
    reference = z[:N] - z[N:]
    # both meet the rows; the objectives agree (the lasso's minimiser need not be unique)
    assert problem.limit_excess(ours.velocities) <= 1e-7
    def objective(qd: np.ndarray) -> float:
        return 0.5 * float(np.sum((problem.jacobian @ qd - problem.reference) ** 2)) + lam * float(np.abs(qd).sum())
    assert objective(ours.velocities) <= objective(reference) + 1e-6


@pytest.mark.parametrize("name", SOLVERS)
def test_a_pair_inside_the_safety_distance_is_pushed_apart(name: str) -> None:
    """b < 0: A qd <= b < 0 asks for motion apart; every command meets it (the pseudo-inverse
    through the separating step, reported)."""
    problem = problem_with_rows(11, rows=1, bound=-0.02)
    result = make_solver(name).solve(problem)
    assert problem.limit_excess(result.velocities) <= 1e-7, (result.status, result.detail)
    if name == "pseudo_inverse":
        assert result.status == "fallback" and "separating step" in result.detail and "pair 0" in result.detail
    else:
        assert result.status == "solved", result.detail


def test_rows_that_the_box_forbids_are_relaxed_by_the_least_slack() -> None:
    """The box pins every joint but one at 0; the row asks for 0.5 m/s apart along that joint,
    which may move only 0.1 rad/s: the separating step moves it at its bound (as far apart as the
    box lets it), reports the slack, never leaves the box."""
    problem = problem_with_rows(3, rows=1, bound=-0.5)
    problem.lower, problem.upper = np.zeros(N), np.zeros(N)
    problem.upper[4] = 0.1
    problem.limit_rows = np.zeros((1, N))
    problem.limit_rows[0, 4] = -1.0  # A qd <= b: -qd_4 <= -0.5
    for name in SOLVERS:
        result = make_solver(name).solve(problem)
        assert result.status == "fallback", (name, result.status, result.detail)
        assert "relaxed by up to 0.4" in result.detail, result.detail
        np.testing.assert_allclose(result.velocities[4], 0.1, atol=1e-9)
        assert np.all(result.velocities >= problem.lower) and np.all(result.velocities <= problem.upper)


@pytest.mark.parametrize(("status", "least_squares_tried"), [(Status.INFEASIBLE, False), (Status.MAX_ITER, True),
                                                             (Status.FAILED, True)])
def test_an_infeasible_qp_with_rows_goes_to_the_separating_step_at_once(monkeypatch: pytest.MonkeyPatch,
                                                                       status: Status, least_squares_tried: bool) -> None:
    """Infeasible with rows: the box meets no point of them, so the bounded least-squares step (inside the box) is not
    computed; the command is the separating step's. Another failure still tries the least-squares step first."""
    from dualarm_control.solvers import policy

    problem = problem_with_rows(3, rows=1, bound=-0.5)
    problem.lower, problem.upper = np.zeros(N), np.zeros(N)
    problem.upper[4] = 0.1
    problem.limit_rows = np.zeros((1, N))
    problem.limit_rows[0, 4] = -1.0  # -qd_4 <= -0.5 with qd_4 <= 0.1: the box meets no point of the row
    calls = []
    least_squares = policy.bounded_least_squares
    monkeypatch.setattr(policy, "bounded_least_squares", lambda *a: calls.append(1) or least_squares(*a))
    velocities, final, detail = policy.fallback(problem, None, status, "test")
    assert bool(calls) == least_squares_tried
    separated = separating_step(problem)
    assert separated is not None
    np.testing.assert_array_equal(velocities, separated[0])
    assert final == Status.FALLBACK and "separating step used" in detail


def test_separating_step_without_conflict_is_the_constrained_least_squares() -> None:
    problem = problem_with_rows(5, bound=0.05)
    separated = separating_step(problem)
    assert separated is not None
    qd, slack = separated
    assert slack <= 1e-9 and problem.limit_excess(qd) <= 1e-7


@pytest.mark.parametrize("name", SOLVERS)
def test_no_rows_and_empty_rows_give_the_same_command(name: str) -> None:
    """A problem with a (0, n) row block is solved exactly as one without rows (bit for bit)."""
    base = problem_with_rows(2)
    plain = ControlProblem(base.jacobian, base.reference, base.lower, base.upper, base.repulsive)
    empty = ControlProblem(base.jacobian, base.reference, base.lower, base.upper, base.repulsive,
                           limit_rows=np.zeros((0, N)), limit_bound=np.zeros(0))
    a, b = make_solver(name).solve(plain), make_solver(name).solve(empty)
    assert np.array_equal(a.velocities, b.velocities) and a.status == b.status


def test_bad_rows_are_invalid_input() -> None:
    problem = problem_with_rows(1)
    assert problem.limit_bound is not None
    problem.limit_bound[0] = np.nan
    result = make_solver("sparse_qp").solve(problem)
    assert result.status == "invalid_input" and "limit rows" in result.detail
    problem = problem_with_rows(1)
    problem.limit_bound = np.zeros(5)
    assert "limit_rows" in make_solver("standard_qp").solve(problem).detail


@pytest.mark.parametrize("name", SOLVERS)
@pytest.mark.parametrize(("seed", "bound"), [(0, 0.05), (1, 0.05), (2, 0.0), (3, 100.0), (4, -0.01)])
def test_deferred_rows_give_what_the_rows_give(name: str, seed: int, bound: float) -> None:
    """The rows given as :class:`DeferredRows` (C = |A|, a valid speed bound) give every solver's
    result, status and detail bit for bit as the rows given at once; rows far from binding (b = 100 m/s)
    are never built, rows that bind are."""
    eager = problem_with_rows(seed, bound=bound)
    assert eager.limit_rows is not None and eager.limit_bound is not None
    built = []

    def build() -> np.ndarray:
        built.append(True)
        assert eager.limit_rows is not None
        return eager.limit_rows

    deferred = ControlProblem(eager.jacobian, eager.reference, eager.lower, eager.upper, eager.repulsive,
                              limit_bound=eager.limit_bound, limit_labels=eager.limit_labels,
                              limit_deferred=DeferredRows(np.abs(eager.limit_rows), eager.limit_bound, build))
    want, got = make_solver(name).solve(eager), make_solver(name).solve(deferred)
    assert (got.status, got.detail) == (want.status, want.detail)
    assert np.array_equal(got.velocities, want.velocities)
    if bound == 100.0 and name != "pseudo_inverse":  # the pseudo-inverse shrinks along the rows: it reads them
        assert not built
    if bound <= 0.0:
        assert built


def test_deferred_rows_build_once_and_stack() -> None:
    a, b = np.array([[1.0, -2.0]]), np.array([[0.5, 0.5], [-1.0, 0.0]])
    calls = []
    first = DeferredRows(np.abs(a), np.array([1.0]), lambda: calls.append(1) or a)
    both = first.stacked(DeferredRows.of(b, np.array([2.0, 3.0])))
    assert np.array_equal(both.bound, [1.0, 2.0, 3.0]) and np.array_equal(both.speed, np.abs(np.vstack((a, b))))
    assert both.meets(np.array([0.1, 0.1]))  # 0.3 <= 1, 0.1 <= 2, 0.1 <= 3
    assert not both.meets(np.array([1.0, 0.0])) and not calls  # the bound says nothing: nothing built yet
    assert np.array_equal(both.matrix, np.vstack((a, b))) and np.array_equal(both.matrix, np.vstack((a, b)))
    assert calls == [1]


def test_meets_remembers_only_the_velocity_it_vouched_for() -> None:
    """``meets`` keeps the last qd that met the bound (a cycle checks the same command up to three
    times): the same values give True again, any other qd is checked anew, so a velocity that
    breaks the bound after one that met it is never vouched for."""
    rows = DeferredRows(np.array([[1.0, 2.0]]), np.array([1.0]), lambda: np.zeros((1, 2)))
    ok, bad, sign = np.array([0.1, 0.2]), np.array([0.5, 0.5]), np.array([-0.1, -0.2])
    assert [rows.meets(v) for v in (ok, bad, ok.copy(), bad, sign, bad)] == [True, False, True, False, True, False]
    worse = ok.copy()
    assert rows.meets(worse)
    worse[1] = 0.9  # the same array, changed in place: checked again
    assert not rows.meets(worse)


def test_stacked_rows_build_only_the_parts_their_speed_bound_does_not_vouch_for() -> None:
    """Two limits' rows stacked (the collision limit's and the live obstacles'): the excess at a qd that the
    first part's speed bound vouches for builds the second part only, and equals max(A qd - b, 0) of the
    whole stacked matrix; a qd both vouch for builds nothing."""
    rng = np.random.default_rng(3)
    a1, a2 = rng.standard_normal((2, N)), rng.standard_normal((3, N))
    built: list[str] = []

    def part(name: str, a: np.ndarray, bound: np.ndarray) -> DeferredRows:
        return DeferredRows(np.abs(a), bound, lambda: built.append(name) or a)

    qd = 0.01 * rng.standard_normal(N)
    far = np.full(2, 10.0)  # C |qd| far below: vouched for
    near = a2 @ qd - np.array([0.01, -0.02, 0.0])  # its first row broken by 0.01 m/s
    stacked = part("first", a1, far).stacked(part("second", a2, near))
    assert stacked.excess(qd) == pytest.approx(0.01, abs=1e-15)
    assert built == ["second"]
    whole = np.vstack((a1, a2))
    assert np.array_equal(stacked.matrix, whole) and built == ["second", "first"]
    assert stacked.excess(qd) == pytest.approx(float((whole @ qd - stacked.bound).max()), abs=1e-15)
    quiet = part("first", a1, far).stacked(part("second", a2, np.full(3, 10.0)))
    built.clear()
    assert quiet.excess(qd) == 0.0 and built == []
