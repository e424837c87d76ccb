"""The velocity damper: the rows ``A qd <= b`` that keep the robot's link pairs apart.

Velocity damper (Faverjon and Tournassoud 1987; Kanoun et al. 2011): for every pair closer than
the influence distance d_i, the approach speed is bounded so that d decays at most exponentially
towards the safety distance d_s:

    d_dot >= -xi (d - d_s) / (d_i - d_s)        i.e.   -dd_dq qd <= xi (d - d_s) / (d_i - d_s)

xi [m/s] is the approach speed allowed at d = d_i (it falls linearly to 0 at d = d_s, and d_dot
must be positive below d_s: the pair is pushed back out). Along the boundary d(t) - d_s = (d_0 -
d_s) exp(-t xi / (d_i - d_s)): d_s is never crossed in continuous time. d and its row dd_dq
(d_dot = dd_dq qd) are :mod:`dualarm_control.collision.distances`'; the settings are
:class:`~dualarm_control.collision.params.CollisionParams`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from dualarm_control.arrays import FloatArray
from dualarm_control.collision.distances import PairDistance
from dualarm_control.collision.params import CollisionParams
from dualarm_control.errors import DimensionError


def velocity_damper(dd_dq: FloatArray, distance: FloatArray, influence: float, safety: float,
                    gain: float) -> tuple[FloatArray, FloatArray]:
    """The velocity damper's rows A qd <= b of m pairs, all closer than ``influence`` (module docstring):

        -dd_dq qd <= xi (d - d_s) / (d_i - d_s)

    Args:
        dd_dq: the pairs' rows [m/rad], (m, n). distance: their d [m], (m,).
        influence: d_i [m]. safety: d_s [m], 0 <= d_s < d_i. gain: xi [m/s], > 0.

    Returns:
        A = -dd_dq [m/rad], (m, n), and b [m/s], (m,).
    """
    if dd_dq.ndim != 2 or distance.shape != (dd_dq.shape[0],):
        raise DimensionError(f"velocity_damper: rows {dd_dq.shape} and distances {distance.shape} do not match")
    return -dd_dq, velocity_damper_bound(distance, influence, safety, gain)


def velocity_damper_bound(distance: FloatArray, influence: float, safety: float, gain: float) -> FloatArray:
    """b = xi (d - d_s) / (d_i - d_s) [m/s], (m,), of :func:`velocity_damper`'s rows, for m distances d [m]."""
    if not (0.0 <= safety < influence and gain > 0.0 and math.isfinite(influence + gain)):
        CollisionParams(influence_distance=influence, safety_distance=safety, gain=gain)  # raises, naming the key
    span = influence - safety  # the pairs one by one: m is small, and each b is the same IEEE operations
    return np.array([gain * (d - safety) / span for d in distance.tolist()], dtype=float)


def velocity_damper_rows(distances: Sequence[PairDistance], influence: float, safety: float,
                         gain: float) -> tuple[FloatArray, FloatArray]:
    """:func:`velocity_damper` of the pairs of ``distances`` closer than ``influence`` (any subset of
    :meth:`CollisionModel.distances`), in their order; (0, n) and (0,) when none (n = 0 when
    ``distances`` is empty too)."""
    near = [p for p in distances if p.distance < influence]
    n = distances[0].dd_dq.shape[0] if distances else 0
    if any(p.dd_dq.shape != (n,) for p in near):
        raise DimensionError(f"velocity_damper_rows: rows of different lengths {sorted({p.dd_dq.shape for p in near})}")
    rows = np.stack([p.dd_dq for p in near]) if near else np.zeros((0, n))
    return velocity_damper(rows, np.array([p.distance for p in near]), influence, safety, gain)
