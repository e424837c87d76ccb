"""Force-transmission index along a direction (paper 003, eq 14) and the closure constraint (eq 17).

Everything here is a pure function of one configuration's :class:`ChainTerms`, computed in
one pinocchio pass (``computeJointJacobians`` + ``updateFramePlacements``).

Notation (paper 003, with the relative Jacobian of paper 000, eq 5-6):

* ``q`` (14,) [rad], left joints 1..7 then right joints 1..7 (the model's order).
* F1 the left tool frame (R_1 its world orientation), F2 the right tool frame (origin o_2).
* ``p(q) = R_1^T (o_2 - o_1)`` [m], the relative position of eq (10), in F1.
* For each joint k the world-frame (spatial) Jacobian column ``(V_k, Z_k)``: ``Z_k`` the
  joint axis, ``V_k`` the velocity of the body point at the world origin. The velocity of
  the point at o_2 rigidly attached to joint k's link is ``W_k = V_k + Z_k x o_2`` [m/rad].
* Relative Jacobian, eq (11): ``J_r = [J_p; J_w]`` with
  ``J_p = R_1^T [-W_L, W_R]`` (= dp/dq, (3, 14), m/rad) and ``J_w = R_1^T [-Z_L, Z_R]``
  ((3, 14), angular velocity of F2 relative to F1, in F1). It equals
  :meth:`DualArmModel.relative_state`'s Jacobian.

Index (eq 14) with ``u = [t; 0]``, t the unit path tangent in F1:
``c(q) = u^T J_r J_r^T u = ||J_p^T t||^2`` [m^2/rad^2]; lower means a higher force
transmission ratio ``alpha = c^{-1/2}`` (eq 6) along t. Only the linear ellipsoid counts
(W = diag(1, 1, 1, 0, 0, 0) of eq 8, Sect. IV-C), which u = [t; 0] gives by itself.

Gradient (needed by eq 13 and the NLP of eq 19-20): ``dc/dq_m = 2 sum_k s_k M_km`` with
``s = J_p^T t`` and ``M_km = t . d^2 p / dq_k dq_m``. For revolute joints of a serial chain
(Lie-bracket rule dZ_k/dq_j = Z_j x Z_k for j before k) the second derivatives are closed
form; in world coordinates, with "early"/"late" the order along each arm's chain:

* both left:  ``d^2p/dq_k dq_m = R_1^T (Z_late x W_early)``
* both right: ``d^2p/dq_k dq_m = R_1^T (Z_early x W_late)``
* left k, right j: ``d^2p/dq_k dq_j = -R_1^T (Z_k x W_j)``

(derived from dR_1/dq_k = [Z_k]x R_1 and do_2/dq_j = W_j; checked against finite
differences in test/test_planner.py). Cost: a few 7x7 products, no finite differences.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from dualarm_control.kinematics import DualArmModel, FloatArray


@dataclass(frozen=True)
class ChainTerms:
    """World-frame kinematic terms of one configuration (see the module docstring).

    Attributes:
        r1: R_1, world orientation of F1, (3, 3).
        position: p = R_1^T (o_2 - o_1) [m], (3,), relative position in F1.
        rotation: R = R_1^T R_2, relative orientation, (3, 3).
        axes: Z, world joint axes, (3, 14).
        point_velocities: W, velocity of o_2 attached to each joint's link [m/rad], (3, 14).
        n_left: number of left-arm joints (7).
    """

    r1: FloatArray
    position: FloatArray
    rotation: FloatArray
    axes: FloatArray
    point_velocities: FloatArray
    n_left: int

    @property
    def position_jacobian(self) -> FloatArray:
        """J_p = dp/dq = R_1^T [-W_L, W_R], (3, 14) [m/rad]: the linear rows of J_r (eq 11)."""
        w = self.point_velocities.copy()
        w[:, : self.n_left] *= -1.0
        return self.r1.T @ w

    @property
    def angular_jacobian(self) -> FloatArray:
        """J_w = R_1^T [-Z_L, Z_R], (3, 14) [1]: the angular rows of J_r (eq 11), in F1."""
        z = self.axes.copy()
        z[:, : self.n_left] *= -1.0
        return self.r1.T @ z

    @property
    def relative_jacobian(self) -> FloatArray:
        """J_r of eq (11) (paper 000 eq 5-6), (6, 14), twist [v; w] in F1."""
        return np.vstack((self.position_jacobian, self.angular_jacobian))


def chain_terms(model: DualArmModel, q: FloatArray) -> ChainTerms:
    """One pinocchio pass at q (14,) [rad] -> :class:`ChainTerms`."""
    pin.computeJointJacobians(model.model, model.data, q)
    pin.updateFramePlacements(model.model, model.data)
    f1, f2 = model.tool_frame_ids
    o1, o2 = model.data.oMf[f1], model.data.oMf[f2]
    jac = model.data.J  # world frame: rows [V; Z]
    z = np.array(jac[3:, :])
    w = np.array(jac[:3, :]) + np.cross(z, o2.translation, axis=0)
    r1 = np.array(o1.rotation)
    return ChainTerms(
        r1=r1,
        position=r1.T @ (o2.translation - o1.translation),
        rotation=r1.T @ o2.rotation,
        axes=z,
        point_velocities=w,
        n_left=model.n_left,
    )


def performance_index(terms: ChainTerms, tangent: FloatArray) -> float:
    """c(q) = u^T J_r J_r^T u with u = [t; 0], eq (14) [m^2/rad^2].

    Args:
        terms: kinematics at q.
        tangent: unit path tangent t in F1, (3,).
    """
    s = terms.position_jacobian.T @ tangent
    return float(s @ s)


def _symmetric_from_upper(a: FloatArray) -> FloatArray:
    """Matrix whose (i, j) entry is a[min(i, j), max(i, j)]."""
    upper = np.triu(a)
    return upper + np.triu(a, 1).T


def index_hessian_projection(terms: ChainTerms, tangent: FloatArray) -> FloatArray:
    """M with M_km = t . d^2 p / dq_k dq_m, (14, 14) [m/rad^2], symmetric (module docstring)."""
    nl = terms.n_left
    tau = terms.r1 @ tangent  # t in world coordinates
    z_l, z_r = terms.axes[:, :nl], terms.axes[:, nl:]
    w_l, w_r = terms.point_velocities[:, :nl], terms.point_velocities[:, nl:]
    tau_x_zl = np.cross(tau, z_l, axis=0)  # tau x Z_l
    wr_x_tau = np.cross(w_r, tau, axis=0)  # W_j x tau
    # tau . (Z_l x W_e) = W_e . (tau x Z_l): row e (early), column l (late)
    m_ll = _symmetric_from_upper(w_l.T @ tau_x_zl)
    # tau . (Z_e x W_l) = Z_e . (W_l x tau)
    m_rr = _symmetric_from_upper(z_r.T @ wr_x_tau)
    # -tau . (Z_k x W_j) = -Z_k . (W_j x tau)
    m_lr = -(z_l.T @ wr_x_tau)
    return np.block([[m_ll, m_lr], [m_lr.T, m_rr]])


def index_and_gradient(terms: ChainTerms, tangent: FloatArray) -> tuple[float, FloatArray]:
    """c(q) of eq (14) and its analytic gradient dc/dq, (14,) [m^2/rad^3].

    ``dc/dq = 2 M s`` with ``s = J_p^T t`` and M from :func:`index_hessian_projection`.
    """
    s = terms.position_jacobian.T @ tangent
    grad = 2.0 * index_hessian_projection(terms, tangent) @ s
    return float(s @ s), grad


def closure_residual(terms: ChainTerms, position: FloatArray, rotation: FloatArray) -> FloatArray:
    """Closure constraint of eq (17) as a residual h(q) = 0, (6,).

    ``h = [p(q) - p_d; log3(R_d^T R(q))]`` [m; rad]: the relative pose minus the path pose,
    the orientation part being the rotation vector of the error expressed in F2.
    """
    e_rot = np.asarray(pin.log3(rotation.T @ terms.rotation))
    return np.concatenate((terms.position - position, e_rot))


def closure_jacobian(terms: ChainTerms, rotation: FloatArray) -> FloatArray:
    """dh/dq of :func:`closure_residual`, (6, 14).

    Position rows: J_p. Orientation rows: ``Jlog3(R_d^T R) R^T J_w`` (the error rotation
    moves with the body angular velocity R^T w of F2 relative to F1).
    """
    err = rotation.T @ terms.rotation
    rows = np.asarray(pin.Jlog3(err)) @ terms.rotation.T @ terms.angular_jacobian
    return np.vstack((terms.position_jacobian, rows))
