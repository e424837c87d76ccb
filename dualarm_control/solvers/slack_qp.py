"""The weighted-slack QP of paper 001 (Lemma 1 with slacks), as arrays: one piece for the
constraint-based solver and the failure policy's separating step (no solver import: no cycle).

Over x = [u (n); s (m_ie)], u the joint velocities [rad/s]:

    min 1/2 ||W_e^(1/2) (A_e u - r_e)||^2 + eps ||u||^2 + rho^T s + mu/2 ||s||^2
    s.t. A_ie u - s <= h,  s >= 0,  A_h u <= b_h (hard, no slack),  lower <= u <= upper

    H = [[2 eps I + A_e^T W_e A_e, 0], [0, mu I]],  g = [-A_e^T W_e r_e; rho],
    C = [[A_ie, -I], [A_h, 0]],  -inf <= C x <= [h; b_h],  [lower; 0] <= x <= [upper; +inf].
"""

from __future__ import annotations

import numpy as np

from dualarm_control.arrays import FloatArray
from dualarm_control.qp import QPProblem

SLACK_CURVATURE = 1e-6
"""mu: quadratic cost on the inequality slacks (keeps H positive definite) [-]."""
INFINITY = 1e20
"""Stand-in for an absent bound (both daqp and proxsuite treat it as infinite)."""


def slack_qp(a_e: FloatArray, r_e: FloatArray, w_e: FloatArray | None, lower: FloatArray, upper: FloatArray,
             regularization: float, a_ie: FloatArray | None = None, h: FloatArray | None = None,
             rho: FloatArray | None = None, a_hard: FloatArray | None = None,
             b_hard: FloatArray | None = None) -> QPProblem:
    """The QP of the module docstring.

    Args:
        a_e (m, n), r_e (m,): equality rows and their reference; w_e (m,) their weights (None: 1).
        lower, upper: the box of u [rad/s], (n,).
        regularization: eps >= 0.
        a_ie (m_ie, n), h (m_ie,), rho (m_ie,): slacked inequality rows, bounds, weights (None: none;
            rho None: 1).
        a_hard (m_h, n), b_hard (m_h,): hard rows without slack (None: none).

    Returns:
        QPProblem over x = [u; s], n + m_ie variables (just u, and no C, without any row).
    """
    n = a_e.shape[1]
    weighted = a_e.T * (np.ones(a_e.shape[0]) if w_e is None else w_e)  # A_e^T W_e, (n, m)
    h_uu = weighted @ a_e
    h_uu.flat[:: n + 1] += 2.0 * regularization
    g_u = -weighted @ r_e
    m = 0 if a_ie is None or h is None else a_ie.shape[0]
    hard = a_hard is not None and b_hard is not None and a_hard.shape[0] > 0
    if m == 0 and not hard:
        return QPProblem(H=h_uu, g=g_u, lb=lower, ub=upper)
    big = np.zeros((n + m, n + m))
    big[:n, :n] = h_uu
    big[n:, n:] = np.eye(m) * SLACK_CURVATURE
    blocks, bounds = [], []
    if m:
        assert a_ie is not None and h is not None
        blocks.append(np.hstack((a_ie, -np.eye(m))))
        bounds.append(h)
    if hard:
        assert a_hard is not None and b_hard is not None
        blocks.append(np.hstack((a_hard, np.zeros((a_hard.shape[0], m)))))
        bounds.append(b_hard)
    c = np.vstack(blocks)
    return QPProblem(
        H=big,
        g=np.concatenate((g_u, np.full(m, 1.0) if rho is None else rho)),
        C=c,
        l=np.full(c.shape[0], -INFINITY),
        u=np.concatenate(bounds),
        lb=np.concatenate((lower, np.zeros(m))),
        ub=np.concatenate((upper, np.full(m, INFINITY))),
    )
