"""LAPACK's Cholesky solve for the solvers' small symmetric positive definite systems (J J^T, 6 x 6).

scipy.linalg is imported when a solver is built (:func:`dposv` from
:class:`~dualarm_control.solvers.base.Solver`), never in a control cycle: the import costs 0.3 s of CPU
and 20 MiB, which a first cycle inside the loop paid as a burst of missed deadlines (the soak's, on CI),
and nodes that never solve (the simulator, the trajectory node) never pay it.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any

import numpy as np

from dualarm_control.arrays import FloatArray


@functools.cache
def dposv() -> Callable[..., Any]:
    """LAPACK's dposv (scipy.linalg.lapack), imported on the first call."""
    from scipy.linalg import lapack

    return lapack.dposv  # type: ignore[no-any-return]


def spd_solve(a: FloatArray, b: FloatArray) -> FloatArray | None:
    """x with a x = b for a symmetric positive definite ``a`` (m, m), by Cholesky (LAPACK dposv).

    Called directly: np.linalg.solve costs four times as much on these 6x6 systems (1.7 against 6.8 us:
    its general LU and checks). Returns None when ``a`` is not positive definite (singular J J^T).
    """
    _, x, info = dposv()(a, b)
    return None if info != 0 else np.asarray(x)
