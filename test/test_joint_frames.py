"""The joints' placements as one strided view of pinocchio's ``data.oMi`` (collision/placements.py): the same
values as read one by one, after every pass, on every robot; the fallback (read one by one) gives them too."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from dualarm_control.collision import CollisionModel
from dualarm_control.collision.placements import JointFrames
from dualarm_control.kinematics import DualArmModel


def one_by_one(data: pin.Data) -> np.ndarray:
    """[R^T; t^T] per joint from the 4x4 homogeneous matrices (another reading than the module's)."""
    h = np.array([p.homogeneous for p in data.oMi])
    return np.concatenate((h[:, :3, :3].transpose(0, 2, 1), h[:, None, :3, 3]), axis=1)


@pytest.mark.parametrize("robot", ["lwr4_cell", "baxter", "panda_pair"])
def test_the_view_follows_every_pass(robot: str) -> None:
    collision = CollisionModel(DualArmModel(robot))
    model = collision.model
    data = model.createData()
    frames = JointFrames(model, data)
    assert frames.view is not None, "the strided view was refused on this pinocchio"
    rng = np.random.default_rng(0)
    for _ in range(50):
        q = pin.integrate(model, pin.neutral(model), rng.uniform(-3.0, 3.0, model.nv))
        pin.computeJointJacobians(model, data, q)
        assert np.array_equal(frames.frames(), one_by_one(data))
        local = np.hstack((rng.normal(size=(model.njoints, 3)), np.ones((model.njoints, 1))))
        joints = np.arange(model.njoints)
        expected = np.array([data.oMi[j].act(local[j, :3]) for j in range(model.njoints)])
        assert np.allclose(frames.points(joints, local), expected, rtol=0.0, atol=1e-12)
    assert not frames.frames().flags.writeable


def test_the_fallback_reads_the_same() -> None:
    model = CollisionModel(DualArmModel("lwr4_cell")).model
    data = model.createData()
    frames = JointFrames(model, data)
    fallback = JointFrames(model, data)
    fallback.view = None
    pin.computeJointJacobians(model, data, pin.randomConfiguration(model))
    assert np.array_equal(fallback.frames(), frames.frames())
