"""One arm's singularity margin, paper 001 eq (10) (scenario task type ``singularity``)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dualarm_control.kinematics import Configuration, FloatArray, jacobian_derivatives
from dualarm_control.tasks.base import (
    DEFAULT_INEQUALITY_WEIGHT,
    INEQUALITY,
    Kind,
    TaskRows,
    check_gain_weight,
)
from dualarm_control.tasks.registry import TaskContext, TaskSpec, register_task


def manipulability(jacobian: FloatArray) -> tuple[float, FloatArray]:
    """det(J J^T) and its gradient with respect to the chain's joints (paper 001, eq 10).

    The paper writes det(J^T J) for its 6-joint Puma arms (square J, the same number); for
    a 7-joint arm J^T J (7, 7) has rank 6 and a zero determinant, so the 6x6 J J^T is used
    (Yoshikawa's manipulability squared). With A = J J^T and dJ/dq_k of
    :func:`jacobian_derivatives`: d det A / dq_k = 2 tr(adj(A) dJ_k J^T), adj(A) = det(A) A^-1
    the adjugate, computed from the eigen-decomposition A = U diag(w) U^T as
    U diag(prod_{j != i} w_j) U^T, so that a singular arm (det A = 0) gives a finite gradient.

    Args:
        jacobian: J (6, m) of one arm at its tool frame, world axes.

    Returns:
        (det(J J^T), gradient (m,)).
    """
    a = jacobian @ jacobian.T
    w, u = np.linalg.eigh(a)
    n = w.shape[0]
    others = np.array([np.prod(np.delete(w, i)) for i in range(n)])  # prod_{j != i} w_j
    adj_j = (u * others) @ (u.T @ jacobian)  # adj(A) J, (6, m)
    derivs = jacobian_derivatives(jacobian)  # (m, 6, m)
    # tr(adj(A) dJ_k J^T) = sum_ij (adj(A) J)_ij (dJ_k)_ij  (adj(A) symmetric)
    grad = 2.0 * np.einsum("ij,kij->k", adj_j, derivs)
    return float(np.prod(w)), grad


@dataclass(frozen=True)
class ManipulabilityTask:
    """Singularity margin of one arm, paper 001 eq (10) (1 inequality row).

        f_5i = -1/2 det(J_i J_i^T) <= b_5 < 0,

    J_i (6, 7) the geometric Jacobian of arm i at its tool frame (see :func:`manipulability`),
    df/dq = -1/2 d det / dq on that arm's joints (0 on the other arm), df/dt = 0.

    Attributes:
        frame: the arm's tool frame. side: "left" or "right". bound: b_5 < 0.
    """

    frame: str
    side: str
    bound: float
    gain: float
    weight: float = DEFAULT_INEQUALITY_WEIGHT
    name: str = "singularity"
    kind: Kind = INEQUALITY

    def __post_init__(self) -> None:
        check_gain_weight(self.name, self.gain, self.weight)
        if not (math.isfinite(self.bound) and self.bound < 0):
            raise ValueError(f"task {self.name!r}: bound b_5 must be < 0, got {self.bound}")

    def evaluate(self, conf: Configuration, t: float) -> TaskRows:
        cols = conf.model.arm_columns(self.side)
        det, grad = manipulability(conf.frame(self.frame).jacobian[:, cols])
        jac = np.zeros((1, conf.model.nq))
        jac[0, cols] = -0.5 * grad
        return TaskRows(self.name, self.kind, np.array([-0.5 * det]), np.array([self.bound]), jac, np.zeros(1),
                        self.gain, self.weight)


@register_task("singularity")
def singularity(spec: TaskSpec, context: TaskContext) -> ManipulabilityTask:
    """``frame``, ``side`` (left|right), ``bound`` (b_5 < 0)."""
    return ManipulabilityTask(spec.value("frame", str), spec.value("side", str), bound=spec.value("bound", float),
                              gain=context.gain, weight=spec.value("weight", float, DEFAULT_INEQUALITY_WEIGHT),
                              name=spec.name)
