"""LAPACK's Cholesky solve for the solvers' small symmetric positive definite systems (J J^T, 6 x 6).

The routine is scipy's own f2py wrapper of LAPACK's dposv (``scipy.linalg.lapack.dposv`` is this very function),
loaded when a solver is built (:func:`dposv` from :class:`~dualarm_control.solvers.base.Solver`), never in a
control cycle, and loaded from its extension module alone: ``import scipy.linalg`` runs the whole package's
``__init__`` (its array-API layer, every submodule), 0.26 s of CPU and about 20 MiB in every controller process
that needs one routine of it. Loaded alone: 0.03 s. Where the extension file is not where scipy keeps it, the
normal import. Nodes that never solve (the simulator, the trajectory node) load nothing.
"""

from __future__ import annotations

import functools
import importlib.machinery
import importlib.util
import sys
from collections.abc import Callable
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

from dualarm_control.arrays import FloatArray

FLAPACK = "scipy.linalg._flapack"
"""scipy's f2py module of LAPACK (``scipy.linalg.lapack`` re-exports its routines)."""


def _flapack() -> ModuleType:
    """scipy's LAPACK extension module: already imported, else loaded from its file without scipy.linalg's package
    ``__init__`` and registered under its name (a later ``import scipy.linalg`` takes this module, the same
    routines); else (another layout of scipy) the normal import."""
    if FLAPACK in sys.modules:
        return sys.modules[FLAPACK]
    import scipy

    linalg = Path(scipy.__path__[0], "linalg")
    files = [linalg / ("_flapack" + suffix) for suffix in importlib.machinery.EXTENSION_SUFFIXES
             if (linalg / ("_flapack" + suffix)).is_file()]
    if not files:
        from scipy.linalg import _flapack  # type: ignore[attr-defined]

        return _flapack  # type: ignore[no-any-return]
    loader = importlib.machinery.ExtensionFileLoader(FLAPACK, str(files[0]))
    spec = importlib.util.spec_from_file_location(FLAPACK, str(files[0]), loader=loader)
    assert spec is not None
    module = importlib.util.module_from_spec(spec)
    loader.exec_module(module)
    sys.modules[FLAPACK] = module
    return module


@functools.cache
def dposv() -> Callable[..., Any]:
    """LAPACK's dposv (module docstring), loaded on the first call."""
    return _flapack().dposv  # type: ignore[no-any-return]


def spd_solve(a: FloatArray, b: FloatArray) -> FloatArray | None:
    """x with a x = b for a symmetric positive definite ``a`` (m, m), by Cholesky (LAPACK dposv).

    Called directly: np.linalg.solve costs four times as much on these 6x6 systems (1.7 against 6.8 us:
    its general LU and checks). Returns None when ``a`` is not positive definite (singular J J^T).
    """
    _, x, info = dposv()(a, b)
    return None if info != 0 else np.asarray(x)
