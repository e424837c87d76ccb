"""LAPACK's dposv as the solvers load it (dualarm_control/solvers/lapack.py): scipy's own routine, without
scipy.linalg's package import (0.26 s of CPU in every controller process), checked in fresh processes."""

from __future__ import annotations

import subprocess
import sys

import numpy as np

from dualarm_control.solvers.lapack import spd_solve

BUILD = """
import sys
from dualarm_control.controller import RelativeController
from dualarm_control.controller_params import controller_params
from dualarm_control.kinematics import DualArmModel
model = DualArmModel()
for solver in ("standard_qp", "sparse_qp", "hierarchical_sparse_qp"):
    RelativeController(model, controller_params({"solver": solver}))
print("scipy.linalg" in sys.modules, "scipy.linalg._flapack" in sys.modules)
import scipy.linalg.lapack
from dualarm_control.solvers.lapack import dposv
print(scipy.linalg.lapack.dposv is dposv())
"""


def test_a_controller_loads_dposv_without_scipy_linalg_and_it_is_scipys_routine() -> None:
    """Building the three daqp solvers' controllers loads LAPACK's module and not scipy.linalg; a later
    ``import scipy.linalg`` finds that module: ``scipy.linalg.lapack.dposv`` is the solvers' routine itself."""
    out = subprocess.run([sys.executable, "-c", BUILD], capture_output=True, text=True, timeout=120, check=True)
    assert out.stdout.split() == ["False", "True", "True"], out.stdout + out.stderr


def test_spd_solve_against_numpy_and_a_singular_system() -> None:
    rng = np.random.default_rng(3)
    for m in (1, 3, 6):
        j = rng.standard_normal((m, 14))
        a, b = j @ j.T + 1e-6 * np.eye(m), rng.standard_normal(m)
        x = spd_solve(a, b)
        assert x is not None
        np.testing.assert_allclose(x, np.linalg.solve(a, b), rtol=1e-10, atol=1e-12)
    assert spd_solve(np.zeros((6, 6)), np.ones(6)) is None
