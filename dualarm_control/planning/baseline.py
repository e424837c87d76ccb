"""Pseudo-inverse baseline of paper 003 (Sect. II-B, eq 12-13): local null-space optimisation of c(q).

``qd = J_r^+ (v_d + K e) + (I - J_r^+ J_r) qd_0`` with ``qd_0 = -k0 (dc/dq)^T`` (eq 12-13,
paper: k0 = 1), integrated with explicit Euler along the same sampled path from a given
start. The path between consecutive samples is followed on the straight line at a constant
relative speed (default 0.05 m/s, the project's default linear limit); the fixed relative
orientation R_d is held. Eq (12) is open loop; the closed-loop term ``K e`` (paper 000,
eq 13, K = 10 1/s, position error and Luh orientation error) is added so that the closure
error does not drift with the integration. The tangent used by c during an interval is the
normalised blend of the two samples' tangents; c is recorded at every path sample with that
sample's tangent, as for the global method.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dualarm_control.kinematics import (
    DualArmModel,
    FloatArray,
    pose_error,
    rotation_angle,
)
from dualarm_control.planning.index import (
    chain_terms,
    index_and_gradient,
    performance_index,
)
from dualarm_control.planning.path import SampledPath


@dataclass(frozen=True)
class BaselineParams:
    """Parameters of the baseline (units in brackets).

    Attributes:
        k0: null-space gain of eq (13) [rad^3/(m^2 s)]; paper: 1.
        gain: closed-loop gain K [1/s].
        speed: relative speed along the path [m/s].
        period: Euler step [s].
    """

    k0: float = 1.0
    gain: float = 10.0
    speed: float = 0.05
    period: float = 0.005


@dataclass(frozen=True)
class BaselineResult:
    """Configurations and indices at the path samples.

    Attributes:
        configurations: q at each path sample, (h, 14) [rad].
        indices: c(q_i) of eq (14) at each sample, (h,).
        position_errors, rotation_errors: closure errors at each sample [m], [rad], (h,).
    """

    configurations: FloatArray
    indices: FloatArray
    position_errors: FloatArray
    rotation_errors: FloatArray


def _closure(position: FloatArray, rotation: FloatArray, p_d: FloatArray, r_d: FloatArray) -> tuple[float, float]:
    """(||p_d - p|| [m], geodesic angle between R and R_d [rad])."""
    return float(np.linalg.norm(p_d - position)), rotation_angle(rotation, r_d)


def run_baseline(
    model: DualArmModel, path: SampledPath, start: FloatArray, params: BaselineParams | None = None
) -> BaselineResult:
    """Integrate eq (12)-(13) along ``path`` from ``start`` (14,) [rad]; see the module docstring."""
    prm = params or BaselineParams()
    q = np.asarray(start, dtype=float).copy()
    n = model.nq
    eye = np.eye(n)
    r_d = path.rotation
    configs = [q.copy()]
    terms = chain_terms(model, q)
    indices = [performance_index(terms, path.tangents[0])]
    errors = [_closure(terms.position, terms.rotation, path.positions[0], r_d)]
    for i in range(len(path) - 1):
        p_a, p_b = path.positions[i], path.positions[i + 1]
        t_a, t_b = path.tangents[i], path.tangents[i + 1]
        duration = float(np.linalg.norm(p_b - p_a)) / prm.speed
        steps = max(1, math.ceil(duration / prm.period - 1e-9))
        dt = duration / steps
        v_d = np.concatenate(((p_b - p_a) / duration, np.zeros(3)))
        for s in range(steps):
            sigma = s / steps
            p_d = p_a + sigma * (p_b - p_a)
            tangent = (1.0 - sigma) * t_a + sigma * t_b
            tangent = tangent / np.linalg.norm(tangent)
            terms = chain_terms(model, q)
            jac = terms.relative_jacobian
            j_pinv = np.linalg.pinv(jac, rcond=1e-8)
            _, grad = index_and_gradient(terms, tangent)
            e = pose_error(terms.position, terms.rotation, p_d, r_d)
            qd = j_pinv @ (v_d + prm.gain * e) + (eye - j_pinv @ jac) @ (-prm.k0 * grad)
            q = q + dt * qd
        terms = chain_terms(model, q)
        configs.append(q.copy())
        indices.append(performance_index(terms, t_b))
        errors.append(_closure(terms.position, terms.rotation, p_b, r_d))
    err = np.array(errors)
    return BaselineResult(
        configurations=np.array(configs),
        indices=np.array(indices),
        position_errors=err[:, 0],
        rotation_errors=err[:, 1],
    )
