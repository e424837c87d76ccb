"""Property tests (issue 11): every registered solver's command is finite and inside eq (21)-(23), always.

Random configurations (inside, at and beyond the joint limits), random targets (unreachable,
very fast, sometimes NaN), with and without the acceleration bound, through
:meth:`RelativeController.step`; and random problems (singular, rank-deficient Jacobians,
huge references) through each solver's ``solve`` directly. The registry is iterated, with
every QP back-end each solver accepts, so a solver added later is covered without editing
this file.

Two things are checked (issue 20): what the solver itself returned
(``SolverResult.raw_velocities``, before ``Solver.solve`` clips it into the bounds) lies
within the solver's ``bound_tolerance`` of the bounds, and the command sent is inside them.
The clip only absorbs that tolerance: a result beyond it is status "bounds_violated", which
these checks refuse; the last tests show that a solver ignoring its bounds makes them fail.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

from dualarm_control.app.bench.suite import solver_configs
from dualarm_control.controller import ControllerParams, RelativeController
from dualarm_control.kinematics import DualArmModel
from dualarm_control.limits import JointLimits, velocity_bounds
from dualarm_control.qp import available_backends
from dualarm_control.solvers import (
    ControlProblem,
    Solver,
    SolverResult,
    make_solver,
    solver_names,
)
from dualarm_control.solvers.base import LIMIT_ROWS_TOLERANCE_FACTOR
from dualarm_control.solvers.policy import FALLBACK_DAMPING, ROUND_OFF, rest_command
from dualarm_control.status import Status

# no ROS node, no wall-clock verdict: make test runs it at idle CPU priority beside the parallel tests (docs/testing.md)
pytestmark = pytest.mark.background

PERIOD = 0.005
OWN_RESULT = ("solved", "scaled")
"""Statuses whose command is the solver's own result (clipped by at most its bound tolerance)."""
CONFIGS = solver_configs(ControllerParams(period=PERIOD), solver_names(), available_backends())[0]
"""Every registered solver with every QP back-end it accepts, as "solver | back-end"."""
FINITE = {"allow_nan": False, "allow_infinity": False}
PROPERTY = settings(max_examples=100, deadline=None, derandomize=True,
                    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
FIRST_FAILURE = settings(PROPERTY, phases=(Phase.generate,))
"""The same examples, stopping at the first failure (no shrinking): for the checks expected to fail."""


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


def assert_inside_eq21_23(qd: np.ndarray, q: np.ndarray, limits: JointLimits, tolerance: float = ROUND_OFF) -> None:
    """Finite; inside the velocity bounds of eq (23) (as :func:`velocity_bounds` extends them beyond a
    limit); |qd| <= qd_max (eq 20); one step keeps q in [q_min, q_max] (eq 21), or, for a joint already
    beyond a limit by d, brings it back by min(d, qd_max T) (the distance to the range never grows);
    each to ``tolerance`` [rad/s]."""
    assert np.all(np.isfinite(qd)), qd
    lower, upper = velocity_bounds(q, limits, PERIOD)
    assert np.all(qd >= lower - tolerance) and np.all(qd <= upper + tolerance), (qd, lower, upper)
    assert np.all(np.abs(qd) <= limits.qd_max + tolerance)
    q_next = q + qd * PERIOD
    beyond = np.maximum(limits.q_min - q, 0.0) + np.maximum(q - limits.q_max, 0.0)
    beyond_next = np.maximum(limits.q_min - q_next, 0.0) + np.maximum(q_next - limits.q_max, 0.0)
    allowed = np.maximum(beyond - limits.qd_max * PERIOD, 0.0)
    assert np.all(beyond_next <= allowed + tolerance * PERIOD + 1e-15), (q, qd)


def assert_solver_kept_eq21_23(result: SolverResult, command: np.ndarray, q: np.ndarray, limits: JointLimits,
                               tolerance: float, allowed: tuple[str, ...] = OWN_RESULT + ("fallback",)) -> None:
    """The solver's own result, before the clip, within ``tolerance`` of eq (21)-(23) (when it is what
    was commanded: "solved", "scaled"), the status one of ``allowed`` (no failure, so no
    "bounds_violated"), and the command itself inside eq (21)-(23) to round-off."""
    assert result.status in allowed, result
    if result.status in OWN_RESULT:
        assert result.raw_velocities is not None and result.bound_excess <= tolerance, result
        assert_inside_eq21_23(result.raw_velocities, q, limits, tolerance)
    assert_inside_eq21_23(command, q, limits)


def controller_property(controller: RelativeController, examples: settings = PROPERTY) -> None:
    """RelativeController.step on random configurations and targets, 1-3 cycles each: every cycle
    passes :func:`assert_solver_kept_eq21_23` (NaN targets: "invalid_input" and its safe command)."""

    @examples
    @given(configurations(controller.model.q_min, controller.model.q_max), targets(), st.integers(1, 3))
    def check(q: np.ndarray, target: Target, cycles: int) -> None:
        controller.reset()
        for _ in range(cycles):  # later cycles use the warm start and the acceleration bound's memory
            out = controller.step(q, target)
            assert_solver_kept_eq21_23(out.result, out.velocities, q, controller.limits,
                                       controller.solver.bound_tolerance * (
                                           LIMIT_ROWS_TOLERANCE_FACTOR if out.collision is not None and out.collision.rows
                                           else 1.0),
                                       OWN_RESULT + ("fallback", "invalid_input"))  # invalid: NaN targets only

    check()


@pytest.mark.parametrize("config", list(CONFIGS))
@pytest.mark.parametrize("acceleration", [(), (10.0,)], ids=["no_acc_bound", "acc_bound"])
def test_controller_command_is_finite_and_inside_eq21_23(config: str, acceleration: tuple[float, ...],
                                                         model: DualArmModel) -> None:
    """RelativeController.step, every solver and back-end: for any configuration and target, the solver's
    own result (before the clip) and the command satisfy eq (21)-(23)."""
    params = replace(CONFIGS[config], acceleration_limit=acceleration)
    controller_property(RelativeController(model, params))


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


def solver_property(solver: Solver, model: DualArmModel, examples: settings = PROPERTY) -> None:
    """Solver.solve on random problems: every result passes :func:`assert_solver_kept_eq21_23` (the
    solver's own result within its bound tolerance, never a failure status, the command inside)."""
    limits = JointLimits(model.q_min, model.q_max, model.qd_max)

    @examples
    @given(problems(model.q_min, model.q_max, model.qd_max))
    def check(case: tuple[ControlProblem, np.ndarray]) -> None:
        problem, q = case
        result = solver.solve(problem)
        assert_solver_kept_eq21_23(result, result.velocities, q, limits, solver.bound_tolerance)

    check()


SEPARATING_CASES = {
    # the arms inside each other at their joint limits, one joint beyond its range (its box a single speed), a
    # target 8 m away at 38 m/s: the standard QP on quadprog fails, the least-squares step breaks the rows, daqp
    # fails on the slack QP (144 iterations), proxsuite solves it (rows relaxed by 3.7 mm/s)
    "daqp fails": ([2.8279790625, -1.832595625, 2.96706, 2.094395, 2.96706, -2.094395, -2.96706, 0.741765, -1.832595625,
                    1.8544125000000005, 2.094395, 0.0, -2.094395, -3.708825],
                   ([-8.0, 0.0, 1.0], [0.0, 38.0, 1.0], [59.0, 5.0, -3.0]), 1, "standard_qp | quadprog", 1),
    # the second cycle, inside the stall brake's box (0.05 rad/s wide) that the first cycle's active rows engaged:
    # daqp fails (154 iterations), proxsuite calls the slack QP infeasible, quadprog solves it
    "daqp and proxsuite fail": ([2.78161875, -1.832595625, 2.96706, 2.094395, 2.96706, -2.094395, -2.96706, -2.96706,
                                 2.094395, -2.96706, 2.094395, 0.0, -2.094395, -2.96706],
                                ([0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [18.0, -10.0, 1.0]), 2, "standard_qp | proxsuite", 2),
    # the last joint beyond its range (its box the single speed 3.21 rad/s back): on the slack QP with that
    # zero-width box daqp fails, proxsuite calls it infeasible, quadprog calls its two opposite bounds
    # inconsistent; with the joint fixed first (policy.fixed_joints) quadprog solves it, rows relaxed by 15 mm/s
    # (daqp and proxsuite still fail)
    "every back-end fails on a zero-width box": (
        [2.78161875, -1.83259562, 2.96706, 2.094395, 2.96706, -2.094395, -2.96706, 1.48353, 0.52359875, -2.96706,
         2.094395, 2.96706, -2.094395, -3.708825],
        ([-8.0, 0.0, 0.0], [0.0, 0.0, 0.0], [39.0, 0.0, 6.0]), 1, "pseudo_inverse | -", 3),
}


@pytest.mark.parametrize("case", list(SEPARATING_CASES))
def test_a_separating_qp_that_daqp_cannot_solve_still_separates(case: str, model: DualArmModel) -> None:
    """Cases the property check found (2026-12-07): the separating step's slack QP defeats daqp (in the second
    proxsuite too, in the third quadprog as well); the command was the one nearest to rest with status "failed" /
    "infeasible". Now the next back-end of the chain takes it (policy.py: SEPARATING_BACKENDS, then
    quadprog_solve), on the QP with its zero-width joints fixed (policy.fixed_joints): status "fallback", the
    separating step, inside the box."""
    from dualarm_control.qp import make_backend
    from dualarm_control.solvers import policy
    from dualarm_control.solvers.slack_qp import slack_qp

    q, (position, linear, angular), cycles, config, failing = SEPARATING_CASES[case]
    target = Target(np.array(position), np.eye(3), np.array(linear), np.array(angular))
    controller = RelativeController(model, replace(CONFIGS[config], acceleration_limit=()))
    problems = []
    solve = controller.solver.solve

    def recorded(problem):  # type: ignore[no-untyped-def]
        problems.append(problem)
        return solve(problem)

    controller.solver.solve = recorded  # type: ignore[method-assign]
    for _ in range(cycles - 1):
        controller.step(np.array(q), target)
    # The case was found with its primary QP failing; whether it does depends on the machine's BLAS build (2026-12-07,
    # numpy 2.4.6's OpenBLAS 0.3.31 on an AMD EPYC: quadprog solved "daqp fails"' standard QP, and the chain under
    # test never ran). The failure policy is what is tested: the primary solve fails here on every machine.
    controller.solver._solve = lambda problem: (None, Status.INFEASIBLE, 0, "primary QP failed (forced)")  # type: ignore[method-assign]
    out = controller.step(np.array(q), target)
    assert out.result.status == "fallback" and "separating step used" in out.result.detail, out.result
    assert_solver_kept_eq21_23(out.result, out.velocities, np.array(q), controller.limits,
                               controller.solver.bound_tolerance)
    problem = problems[-1]
    rows = problem.limit_matrix()
    qp = slack_qp(problem.jacobian, problem.reference, problem.equality_weights, problem.lower, problem.upper,
                  policy.FALLBACK_DAMPING, rows, problem.limit_bound, np.full(rows.shape[0], policy.SEPARATING_WEIGHT))
    # still cases where the first back-ends fail on the whole slack QP (else this test tests nothing)
    chain = [lambda qp, name=name: make_backend(name).solve(qp).x for name in policy.SEPARATING_BACKENDS]
    chain.append(policy.quadprog_solve)
    assert [solve_qp(qp) is None for solve_qp in chain[:failing]] == [True] * failing
    step = policy.separating_step(problem)
    assert step is not None and 0.0 <= step[1] < 0.02, step


@pytest.mark.parametrize("config", list(CONFIGS))
def test_solver_command_is_finite_and_inside_the_bounds(config: str, model: DualArmModel) -> None:
    """Solver.solve on random problems, every solver and back-end: its own result within its bound
    tolerance of [lower, upper] and eq (21), the command inside, never a failure status."""
    solver_property(make_solver(CONFIGS[config].solver, CONFIGS[config].solver_params), model)


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


# ---- the checks above can fail: a solver that ignores its bounds (registered for the test) ------------


def test_a_solver_ignoring_its_bounds_fails_the_property_checks(bound_ignoring_solver: str,
                                                               model: DualArmModel) -> None:
    """test/bound_ignoring.py's solver commands 1.5 x its upper bounds with status "solved": both property
    checks above flag it, through Solver.solve and through RelativeController.step, although every command
    sent is still inside the bounds (the failure policy replaced it)."""
    with pytest.raises(AssertionError, match="bounds_violated"):
        solver_property(make_solver(bound_ignoring_solver), model, FIRST_FAILURE)
    controller = RelativeController(model, ControllerParams(solver=bound_ignoring_solver, period=PERIOD))
    with pytest.raises(AssertionError, match="bounds_violated"):
        controller_property(controller, FIRST_FAILURE)


def test_the_own_result_check_flags_an_overshoot_beyond_the_tolerance(model: DualArmModel) -> None:
    """The check on the solver's own result, without the status check: a "solved" result 10 x the
    tolerance beyond a bound fails it, one within the tolerance passes."""
    solver = make_solver("sparse_qp")
    limits = JointLimits(model.q_min, model.q_max, model.qd_max)
    q = 0.5 * (model.q_min + model.q_max)
    upper = velocity_bounds(q, limits, PERIOD)[1]
    for overshoot, fails in ((10.0, True), (0.5, False)):
        raw = upper.copy()
        raw[3] += overshoot * solver.bound_tolerance
        result = SolverResult(np.minimum(raw, upper), "solved", 0.0, 0, 14, 0.0, "", raw,
                              overshoot * solver.bound_tolerance)
        if fails:
            with pytest.raises(AssertionError):
                assert_solver_kept_eq21_23(result, result.velocities, q, limits, solver.bound_tolerance)
        else:
            assert_solver_kept_eq21_23(result, result.velocities, q, limits, solver.bound_tolerance)


def test_a_bound_violation_in_the_control_cycle_gives_its_status_and_the_fallback(
        bound_ignoring_solver: str, model: DualArmModel, monkeypatch: pytest.MonkeyPatch) -> None:
    """One RelativeController cycle with the bound-ignoring solver: status "bounds_violated" (a failure,
    the excess and the joint in detail) and the failure policy's command: the bounded least-squares step
    that the same cycle gets from a solver whose QP is infeasible."""
    target = Target(np.array([0.3, 0.1, 0.2]), np.eye(3), np.full(3, 0.5), np.zeros(3))
    q = 0.5 * (model.q_min + model.q_max)
    wrong = RelativeController(model, ControllerParams(solver=bound_ignoring_solver, period=PERIOD))
    infeasible = RelativeController(model, ControllerParams(solver="standard_qp", period=PERIOD))
    monkeypatch.setattr(infeasible.solver, "_solve", lambda problem: (None, "infeasible", 0, "QP infeasible"))
    out, reference = wrong.step(q, target), infeasible.step(q, target)
    assert out.result.status == "bounds_violated" and out.result.failed, out.result
    assert out.result.bound_excess > 1e-3 > wrong.solver.bound_tolerance
    assert "beyond its upper bound" in out.result.detail and "bounded least-squares step used" in out.result.detail
    assert reference.result.status == "fallback"
    np.testing.assert_array_equal(out.velocities, reference.velocities)
    assert_inside_eq21_23(out.velocities, q, wrong.limits)
    upper = velocity_bounds(q, wrong.limits, PERIOD)[1]
    np.testing.assert_array_equal(out.result.raw_velocities, 1.5 * upper)  # what the solver returned, kept


def test_a_daqp_result_beyond_the_box_by_its_own_tolerance_is_the_solvers_result(model: DualArmModel) -> None:
    """A case a 6,000-example random run of the property check found (2026-12-07): the LWR4 stretched (q = 0), a
    target 6.6 m away at 20 rad/s, the sparse QP on daqp, second cycle (the proximal term on): daqp's "solved" x
    lay 1.04e-8 beyond the lasso box, 2.1x the solver's bound tolerance but within daqp's own tolerance in x
    (primal_tol sqrt((H^-1)_ii), sqrt((H^-1)_ii) about 950 here), and the cycle was "bounds_violated", the
    bounded least-squares step commanded. Now the back-end moves x onto the box (DaqpBackend.onto_box): "solved",
    both cycles, and the command inside eq (21)-(23)."""
    x = -6.5914579852220925
    target = Target(np.array([x, 0.0, 0.0]), np.array([[1.0, 0.0, 1e-10], [0.0, 1.0, 0.0], [-1e-10, 0.0, 1.0]]),
                    np.array([x, 0.0, 0.0]), np.array([x, 1e-10, -20.081740487149233]))
    controller = RelativeController(model, replace(CONFIGS["sparse_qp | daqp"], acceleration_limit=()))
    q = np.zeros(model.nq)
    for _ in range(2):
        out = controller.step(q, target)
        assert out.result.status == "solved", out.result
        assert_solver_kept_eq21_23(out.result, out.velocities, q, controller.limits, controller.solver.bound_tolerance)
