"""Issue 43: ``hierarchical_sparse_l1_qp``, a hierarchy whose second level stays sparse.

Its second level, min 1/2 sum_Z (qd_i - qd_r,i)^2 + lambda_2 sum_{not Z} |qd_i| s.t. J qd = J qd1, the eq (23)
box, is checked against an independent solve of the same problem in another form (scipy's SLSQP on the
epigraph form, variables (qd, t) with -t <= qd <= t: no split variables, no daqp), on real Jacobians with one
joint in the repulsive zone; and against eq (27)'s second level on the same problems: the task kept, fewer
joints moving.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import minimize

from dualarm_control.kinematics import DualArmModel
from dualarm_control.limits import JointLimits, repulsive_velocity, velocity_bounds
from dualarm_control.solvers import (
    ACTIVITY_THRESHOLD,
    ControlProblem,
    SolverParams,
    make_solver,
)

PERIOD = 0.005
SECONDARY_L1_WEIGHT = SolverParams().secondary_l1_weight


@pytest.fixture(scope="module")
def model() -> DualArmModel:
    return DualArmModel()


def near_limit(model: DualArmModel, joint: int, seed: int) -> ControlProblem:
    """A real problem with joint ``joint`` at 98 % of its range (inside alpha = 0.1's zone)."""
    limits = JointLimits(model.q_min, model.q_max, model.qd_max)
    rng = np.random.default_rng(seed)
    q = rng.uniform(0.5 * model.q_min, 0.5 * model.q_max)
    q[joint] = model.q_max[joint] - 0.01 * (model.q_max[joint] - model.q_min[joint])
    lower, upper = velocity_bounds(q, limits, PERIOD)
    return ControlProblem(model.relative_state(q).jacobian, 0.05 * rng.standard_normal(6), lower, upper,
                          repulsive_velocity(q, limits, 0.1))


def objective(qd: np.ndarray, repulsive: np.ndarray) -> float:
    zone = repulsive != 0.0
    return float(0.5 * np.sum((qd[zone] - repulsive[zone]) ** 2) + SECONDARY_L1_WEIGHT * np.sum(np.abs(qd[~zone])))


def epigraph_solve(p: ControlProblem, qd1: np.ndarray) -> np.ndarray:
    """The second level by SLSQP on (qd, t): min 1/2 sum_Z (qd - r)^2 + lambda_2 sum_{not Z} t,
    -t <= qd <= t, J qd = J qd1, lower <= qd <= upper (started at qd1, feasible)."""
    n = qd1.shape[0]
    zone = p.repulsive != 0.0
    price = np.where(zone, 0.0, SECONDARY_L1_WEIGHT)

    def f(x: np.ndarray) -> float:
        qd, t = x[:n], x[n:]
        return float(0.5 * np.sum((qd[zone] - p.repulsive[zone]) ** 2) + price @ t)

    def grad(x: np.ndarray) -> np.ndarray:
        g = np.zeros(2 * n)
        g[:n][zone] = x[:n][zone] - p.repulsive[zone]
        g[n:] = price
        return g

    eye = np.eye(n)
    cons = [{"type": "eq", "fun": lambda x: p.jacobian @ x[:n] - p.jacobian @ qd1,
             "jac": lambda x: np.hstack((p.jacobian, np.zeros((6, n))))},
            {"type": "ineq", "fun": lambda x: x[n:] - x[:n], "jac": lambda x: np.hstack((-eye, eye))},
            {"type": "ineq", "fun": lambda x: x[n:] + x[:n], "jac": lambda x: np.hstack((eye, eye))}]
    bounds = [*zip(p.lower, p.upper, strict=True), *[(0.0, None)] * n]
    res = minimize(f, np.concatenate((qd1, np.abs(qd1))), jac=grad, constraints=cons, bounds=bounds, method="SLSQP",
                   options={"ftol": 1e-14, "maxiter": 1000})
    assert res.success, res.message
    return np.asarray(res.x[:n])


@pytest.mark.parametrize(("joint", "seed"), [(3, 1), (5, 2), (1, 3), (10, 4), (12, 5)])
def test_the_second_level_equals_an_independent_solve(model: DualArmModel, joint: int, seed: int) -> None:
    p = near_limit(model, joint, seed)
    assert np.count_nonzero(p.repulsive) >= 1
    qd1 = make_solver("sparse_qp").solve(p).velocities
    got = make_solver("hierarchical_sparse_l1_qp").solve(p)
    assert got.status == "solved", got.detail
    qd = got.velocities
    np.testing.assert_allclose(p.jacobian @ qd, p.jacobian @ qd1, atol=1e-8)  # the first level's task, kept
    assert np.all(qd >= p.lower - 1e-9) and np.all(qd <= p.upper + 1e-9)
    reference = epigraph_solve(p, qd1)
    assert objective(qd, p.repulsive) <= objective(reference, p.repulsive) + 1e-9
    assert objective(qd, p.repulsive) == pytest.approx(objective(reference, p.repulsive), abs=1e-7)


@pytest.mark.parametrize(("joint", "seed"), [(3, 1), (5, 2), (1, 3), (10, 4), (12, 5)])
def test_fewer_joints_move_than_with_eq27_and_the_zone_joint_is_pushed_out(model: DualArmModel, joint: int,
                                                                           seed: int) -> None:
    """Same problems: eq (27)'s second level moves (nearly) every joint; the l1 level moves at most 6 beyond
    the first level's, and drives the zone joint away from its limit as eq (27) does."""
    p = near_limit(model, joint, seed)
    l1 = make_solver("hierarchical_sparse_l1_qp").solve(p).velocities
    l2 = make_solver("hierarchical_sparse_qp").solve(p).velocities
    qd1 = make_solver("sparse_qp").solve(p).velocities

    def active(qd: np.ndarray) -> int:
        return int(np.count_nonzero(np.abs(qd) > ACTIVITY_THRESHOLD))

    assert active(l1) < active(l2), (active(l1), active(l2))
    assert active(l1) <= active(qd1) + 6 + 1  # a basic solution: 6 task rows, plus the zone joint
    assert l1[joint] < 0.0 and p.repulsive[joint] < 0.0  # at the upper limit: moving down


def test_without_a_joint_in_the_zone_it_is_the_sparse_qp_bit_for_bit(model: DualArmModel) -> None:
    p = near_limit(model, 3, 1)
    calm = ControlProblem(p.jacobian, p.reference, p.lower, p.upper, np.zeros_like(p.repulsive))
    np.testing.assert_array_equal(make_solver("hierarchical_sparse_l1_qp").solve(calm).velocities,
                                  make_solver("sparse_qp").solve(calm).velocities)
