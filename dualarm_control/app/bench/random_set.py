"""Benchmark problems that need no simulator: random configurations, exactness, scaling.

The random set: seeded joint configurations drawn uniformly inside the position limits
(a margin of 2 % of each range, so the repulsive band of eq (24), alpha = 0.1, is entered
by some joints), each with a relative target near the current relative pose (1 cm and
0.03 rad standard deviation per axis, zero twist). Every configuration inside the limits
is reachable by construction.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import pinocchio as pin

from dualarm_control.controller import ControllerParams, RelativeController
from dualarm_control.kinematics import DualArmModel, FloatArray, pose_error
from dualarm_control.limits import JointLimits, repulsive_velocity, velocity_bounds
from dualarm_control.metrics import percentiles
from dualarm_control.qp import QPSettings
from dualarm_control.solvers import ControlProblem, make_solver
from dualarm_control.status import Status

MARGIN = 0.02
"""Share of each joint range left out at both ends when drawing configurations."""
POSITION_SIGMA = 0.01
"""m: standard deviation of the target's offset per axis."""
ROTATION_SIGMA = 0.03
"""rad: standard deviation of the target's rotation vector per axis."""


@dataclass(frozen=True)
class PoseTarget:
    """A fixed relative target (zero twist) in F1: satisfies controller.RelativeTarget."""

    position: FloatArray
    rotation: FloatArray
    linear_velocity: FloatArray
    angular_velocity: FloatArray


@dataclass(frozen=True)
class Case:
    """One random problem: joint positions q [rad] (n,) and a relative target."""

    q: FloatArray
    target: PoseTarget


def random_cases(model: DualArmModel, count: int, seed: int) -> list[Case]:
    """``count`` seeded random configurations with targets near their relative pose."""
    rng = np.random.default_rng(seed)
    span = model.q_max - model.q_min
    cases = []
    for _ in range(count):
        q = model.q_min + span * rng.uniform(MARGIN, 1.0 - MARGIN, model.nq)
        p, r = model.relative_pose(q)
        target = PoseTarget(
            position=p + rng.normal(scale=POSITION_SIGMA, size=3),
            rotation=r @ pin.exp3(rng.normal(scale=ROTATION_SIGMA, size=3)),
            linear_velocity=np.zeros(3),
            angular_velocity=np.zeros(3),
        )
        cases.append(Case(q=q, target=target))
    return cases


def control_problem(model: DualArmModel, controller: RelativeController, case: Case) -> ControlProblem:
    """The ControlProblem the controller builds for ``case`` (eq 13, 23, 25), without solving it."""
    state = model.relative_state(case.q)
    error = pose_error(state.position, state.rotation, case.target.position, case.target.rotation)
    lower, upper = velocity_bounds(case.q, controller.limits, controller.params.period)
    repulsive = repulsive_velocity(case.q, controller.limits, controller.params.alpha)
    return ControlProblem(state.jacobian, controller.params.gain * error, lower, upper, repulsive)


def with_backend(params: ControllerParams, solver: str, backend: str) -> ControllerParams:
    """``params`` with another solver and QP back-end."""
    return replace(params, solver=solver, solver_params=replace(params.solver_params, qp_backend=backend))


def time_random_set(
    model: DualArmModel,
    cases: Sequence[Case],
    configs: dict[str, ControllerParams],
    extra: dict[str, Callable[[Case], None]] | None = None,
    repeats: int = 1,
    reset: bool = True,
) -> dict[str, dict[str, Any]]:
    """Cycle and solve times of ``RelativeController.step`` per configuration on ``cases``.

    Configurations are interleaved case by case (every configuration sees the same machine
    load), in a seeded random order per case (with a fixed order, the configuration that
    always ran right after pseudo_inverse's SVD measured 30 % slower than the same
    computation elsewhere), and each controller is reset before each case: the cases are independent, so
    no warm start or proximal tie-break carries over from an unrelated problem. ``extra``
    adds other timed callables (e.g. pink) to the same interleaving. ``reset`` False keeps each
    controller's memory from case to case (a run's consecutive states replayed: warm starts and the
    proximal tie-break on, as in the run).

    Each call is also timed in the thread's CPU time (``time.thread_time_ns``): a cycle preempted by another
    process counts only what it ran, so ``cpu_p50_ms``/``cpu_p99_ms`` hold on a loaded machine where the wall
    clock's percentiles hold the preemptions.

    Returns:
        {name: {cycle_p50_ms, cycle_p99_ms, cpu_p50_ms, cpu_p99_ms, solve_p50_ms, solve_p99_ms, active_joints_p50,
        active_joints_max, share_at_most_6_active, failures, max_bound_excess}}; max_bound_excess
        [rad/s] is the largest ``SolverResult.bound_excess`` of a result commanded as the solver
        returned it ("solved", "scaled"), to set beside the solver's ``bound_tolerance``.
    """
    controllers = {name: RelativeController(model, p) for name, p in configs.items()}
    cycle: dict[str, list[float]] = {name: [] for name in [*controllers, *(extra or {})]}
    cpu: dict[str, list[int]] = {name: [] for name in cycle}
    cpu_clock = time.thread_time_ns
    solve: dict[str, list[float]] = {name: [] for name in controllers}
    active: dict[str, list[int]] = {name: [] for name in controllers}
    failures = dict.fromkeys(controllers, 0)
    excess = dict.fromkeys(controllers, 0.0)
    names = list(cycle)
    shuffle = np.random.default_rng(0)
    for _ in range(repeats):
        for case in cases:
            for index in shuffle.permutation(len(names)):  # a new order per case: no neighbour is favoured
                name = names[int(index)]
                if name in controllers:
                    ctrl = controllers[name]
                    if reset:
                        ctrl.reset()
                    begin = cpu_clock()
                    out = ctrl.step(case.q, case.target)
                    cpu[name].append(cpu_clock() - begin)
                    cycle[name].append(out.cycle_time)
                    solve[name].append(out.result.solve_time)
                    active[name].append(out.result.active_joints)
                    failures[name] += int(out.result.failed)
                    if out.result.status in (Status.SOLVED, Status.SCALED):
                        excess[name] = max(excess[name], out.result.bound_excess)
                else:
                    begin, start = cpu_clock(), time.perf_counter()
                    (extra or {})[name](case)
                    cycle[name].append(time.perf_counter() - start)
                    cpu[name].append(cpu_clock() - begin)
    rows: dict[str, dict[str, Any]] = {}
    for name, samples in cycle.items():
        c50, c99 = percentiles(np.asarray(samples))
        u50, u99 = percentiles(np.asarray(cpu[name], dtype=float) * 1e-9)
        row: dict[str, Any] = {"samples": len(samples), "cycle_p50_ms": c50 * 1e3, "cycle_p99_ms": c99 * 1e3,
                               "cpu_p50_ms": u50 * 1e3, "cpu_p99_ms": u99 * 1e3}
        if name in controllers:
            s50, s99 = percentiles(np.asarray(solve[name]))
            counts = np.asarray(active[name])
            row.update(solve_p50_ms=s50 * 1e3, solve_p99_ms=s99 * 1e3,
                       active_joints_p50=float(np.median(counts)), active_joints_max=int(counts.max()),
                       share_at_most_6_active=float(np.mean(counts <= 6)), failures=failures[name],
                       max_bound_excess=excess[name])
        rows[name] = row
    return rows


def lasso_objective(problem: ControlProblem, qd: FloatArray, l1_weight: float) -> float:
    """Eq (17): 1/2 ||J qd - r||^2 + lambda ||qd||_1."""
    d = problem.jacobian @ qd - problem.reference
    return float(0.5 * d @ d + l1_weight * np.abs(qd).sum())


def active_sets(problem: ControlProblem, qd: FloatArray, tol: float) -> tuple[frozenset[int], frozenset[int]]:
    """(joints with |qd_i| > tol, joints within tol of a bound of eq 23)."""
    nonzero = frozenset(int(i) for i in np.flatnonzero(np.abs(qd) > tol))
    at_bound = np.flatnonzero((qd - problem.lower < tol) | (problem.upper - qd < tol))
    return nonzero, frozenset(int(i) for i in at_bound)


def lasso_on_active_set(problem: ControlProblem, guess: FloatArray, l1_weight: float,
                        tol: float = 1e-7) -> FloatArray | None:
    """Exact solution of eq (19) on the active set of ``guess``, or None when it is not optimal.

    With z = [qd+; qd-] and B = J [I, -I]: the entries of z within ``tol`` of a bound of
    :func:`lasso_box` are fixed there; the free ones solve the stationarity equations
    B_F^T (B z - r) + lambda = 0 exactly (B_F must have full column rank, as at a basic
    solution with at most 6 free entries). The point is returned only if it is an optimum:
    inside the box, and the gradient B^T (B z - r) + lambda is >= 0 at lower bounds and
    <= 0 at upper bounds (KKT, to 1e-12 = 1e-6 lambda). It thus gives an exact reference from
    an approximate solution of any other solver.

    Args:
        problem: the cycle's problem (J (6, n), r, bounds).
        guess: approximate lasso solution qd [rad/s], (n,).
        l1_weight: lambda.
        tol: distance to a bound below which an entry of z counts as at the bound [rad/s].

    Returns:
        qd [rad/s], (n,), or None.
    """
    from dualarm_control.solvers.methods import lasso_box

    n = guess.shape[0]
    b = np.hstack((problem.jacobian, -problem.jacobian))
    lb, ub = lasso_box(problem.lower, problem.upper)
    z = np.concatenate((np.maximum(guess, 0.0), np.maximum(-guess, 0.0)))
    at_lb = z - lb <= tol
    at_ub = (ub - z <= tol) & ~at_lb
    free = ~(at_lb | at_ub)
    z = np.where(at_ub, ub, lb)
    b_free = b[:, free]
    if np.linalg.matrix_rank(b_free) < int(free.sum()):
        return None
    rhs = b_free.T @ (problem.reference - b[:, ~free] @ z[~free]) - l1_weight
    z[free] = np.linalg.solve(b_free.T @ b_free, rhs) if free.any() else z[free]
    grad = b.T @ (b @ z - problem.reference) + l1_weight
    kkt = 1e-6 * l1_weight
    inside = bool(np.all(z >= lb - 1e-12) and np.all(z <= ub + 1e-12))
    if not (inside and np.all(grad[at_lb] >= -kkt) and np.all(grad[at_ub] <= kkt)):
        return None
    return z[:n] - z[n:]


def exactness(
    model: DualArmModel, cases: Sequence[Case], params: ControllerParams, reference_backend: str = "proxsuite",
    reference_eps: float = 1e-12, set_tol: float = 1e-7,
) -> dict[str, Any]:
    """Lasso (eq 17) objective and active set of ``params``' sparse_qp vs an exact reference.

    The solver under test is reset before each case (exact lasso, no proximal term). The
    reference: the same box QP solved by ``reference_backend`` at ``reference_eps``, then
    made exact on its own active set and verified (:func:`lasso_on_active_set`); the raw
    reference solve is compared too. Active set = (non-zero joints, joints at a bound) at
    ``set_tol``.
    """
    test_params = replace(params.solver_params, proximal_weight=0.0)
    ref_params = replace(test_params, qp_backend=reference_backend,
                         qp=QPSettings(eps_abs=reference_eps, max_iter=1_000_000))
    solver, reference = make_solver("sparse_qp", test_params), make_solver("sparse_qp", ref_params)
    controller = RelativeController(model, params)
    lam = test_params.l1_weight
    rel, raw, same, verified = [], [], 0, 0
    for case in cases:
        problem = control_problem(model, controller, case)
        solver.reset()
        reference.reset()
        qd, qd_raw = solver.solve(problem).velocities, reference.solve(problem).velocities
        f, f_raw = lasso_objective(problem, qd, lam), lasso_objective(problem, qd_raw, lam)
        raw.append((f - f_raw) / f_raw)
        qd_ref = lasso_on_active_set(problem, qd_raw, lam)
        if qd_ref is None:
            continue
        verified += 1
        f_ref = lasso_objective(problem, qd_ref, lam)
        rel.append((f - f_ref) / f_ref)
        same += int(active_sets(problem, qd, set_tol) == active_sets(problem, qd_ref, set_tol))
    arr, raw_arr = np.asarray(rel), np.asarray(raw)
    return {
        "cases": len(cases),
        "reference": f"{reference_backend} eps_abs {reference_eps:g}, made exact on its active set",
        "verified_references": verified,
        "objective_rel_diff_min": float(np.min(arr)),
        "objective_rel_diff_max": float(np.max(arr)),
        "objective_abs_rel_diff_max": float(np.max(np.abs(arr))),
        "same_active_set": same,
        "raw_reference_rel_diff_min": float(np.min(raw_arr)),
        "raw_reference_rel_diff_max": float(np.max(raw_arr)),
    }


def chain_problem(model: DualArmModel, arms: int, rng: np.random.Generator, limits: JointLimits,
                  params: ControllerParams) -> ControlProblem:
    """A relative-task problem for a chain of ``arms`` LWR4 arms (7 joints each).

    Tasks between neighbours i, i+1 (arms - 1 of them, 6 rows each). Block (i, arm i) and
    (i, arm i+1) are the left and right halves of the dual-arm relative Jacobian at a random
    configuration of the same LWR4 model, so every block has the real kinematic structure;
    the configurations of one arm in its two tasks are drawn independently (a synthetic
    chain for timing, not a physical cell). Bounds and repulsive velocity per arm from the
    model's limits at that configuration, reference = K e with a random target offset.
    """
    n = 7 * arms
    jac = np.zeros((6 * (arms - 1), n))
    ref = np.zeros(6 * (arms - 1))
    lower, upper, repulsive = np.zeros(n), np.zeros(n), np.zeros(n)
    for task in range(arms - 1):
        case = random_cases(model, 1, int(rng.integers(1 << 31)))[0]
        problem = control_problem(model, RelativeController(model, params), case)
        rows, cols = slice(6 * task, 6 * task + 6), slice(7 * task, 7 * task + 14)
        jac[rows, cols] = problem.jacobian
        ref[rows] = problem.reference
        lower[cols], upper[cols], repulsive[cols] = problem.lower, problem.upper, problem.repulsive
    return ControlProblem(jac, ref, lower, upper, repulsive)


def time_scaling(model: DualArmModel, params: ControllerParams, solvers: Sequence[str], backends: Sequence[str],
                 arms: Sequence[int], count: int, seed: int) -> dict[str, dict[str, Any]]:
    """Solve time p50/p99 [ms] per (arms, solver, back-end) on ``count`` chain problems, interleaved in random order."""
    limits = JointLimits(model.q_min, model.q_max, model.qd_max)
    rng = np.random.default_rng(seed)
    rows: dict[str, dict[str, Any]] = {}
    for k in arms:
        problems = [chain_problem(model, k, rng, limits, params) for _ in range(count)]
        solver_objs = {}
        for s in solvers:
            for b in backends:
                try:
                    solver_objs[(s, b)] = make_solver(s, replace(params.solver_params, qp_backend=b))
                except ValueError:
                    continue  # refused back-end (definite H needed): listed in the per-solver table
        times: dict[tuple[str, str], list[float]] = {key: [] for key in solver_objs}
        active: dict[tuple[str, str], list[int]] = {key: [] for key in solver_objs}
        keys = list(solver_objs)
        shuffle = np.random.default_rng(seed)
        for problem in problems:
            for index in shuffle.permutation(len(keys)):  # a new order per problem, as in time_random_set
                key = keys[int(index)]
                solver = solver_objs[key]
                solver.reset()
                res = solver.solve(problem)
                times[key].append(res.solve_time)
                active[key].append(res.active_joints)
        for (s, b), samples in times.items():
            p50, p99 = percentiles(np.asarray(samples))
            rows[f"{k} arms ({7 * k} joints, {6 * (k - 1)} rows) | {s} | {b}"] = {
                "arms": k, "joints": 7 * k, "rows": 6 * (k - 1), "solver": s, "backend": b,
                "solve_p50_ms": p50 * 1e3, "solve_p99_ms": p99 * 1e3,
                "active_joints_p50": float(np.median(active[(s, b)])),
            }
    return rows

