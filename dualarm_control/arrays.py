"""The array type of the package's vectors and matrices (positions, velocities, Jacobians): float64 numpy arrays."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
"""A float64 array; each use says its shape and units."""
