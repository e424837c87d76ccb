"""Tests of dualarm_control.tasks: every task's Jacobian and time derivative vs finite differences."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin
import pytest

from dualarm_control.kinematics import Configuration, DualArmModel, jacobian_derivatives
from dualarm_control.tasks import (
    EQUALITY,
    INEQUALITY,
    CircleTask,
    ConeTask,
    ManipulabilityTask,
    RelativePoseTask,
    TablePlaneTask,
    Task,
    assemble_problem,
    evaluate_tasks,
    manipulability,
)

H = 1e-6  # central differences: truncation O(h^2), round-off O(eps/h) ~ 1e-10


@pytest.fixture(scope="module")
def model() -> DualArmModel:
    return DualArmModel("lwr4_pan_cell")


def configurations(model: DualArmModel, count: int, seed: int) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    mid, half = (model.q_max + model.q_min) / 2, (model.q_max - model.q_min) / 2
    return [mid + 0.9 * half * rng.uniform(-1.0, 1.0, model.nq) for _ in range(count)]


def fd_jacobian(task: Task, model: DualArmModel, q: np.ndarray, t: float) -> np.ndarray:
    cols = []
    for i in range(model.nq):
        dq = np.zeros(model.nq)
        dq[i] = H
        plus = task.evaluate(Configuration(model, q + dq), t).value
        minus = task.evaluate(Configuration(model, q - dq), t).value
        cols.append((plus - minus) / (2 * H))
    return np.array(cols).T


def fd_time(task: Task, model: DualArmModel, q: np.ndarray, t: float) -> np.ndarray:
    conf = Configuration(model, q)
    return (task.evaluate(conf, t + H).value - task.evaluate(conf, t - H).value) / (2 * H)


def paper_001_tasks() -> list[Task]:
    return [
        CircleTask("left_tool", "right_tool", radius=0.06, rate=0.7, gain=1.0, height=0.02, normal_offset=0.004),
        ConeTask("left_tool", "right_tool", max_angle=math.radians(20), gain=1.0),
        ManipulabilityTask("left_tool", "left", bound=-1e-3, gain=1.0),
        ManipulabilityTask("right_tool", "right", bound=-1e-3, gain=1.0),
        TablePlaneTask((("left_link_4", 0.07), ("right_tool", 0.02), ("left_tool", 0.13)), table_height=0.4,
                       bound=-0.05, gain=1.0),
    ]


@pytest.mark.parametrize("index", range(5))
def test_paper_001_task_jacobian_and_time_derivative_match_finite_differences(model: DualArmModel,
                                                                              index: int) -> None:
    task = paper_001_tasks()[index]
    for q in configurations(model, 4, seed=index):
        t = 1.3
        rows = task.evaluate(Configuration(model, q), t)
        scale = max(1.0, float(np.abs(rows.jacobian).max()))
        np.testing.assert_allclose(rows.jacobian, fd_jacobian(task, model, q, t), atol=1e-7 * scale)
        np.testing.assert_allclose(rows.time_derivative, fd_time(task, model, q, t), atol=1e-7)
        assert rows.jacobian.shape == (rows.value.shape[0], model.nq) and rows.bound.shape == rows.value.shape


def test_manipulability_gradient_and_jacobian_derivatives(model: DualArmModel) -> None:
    """d det(J J^T)/dq and dJ/dq_k of the closed forms vs finite differences on one arm."""
    for q in configurations(model, 3, seed=10):
        cols = model.arm_columns("right")
        jac = Configuration(model, q).frame("right_tool").jacobian[:, cols]
        det, grad = manipulability(jac)
        derivs = jacobian_derivatives(jac)
        for k in range(7):
            dq = np.zeros(model.nq)
            dq[7 + k] = H
            jp = Configuration(model, q + dq).frame("right_tool").jacobian[:, cols]
            jm = Configuration(model, q - dq).frame("right_tool").jacobian[:, cols]
            np.testing.assert_allclose(derivs[k], (jp - jm) / (2 * H), atol=1e-8)
            fd = (manipulability(jp)[0] - manipulability(jm)[0]) / (2 * H)
            assert abs(grad[k] - fd) < 1e-8 * max(1.0, abs(det))


@dataclass(frozen=True)
class LinearTarget:
    """p*(t) = p0 + v t, R*(t) = exp(w t) R0 (a RelativeTarget with its own time derivative)."""

    p0: np.ndarray
    r0: np.ndarray
    linear_velocity: np.ndarray
    angular_velocity: np.ndarray
    t: float = 0.0

    @property
    def position(self) -> np.ndarray:
        return self.p0 + self.linear_velocity * self.t

    @property
    def rotation(self) -> np.ndarray:
        return pin.exp3(self.angular_velocity * self.t) @ self.r0


def test_relative_pose_task_is_paper_000_and_exact_at_zero_orientation_error() -> None:
    """f = -e, J the relative Jacobian (exact at R = R*), df/dt = -xd*, reference = xd* + K e."""
    model = DualArmModel()
    v, w = np.array([0.01, -0.02, 0.03]), np.array([0.1, 0.2, -0.1])
    for q in configurations(model, 3, seed=3):
        p, r = model.relative_pose(q)
        target = LinearTarget(p + 0.01, r, v, w)
        task = RelativePoseTask(target, gain=10.0)
        rows = task.evaluate(Configuration(model, q), 0.0)
        np.testing.assert_allclose(rows.jacobian, fd_jacobian(task, model, q, 0.0), atol=1e-7)
        conf = Configuration(model, q)
        fd_t = (RelativePoseTask(LinearTarget(p + 0.01, r, v, w, H), 10.0).evaluate(conf, 0).value
                - RelativePoseTask(LinearTarget(p + 0.01, r, v, w, -H), 10.0).evaluate(conf, 0).value) / (2 * H)
        np.testing.assert_allclose(rows.time_derivative, fd_t, atol=1e-7)
        np.testing.assert_allclose(rows.reference, np.concatenate((v, w)) + 10.0 * np.r_[0.01, 0.01, 0.01, 0, 0, 0],
                                   atol=1e-12)


def test_circle_task_value_is_the_offset_in_the_pan_frame(model: DualArmModel) -> None:
    """f = 0 exactly when the tip is at R_1 c(t) from the pan centre (eq 8)."""
    q = configurations(model, 1, seed=5)[0]
    task = CircleTask("left_tool", "right_tool", radius=0.05, rate=1.0, gain=1.0)
    conf = Configuration(model, q)
    pan, tip = conf.frame("left_tool"), conf.frame("right_tool")
    t = math.atan2(*(pan.rotation.T @ (tip.position - pan.position))[[1, 0]])
    local = pan.rotation.T @ (tip.position - pan.position)
    shifted = CircleTask("left_tool", "right_tool", radius=float(np.hypot(local[0], local[1])), rate=1.0,
                         gain=1.0, height=float(local[2]))
    np.testing.assert_allclose(shifted.evaluate(conf, t).value, 0.0, atol=1e-12)
    assert task.evaluate(conf, t).kind == EQUALITY


def test_assemble_problem_stacks_rows_by_kind(model: DualArmModel) -> None:
    q = configurations(model, 1, seed=6)[0]
    rows = evaluate_tasks(paper_001_tasks(), Configuration(model, q), 0.5)
    lower, upper = -np.ones(model.nq), np.ones(model.nq)
    problem = assemble_problem(rows, lower, upper, np.zeros(model.nq))
    assert problem.jacobian.shape == (3, 14)
    assert problem.inequality_jacobian is not None and problem.inequality_jacobian.shape == (1 + 1 + 1 + 3, 14)
    assert problem.inequality_weights is not None and np.all(problem.inequality_weights == 1e3)
    assert problem.problem_with_invalid_input() == ""
    assert [r.kind for r in rows] == [EQUALITY] + [INEQUALITY] * 4


def test_task_parameters_are_validated() -> None:
    with pytest.raises(ValueError, match="gain"):
        ConeTask("a", "b", max_angle=0.3, gain=0.0)
    with pytest.raises(ValueError, match="b_5"):
        ManipulabilityTask("a", "left", bound=0.1, gain=1.0)
    with pytest.raises(ValueError, match="max_angle"):
        ConeTask("a", "b", max_angle=4.0, gain=1.0)
    with pytest.raises(ValueError, match="radius"):
        CircleTask("a", "b", radius=-1.0, rate=1.0, gain=1.0)


def test_manipulability_is_finite_at_a_singular_configuration(model: DualArmModel) -> None:
    """q = 0: the arm is stretched out (det J J^T = 0); value and gradient stay finite (adjugate form)."""
    task = ManipulabilityTask("right_tool", "right", bound=-1e-3, gain=1.0)
    rows = task.evaluate(Configuration(model, np.zeros(model.nq)), 0.0)
    assert abs(rows.value[0]) < 1e-12 and np.all(np.isfinite(rows.jacobian))


def test_table_plane_rows_are_the_collision_limits_and_eq_11(model: DualArmModel) -> None:
    """f_6 (eq (11)) through the collision limit's distance code (coal's sphere-half-space distance,
    the witness point's row) equals the paper's closed form bit for bit: f_6j = -(z_j - r_j - z_table),
    df_6j/dq = -(J_v,j)_z."""
    task = paper_001_tasks()[4]
    assert isinstance(task, TablePlaneTask)
    for q in configurations(model, 5, seed=21):
        conf = Configuration(model, q)
        rows = task.evaluate(conf, 0.0)
        for j, (frame, radius) in enumerate(task.points):
            state = conf.frame(frame)
            assert rows.value[j] == -(state.position[2] - radius - task.table_height)
            assert np.array_equal(rows.jacobian[j], -state.jacobian[2])
