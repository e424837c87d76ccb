"""The collision limit's deferred rows (:class:`~dualarm_control.limits.DeferredRows`) change no command.

The limit hands the solvers its rows' matrix unbuilt, with a speed bound C (|A qd| <= C |qd|): a
solver's result that the bound vouches for needs no matrix. A controller whose rows are always built
(the bound never vouching) must command the same velocities, bit for bit, cycle after cycle, as one
that defers them; along a drive of one arm into the other both kinds of cycles occur (rows deferred
while the pair approaches slowly, built once the damper holds it).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from test_properties import Target

from dualarm_control.collision import CollisionParams
from dualarm_control.controller import ControllerParams, RelativeController
from dualarm_control.kinematics import DualArmModel
from dualarm_control.limits import CollisionLimit, DeferredRows

PERIOD = 0.005


@pytest.mark.parametrize(("solver", "stall"), [("hierarchical_sparse_qp", 0.0), ("sparse_qp", 10.0),
                                               ("standard_qp", 10.0)])
def test_deferred_rows_change_no_command(solver: str, stall: float, monkeypatch: pytest.MonkeyPatch) -> None:
    """From the LWR4 cell's ready configuration, kinematic loop q += T qd: 2 s to a goal with the tools
    side by side, 10 cm apart (wrist links 8 cm apart, within d_i: rows deferred), then 2 s to the goal through the left forearm (right tool 0.35 m
    behind the left one: the issue's example). The deferring controller and the always-building one
    command the same bits every cycle. The hierarchical QP runs without the brake at a stall
    (``collision.stall_acceleration`` 0: with it, its rows are built in every cycle that has rows, 757 of 757,
    and the deferred path would go untested here); the other two with it (deferred in 230-240 cycles)."""
    model = DualArmModel("lwr4_cell")
    params = ControllerParams(solver=solver, collision=CollisionParams(stall_acceleration=stall))
    deferring = RelativeController(model, params)
    building = RelativeController(model, params)
    facing = Rotation.from_euler("xyz", [np.pi, 0.0, 0.0]).as_matrix()
    zero = np.zeros(3)
    goals = [Target(np.array([0.0, 0.1, 0.0]), facing, zero, zero),  # side by side: links 8 cm apart
             Target(np.array([0.0, 0.0, -0.35]), facing, zero, zero)]  # then through the left forearm
    never = DeferredRows.meets
    q = np.asarray(model.description.ready, dtype=float)
    deferred = built = 0
    closest = np.inf
    for k in range(800):
        target = goals[k // 400]
        mine = deferring.step(q, target)
        limit = deferring.limit("collision")
        assert isinstance(limit, CollisionLimit) and mine.collision is not None
        if mine.collision.rows:
            built += limit._rows.built
            deferred += not limit._rows.built
            closest = min(closest, mine.collision.distance)
        monkeypatch.setattr(DeferredRows, "meets", lambda self, qd: False)
        theirs = building.step(q, target)
        monkeypatch.setattr(DeferredRows, "meets", never)
        assert np.array_equal(mine.velocities, theirs.velocities)
        assert (mine.result.status, mine.result.detail, mine.collision) == (
            theirs.result.status, theirs.result.detail, theirs.collision)
        q = q + PERIOD * mine.velocities
    print(f"{solver}: cycles with rows deferred {deferred}, built {built}; closest pair {closest:.4f} m")
    assert deferred > 0 and built > 0  # both paths ran
    assert closest >= 0.03  # the limit held (d_s kept between the shapes, 1 mm margins each)
