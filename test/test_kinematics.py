"""Tests of dualarm_control.kinematics: relative Jacobian (eq 5-6), Luh error (eq 10), relative pose (eq 1-2)."""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest

from dualarm_control.errors import DimensionError
from dualarm_control.kinematics import (
    LEFT_TOOL,
    RIGHT_TOOL,
    DualArmModel,
    luh_orientation_error,
    pose_error,
    rotation_angle,
    skew,
)
from dualarm_control.paths import urdf_path

N_CONFIGS = 12
FD_STEP = 1e-6  # central differences: truncation O(h^2) ~ 1e-12, round-off O(eps/h) ~ 1e-10


@pytest.fixture(scope="module")
def model() -> DualArmModel:
    return DualArmModel()


def random_configurations(model: DualArmModel, count: int, seed: int) -> list[np.ndarray]:
    """Uniform configurations in the inner 95 % of the joint ranges (so q +- h stays inside)."""
    rng = np.random.default_rng(seed)
    mid, half = (model.q_max + model.q_min) / 2, (model.q_max - model.q_min) / 2
    return [mid + 0.95 * half * rng.uniform(-1.0, 1.0, model.nq) for _ in range(count)]


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    """Random rotation from a QR decomposition of a Gaussian matrix (not via pinocchio)."""
    q, r = np.linalg.qr(rng.standard_normal((3, 3)))
    q = q @ np.diag(np.sign(np.diag(r)))
    return q if np.linalg.det(q) > 0 else -q


def rodrigues(axis: np.ndarray, angle: float) -> np.ndarray:
    """exp(angle [axis]x) written out (Rodrigues), for a unit axis."""
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    return np.eye(3) + math.sin(angle) * k + (1.0 - math.cos(angle)) * k @ k


def test_model_dimensions_and_joint_order(model: DualArmModel) -> None:
    """Joint order is left 1..7 then right 1..7, as the module's convention states."""
    assert model.nq == 14 and model.n_left == 7
    assert model.joint_names == [f"left_joint_{i}" for i in range(1, 8)] + [f"right_joint_{i}" for i in range(1, 8)]
    assert np.all(model.q_min < model.q_max) and np.all(model.qd_max > 0)


def test_relative_jacobian_matches_central_finite_differences(model: DualArmModel) -> None:
    """Each column of J vs central differences of relative_pose: v = dp/dt, w = log3(R+ R-^T)/2h."""
    worst = 0.0
    for q in random_configurations(model, N_CONFIGS, seed=1):
        jac = model.relative_state(q).jacobian
        assert jac.shape == (6, 14)
        fd = np.zeros((6, 14))
        for i in range(14):
            dq = np.zeros(14)
            dq[i] = FD_STEP
            p_plus, r_plus = model.relative_pose(q + dq)
            p_minus, r_minus = model.relative_pose(q - dq)
            fd[:3, i] = (p_plus - p_minus) / (2 * FD_STEP)
            fd[3:, i] = pin.log3(r_plus @ r_minus.T) / (2 * FD_STEP)
        worst = max(worst, float(np.max(np.abs(jac - fd))))
    assert worst < 1e-6, f"max |J - J_fd| = {worst:.3g}"


def test_relative_jacobian_predicts_a_random_direction(model: DualArmModel) -> None:
    """J @ dq vs the finite-difference twist along a random joint direction (not a single joint)."""
    rng = np.random.default_rng(7)
    for q in random_configurations(model, 4, seed=2):
        dq = rng.standard_normal(14)
        dq /= np.linalg.norm(dq)
        p_plus, r_plus = model.relative_pose(q + FD_STEP * dq)
        p_minus, r_minus = model.relative_pose(q - FD_STEP * dq)
        twist = np.concatenate(((p_plus - p_minus) / (2 * FD_STEP), pin.log3(r_plus @ r_minus.T) / (2 * FD_STEP)))
        np.testing.assert_allclose(model.relative_state(q).jacobian @ dq, twist, atol=1e-6)


def test_relative_pose_equals_independent_se3_composition(model: DualArmModel) -> None:
    """relative_pose and relative_state vs a separate pinocchio model: (oMf1)^-1 * oMf2."""
    ref = pin.buildModelFromUrdf(str(urdf_path()))
    data = ref.createData()
    f1, f2 = ref.getFrameId(LEFT_TOOL), ref.getFrameId(RIGHT_TOOL)
    for q in random_configurations(model, 6, seed=3):
        pin.framesForwardKinematics(ref, data, q)
        rel = data.oMf[f1].inverse() * data.oMf[f2]
        p, r = model.relative_pose(q)
        np.testing.assert_allclose(p, rel.translation, atol=1e-12)
        np.testing.assert_allclose(r, rel.rotation, atol=1e-12)
        state = model.relative_state(q)
        np.testing.assert_allclose(state.position, rel.translation, atol=1e-12)
        np.testing.assert_allclose(state.rotation, rel.rotation, atol=1e-12)


def test_right_tool_pose_is_independent_of_left_joints(model: DualArmModel) -> None:
    """The right tool's world pose does not depend on the left joints (independent check of the joint split)."""
    ref = pin.buildModelFromUrdf(str(urdf_path()))
    data = ref.createData()
    f2 = ref.getFrameId(RIGHT_TOOL)
    q = random_configurations(model, 1, seed=4)[0]
    q2 = q.copy()
    q2[:7] += 0.1
    pin.framesForwardKinematics(ref, data, q)
    before = data.oMf[f2].copy()
    pin.framesForwardKinematics(ref, data, q2)
    assert before.isApprox(data.oMf[f2], 1e-12)
    np.testing.assert_allclose(model.tool_poses(q2)[1].homogeneous, before.homogeneous, atol=1e-12)


def test_luh_error_is_zero_for_equal_rotations() -> None:
    """Eq (10) with R* = R: each column crossed with itself gives 0."""
    rng = np.random.default_rng(5)
    for _ in range(10):
        r = random_rotation(rng)
        np.testing.assert_allclose(luh_orientation_error(r, r), 0.0, atol=1e-15)


def test_luh_error_equals_sin_theta_u() -> None:
    """Eq (10) for R* = exp(theta u) R equals the closed form sin(theta) u (theta in (0, pi))."""
    rng = np.random.default_rng(6)
    for theta in np.linspace(0.01, math.pi - 0.01, 25):
        u = rng.standard_normal(3)
        u /= np.linalg.norm(u)
        r = random_rotation(rng)
        r_des = rodrigues(u, float(theta)) @ r
        np.testing.assert_allclose(luh_orientation_error(r, r_des), math.sin(theta) * u, atol=1e-12)


def test_luh_error_is_vee_of_skew_part() -> None:
    """Eq (10) equals vee((A - A^T)/2) with A = R* R^T."""
    rng = np.random.default_rng(8)
    for _ in range(20):
        r, r_des = random_rotation(rng), random_rotation(rng)
        a = r_des @ r.T
        s = (a - a.T) / 2
        vee = np.array([s[2, 1], s[0, 2], s[1, 0]])
        np.testing.assert_allclose(luh_orientation_error(r, r_des), vee, atol=1e-12)


def test_pose_error_stacks_position_and_luh_error() -> None:
    """Eq (8)-(10): e = [p* - p; e_o] against hand values (90 degrees about z: e_o = z)."""
    r = np.eye(3)
    r_des = rodrigues(np.array([0.0, 0.0, 1.0]), math.pi / 2)
    e = pose_error(np.array([1.0, 2.0, 3.0]), r, np.array([1.5, 2.0, 2.0]), r_des)
    np.testing.assert_allclose(e, [0.5, 0.0, -1.0, 0.0, 0.0, 1.0], atol=1e-15)


def test_rotation_angle_is_the_geodesic_angle() -> None:
    """rotation_angle(R, exp(theta u) R) == theta, including theta = 0 and pi."""
    rng = np.random.default_rng(9)
    for theta in (0.0, 1e-3, 0.5, 2.0, math.pi):
        u = rng.standard_normal(3)
        u /= np.linalg.norm(u)
        r = random_rotation(rng)
        assert rotation_angle(r, rodrigues(u, theta) @ r) == pytest.approx(theta, abs=2e-8)


@pytest.mark.parametrize("size", [13, 15])
def test_check_q_rejects_wrong_joint_count(model: DualArmModel, size: int) -> None:
    """check_q raises DimensionError naming the expected count for 13 or 15 values."""
    with pytest.raises(DimensionError, match="expected 14 values"):
        model.check_q(np.zeros(size))
    with pytest.raises(DimensionError):
        model.relative_state(np.zeros(size))


def test_skew_matches_cross_product() -> None:
    """skew(v) @ w == np.cross(v, w), and skew(v) is antisymmetric."""
    rng = np.random.default_rng(10)
    for _ in range(20):
        v, w = rng.standard_normal(3), rng.standard_normal(3)
        np.testing.assert_allclose(skew(v) @ w, np.cross(v, w), atol=1e-14)
        np.testing.assert_array_equal(skew(v), -skew(v).T)
