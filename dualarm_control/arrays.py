"""The array type of the package's vectors and matrices (positions, velocities, Jacobians): float64 numpy arrays."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
"""A float64 array; each use says its shape and units."""


def add_diagonal(matrix: FloatArray, value: float) -> None:
    """``matrix`` (m, m) += ``value`` I in place: the same sums as ``matrix.flat[:: m + 1] += value``, through a
    strided view when the matrix is C-contiguous (cheaper than numpy's flat iterator on the cycle's small matrices)."""
    if matrix.flags.c_contiguous:
        matrix.reshape(-1)[:: matrix.shape[0] + 1] += value
    else:
        matrix.flat[:: matrix.shape[0] + 1] += value


def split_columns(matrix: FloatArray) -> FloatArray:
    """[A, -A] (m, 2n) for A (m, n): a matrix over z = [x+; x-] with x = x+ - x- (the lasso's split, eq (19))."""
    return np.concatenate((matrix, -matrix), axis=1)
