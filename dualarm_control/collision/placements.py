"""The joints' placements in the world as one array, for the broadphases' bounding spheres.

After a forward-kinematics pass, pinocchio holds each joint's placement oMi = (R, t) in ``data.oMi``. Read
one by one (``[p.homogeneous for p in data.oMi]``) they cost 15-26 us a cycle for the LWR4 cell's 15 joints:
a Python object and a new array each. pinocchio lays ``data.oMi`` out as one contiguous vector of SE3
(R column-major, 9 doubles, then t, 3 doubles), and the arrays ``oMi[k].rotation`` and ``.translation``
are views into it that follow every later pass. :class:`JointFrames` keeps one strided, read-only view of
the whole vector,

    frames[k] = [R_k[:, 0]; R_k[:, 1]; R_k[:, 2]; t_k]        (joints, 4, 3)  [-, -, -, m]

so that a point c given in joint k's frame is at ``[c, 1] @ frames[k]`` = R_k c + t_k in the world. The
layout is checked against the placements read one by one when the view is made (after a pass at a
configuration with every joint turned); where it differs (another pinocchio), the frames are read one by
one instead: the same values, slower.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from dualarm_control.arrays import FloatArray

_DOUBLE = 8


def _address(array: np.ndarray) -> int:
    return int(array.__array_interface__["data"][0])


def _frames_one_by_one(data: pin.Data) -> FloatArray:
    """(joints, 4, 3): each joint's [R^T; t^T] from ``data.oMi``, read element by element."""
    return np.array([np.vstack((p.rotation.T, p.translation)) for p in data.oMi])


def _strided_view(model: pin.Model, data: pin.Data) -> FloatArray | None:
    """The view of the module docstring over ``data.oMi``, or None where pinocchio's layout is not the one
    expected (checked on addresses, then on values after a pass at a configuration with every joint turned)."""
    placements = list(data.oMi)
    first = placements[0].rotation
    if first.dtype != np.float64 or first.strides != (_DOUBLE, 3 * _DOUBLE):  # (the universe joint is always there)
        return None
    base = _address(first)
    stride = _address(placements[1].rotation) - base if len(placements) > 1 else 12 * _DOUBLE
    for k, p in enumerate(placements):
        if (_address(p.rotation) != base + k * stride or _address(p.translation) != base + k * stride + 9 * _DOUBLE
                or p.translation.strides != (_DOUBLE,)):
            return None
    view = np.lib.stride_tricks.as_strided(first, shape=(len(placements), 4, 3),
                                           strides=(stride, 3 * _DOUBLE, _DOUBLE), writeable=False)
    pin.forwardKinematics(model, data, pin.integrate(model, pin.neutral(model), np.linspace(0.3, 0.7, model.nv)))
    return view if np.array_equal(view, _frames_one_by_one(data)) else None


class JointFrames:
    """Every joint's placement in the world after the last forward-kinematics pass on ``data``, as one
    (joints, 4, 3) array (module docstring).

    Args:
        model: the pinocchio model of ``data``.
        data: the data whose ``oMi`` the passes fill (a pass at a test configuration is run on it here).
    """

    def __init__(self, model: pin.Model, data: pin.Data) -> None:
        self.data = data
        self.view = _strided_view(model, data)
        """The strided view, or None where the placements are read one by one."""

    def frames(self) -> FloatArray:
        """(joints, 4, 3): [R_k^T; t_k^T] of every joint k at the last pass (the view itself: read it before
        the next pass, never write it)."""
        return self.view if self.view is not None else _frames_one_by_one(self.data)

    def points(self, joints: np.ndarray, local: FloatArray) -> FloatArray:
        """Points given in their joints' frames, in the world [m], (m, 3): ``local`` (m, 4) homogeneous [m],
        ``joints`` (m,) their joint indices."""
        return np.einsum("mk,mkd->md", local, self.frames()[joints])


class SphereGaps:
    """Lower bounds [m] of shape pairs' distances at the last pass: ||c_a - c_b|| - r_a - r_b, with c, r each shape's
    bounding sphere (the broadphase of :class:`~dualarm_control.collision.CollisionModel`).

    c_a - c_b of every pair at once is one matrix product on the joints' frames, (joints * 4, 3): a centre c_s given in
    its joint j's frame is ``[c_s, 1] @ frames[j]``, linear in the frames, so row p of M holds [c_a, 1] at a's joint and
    -[c_b, 1] at b's. Cheaper than placing the centres and gathering the pairs asked for (the LWR4 cell's 226 shape
    pairs: 10 against 20 us).

    Args:
        frames: the joints' placements. shape_joint: each shape's joint, (shapes,).
        centres: each shape's sphere centre in its joint's frame [m], (shapes, 3). radii: their radii [m], (shapes,).
        shape_a, shape_b: each pair's two shapes, (pairs,).
    """

    def __init__(self, frames: JointFrames, shape_joint: np.ndarray, centres: FloatArray, radii: FloatArray,
                 shape_a: np.ndarray, shape_b: np.ndarray) -> None:
        self.frames = frames
        homogeneous = np.hstack((centres, np.ones((len(centres), 1))))
        matrix = np.zeros((len(shape_a), len(frames.data.oMi), 4))
        for p, (a, b) in enumerate(zip(shape_a.tolist(), shape_b.tolist())):
            matrix[p, shape_joint[a]] += homogeneous[a]
            matrix[p, shape_joint[b]] -= homogeneous[b]
        self._matrix = matrix.reshape(len(shape_a), -1)
        self._radii = radii[shape_a] + radii[shape_b]  # r_a + r_b per pair

    def bounds(self, pairs: np.ndarray) -> FloatArray:
        """The bounds [m] of ``pairs`` (indices, (k,)) at the last pass on the frames' data, (k,)."""
        gap = self._matrix @ self.frames.frames().reshape(-1, 3)
        result: FloatArray = (np.sqrt(np.einsum("pk,pk->p", gap, gap)) - self._radii)[pairs]
        return result
