"""Dual-arm relative kinematics (paper 000, Sect. II) with pinocchio.

Conventions: frame F1 is the left tool (the part with the hole), frame F2 the right tool
(the peg): the links ``left_tool`` and ``right_tool`` of the robot's resolved URDF
(:mod:`dualarm_control.robot`). The relative pose is the right tool in the left tool frame,
eq (1)-(2). Joint vector order: the robot description's left joints then its right joints, as
listed (the model is the arms' joints only; every other joint is locked).
Twists are ``[v; w]`` (m/s; rad/s), both expressed in F1.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pinocchio as pin

from dualarm_control.arrays import FloatArray
from dualarm_control.errors import DimensionError
from dualarm_control.robot import LEFT_TOOL, RIGHT_TOOL, RobotDescription
from dualarm_control.robot_files import RobotError
from dualarm_control.robot_params import load_robot


def skew(v: FloatArray) -> FloatArray:
    """Cross-product matrix S(v), so that S(v) @ w == np.cross(v, w). Shape (3,) -> (3, 3)."""
    x, y, z = v.tolist()
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def relative_jacobian(r_b1: FloatArray, p_r1: FloatArray, j1_b: FloatArray, j2_b: FloatArray) -> FloatArray:
    """Relative Jacobian of eq (5)-(6): J = [-Psi_r^1 Omega_b^1 J_1^b, Omega_b^1 J_2^b].

    Args:
        r_b1: R_1^b, orientation of F1 in the base frame, (3, 3).
        p_r1: p_r^1, position of F2 in F1 [m], (3,).
        j1_b, j2_b: geometric Jacobians of each tool in the base frame (linear velocity of
            the tool origin, angular velocity) over all n joints, (6, n) each; each arm's
            tool does not move with the other arm's joints, so J_1^b is zero in the right
            arm's columns and J_2^b in the left arm's (pinocchio's frame Jacobians are so).

    Returns:
        (6, n) matrix mapping joint velocities [rad/s] to the relative twist
        [v_r^1; w_r^1] of eq (4), expressed in F1. With Omega J = [R^T J_v; R^T J_w] and
        Psi = [[I, -S(p)], [0, I]]: J = Omega J_2 - Omega J_1 + [S(p) R^T J_w1; 0].
    """
    r_t = r_b1.T
    a = r_t @ j1_b.reshape(2, 3, -1)  # Omega_b^1 J_1^b as (linear, angular) blocks
    out = (r_t @ j2_b.reshape(2, 3, -1) - a).reshape(6, -1)
    out[:3] += skew(p_r1) @ a[1]  # -Psi_r^1 on the J_1 block: + p x w_1
    return out


def luh_orientation_error(r_actual: FloatArray, r_desired: FloatArray) -> FloatArray:
    """Orientation error of Luh et al., eq (10): e_o = 1/2 (n x n* + s x s* + a x a*).

    Computed in closed form: a x d is the vector of the skew matrix d a^T - a d^T, so the
    sum over the three columns is the vector of M - M^T with M = R* R^T.

    Args:
        r_actual: R_r^1, actual relative orientation, columns (n, s, a), (3, 3).
        r_desired: R_r^1*, desired relative orientation, (3, 3).

    Returns:
        (3,) error [rad-like, equal to sin(theta) u for a rotation theta about u], in F1.
    """
    return np.array(luh_components(r_actual, r_desired))


def luh_components(r_actual: FloatArray, r_desired: FloatArray) -> tuple[float, float, float]:
    """The three components of :func:`luh_orientation_error` as Python floats (no array built)."""
    (m0, m1, m2) = (r_desired @ r_actual.T).tolist()  # Python floats: cheaper than indexing the array
    return 0.5 * (m2[1] - m1[2]), 0.5 * (m0[2] - m2[0]), 0.5 * (m1[0] - m0[1])


def pose_error(p: FloatArray, r: FloatArray, p_des: FloatArray, r_des: FloatArray) -> FloatArray:
    """Task error e = [e_p; e_o] of eq (8)-(10), shape (6,), in F1."""
    return np.concatenate((p_des - p, luh_orientation_error(r, r_des)))


def rotation_angle(r_a: FloatArray, r_b: FloatArray) -> float:
    """Geodesic angle [rad] between two rotations, in [0, pi].

    theta = atan2(||vee(R - R^T)|| / 2, (trace R - 1) / 2) with R = R_a^T R_b: accurate to
    machine precision over the whole range (acos of the trace loses half the digits near 0
    and pi, ~2e-8 rad).
    """
    (r0, r1, r2) = (r_a.T @ r_b).tolist()
    c = (r0[0] + r1[1] + r2[2] - 1.0) / 2.0
    s = 0.5 * math.sqrt((r2[1] - r1[2]) ** 2 + (r0[2] - r2[0]) ** 2 + (r1[0] - r0[1]) ** 2)
    return math.atan2(s, c)


def jacobian_derivatives(jacobian: FloatArray) -> FloatArray:
    """Derivatives dJ/dq_k of the geometric Jacobian of a serial chain of revolute joints.

    For J = [J_v; J_w] at a point p in world axes (pinocchio LOCAL_WORLD_ALIGNED), column i
    is [z_i x (p - o_i); z_i] with z_i = J_w[:, i] the joint axis. Then (Jacobi identity)

        dJ_i/dq_k = [z_k x J_v,i ; z_k x z_i]   for k <= i,
        dJ_i/dq_k = [z_i x J_v,k ; 0]           for k > i,

    computed from J alone. Used for the gradient of the manipulability (paper 001, eq 10).

    Args:
        jacobian: J (6, m) of one chain, columns in chain order (base to tip).

    Returns:
        (m, 6, m) array D with D[k] = dJ/dq_k [m/rad per rad; 1/rad].
    """
    jv, jw = jacobian[:3], jacobian[3:]
    m = jacobian.shape[1]
    cross_v = _pairwise_cross(jw, jv)  # [k, :, i] = z_k x Jv_i
    cross_w = _pairwise_cross(jw, jw)  # [k, :, i] = z_k x z_i
    lower_v = np.transpose(cross_v, (2, 1, 0))  # [k, :, i] = cross_v[i, :, k] = z_i x Jv_k
    out = np.zeros((m, 6, m))
    mask = np.triu(np.ones((m, m), dtype=bool))[:, None, :]  # [k, :, i]: k <= i
    out[:, :3, :] = np.where(mask, cross_v, lower_v)
    out[:, 3:, :] = np.where(mask, cross_w, 0.0)
    return out


def _pairwise_cross(a: FloatArray, b: FloatArray) -> FloatArray:
    """c[k, :, i] = a[:, k] x b[:, i] for a (3, m) and b (3, p): shape (m, 3, p).

    Written out by components: np.cross with axis arguments costs several times more on
    these small arrays (it runs every control cycle)."""
    a0, a1, a2 = a[0][:, None], a[1][:, None], a[2][:, None]
    b0, b1, b2 = b[0][None, :], b[1][None, :], b[2][None, :]
    return np.stack((a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0), axis=1)


@dataclass(slots=True)
class FrameState:
    """World pose and geometric Jacobian of one frame at one configuration.

    A per-cycle record: slotted, not frozen (cheaper to build, docs/bench.md); read-only by convention.

    Attributes:
        position: origin in the world [m], (3,).
        rotation: axes in the world, (3, 3) (columns x, y, z).
        jacobian: (6, n) map from joint velocities to [v; w] of the frame origin in world
            axes (pinocchio LOCAL_WORLD_ALIGNED) [m/s; rad/s per rad/s].
    """

    position: FloatArray
    rotation: FloatArray
    jacobian: FloatArray


@dataclass(slots=True)
class RelativeState:
    """Relative kinematics at one configuration.

    A per-cycle record: slotted, not frozen (cheaper to build, docs/bench.md); read-only by convention.

    Attributes:
        position: p_r^1 [m], (3,).
        rotation: R_r^1, (3, 3).
        jacobian: relative Jacobian J of eq (5), (6, n).
    """

    position: FloatArray
    rotation: FloatArray
    jacobian: FloatArray


@dataclass
class DualArmModel:
    """Pinocchio model of the robot's two arms: joint names, limits and relative kinematics.

    Built from a robot description (a name of ``config/robots/``, a YAML path, or a
    :class:`~dualarm_control.robot.RobotDescription`; default ``lwr4_cell``): the resolved
    URDF's model reduced to the arms' joints (``pin.buildReducedModel``, every other movable
    joint locked at its description value), limits from the URDF. RobotError when the
    URDF's joint order is not the description's (each arm listed base to tip, left first).
    """

    robot: RobotDescription | str = field(default_factory=load_robot)

    def __post_init__(self) -> None:
        self.robot = robot = load_robot(self.robot)
        self.urdf: Path = robot.urdf_path
        full = pin.buildModelFromUrdf(str(self.urdf))
        locked = robot.locked_positions()
        if locked:
            q_ref = pin.neutral(full)
            for name, value in locked.items():
                joint = full.getJointId(name)
                if full.nqs[joint] != 1:
                    raise RobotError(f"robot {robot.name!r}: locked joint {name!r} has nq = {full.nqs[joint]}: "
                                     "give its value as a revolute joint's")
                q_ref[full.idx_qs[joint]] = value
            self.model = pin.buildReducedModel(full, [full.getJointId(n) for n in locked], q_ref)
        else:
            self.model = full
        self.data = self.model.createData()
        self.joint_names: list[str] = [self.model.names[i] for i in range(1, self.model.njoints)]
        if self.joint_names != robot.joint_names:
            raise RobotError(f"robot {robot.name!r}: the URDF orders the arms' joints {self.joint_names}, the "
                             f"description {robot.joint_names}: list each arm base to tip (pinocchio takes the "
                             "left arm first only if its branch sorts first: docs/robots.md)")
        if self.model.nq != self.model.nv:
            raise RobotError(f"robot {robot.name!r}: a joint with nq != nv (continuous) among the arms")
        self.nq: int = self.model.nq
        self.n_left: int = robot.n_left
        self.q_min: FloatArray = self.model.lowerPositionLimit.copy()
        self.q_max: FloatArray = self.model.upperPositionLimit.copy()
        self.qd_max: FloatArray = self.model.velocityLimit.copy()
        self._f1 = self.model.getFrameId(LEFT_TOOL)
        self._f2 = self.model.getFrameId(RIGHT_TOOL)
        self._frame_ids: dict[str, int] = {}
        self._owner: object | None = None  # the Configuration whose q is in self.data
        self.derived: dict[object, object] = {}
        """Objects built from this model once and shared by its users in this process (the collision
        models per allowed pairs: :meth:`dualarm_control.collision.CollisionModel.shared`)."""

    @property
    def description(self) -> RobotDescription:
        """The robot description the model was built from."""
        assert isinstance(self.robot, RobotDescription)
        return self.robot

    def frame_id(self, name: str) -> int:
        """Pinocchio frame id of ``name``; KeyError naming the frames of the arms' links."""
        fid = self._frame_ids.get(name)
        if fid is None:
            if not self.model.existFrame(name):
                links = sorted(f.name for f in self.model.frames if f.type == pin.FrameType.BODY)
                raise KeyError(f"unknown frame {name!r}; frames: {', '.join(links)}")
            fid = self._frame_ids[name] = self.model.getFrameId(name)
        return fid

    def arm_columns(self, side: str) -> slice:
        """Columns (joints) of one arm, ``"left"`` or ``"right"``, in the joint vector."""
        if side not in ("left", "right"):
            raise ValueError(f"arm side must be 'left' or 'right', got {side!r}")
        return slice(0, self.n_left) if side == "left" else slice(self.n_left, self.nq)

    @property
    def tool_frame_ids(self) -> tuple[int, int]:
        """Pinocchio frame ids of the left (F1) and right (F2) tool frames."""
        return self._f1, self._f2

    def relative_reach(self) -> float:
        """Upper bound of ||p_r^1|| over all configurations [m]: how far apart the tools can ever be.

        Triangle inequality along each arm's chain: the distance from an arm's first joint
        (fixed in the world) to its tool frame is at most the sum of the link offsets
        (joint placements after the first, then the tool frame's placement), whatever q is; so
        ||p_r|| <= ||o_left - o_right|| + reach_left + reach_right, with o the first joints'
        origins (||p_r^1|| is the tools' distance: the frame F1 does not change it). For the
        cell's URDF: 0.628 + 1.101 + 1.141 = 2.870 m (the largest of 20 000 random
        configurations: 2.54 m). A target farther than this cannot be reached.
        """
        total = 0.0
        origins = []
        for frame_id in self.tool_frame_ids:
            frame = self.model.frames[frame_id]
            total += float(np.linalg.norm(frame.placement.translation))
            joint = frame.parentJoint
            while self.model.parents[joint] != 0:
                total += float(np.linalg.norm(self.model.jointPlacements[joint].translation))
                joint = self.model.parents[joint]
            origins.append(self.model.jointPlacements[joint].translation)
        return total + float(np.linalg.norm(origins[0] - origins[1]))

    def check_q(self, q: FloatArray, what: str = "joint positions") -> FloatArray:
        """Return q as a float array of shape (nq,), or raise DimensionError naming the problem."""
        q = np.asarray(q, dtype=float)
        if q.shape != (self.nq,):
            raise DimensionError(f"{what}: expected {self.nq} values, got shape {q.shape}")
        return q

    def tool_poses(self, q: FloatArray) -> tuple[pin.SE3, pin.SE3]:
        """World poses of the left and right tool frames at q."""
        q = self.check_q(q)
        pin.framesForwardKinematics(self.model, self.data, q)
        self._owner = None  # a Configuration must recompute before reading self.data
        return self.data.oMf[self._f1].copy(), self.data.oMf[self._f2].copy()

    def frame_poses(self, q: FloatArray, names: tuple[str, ...]) -> tuple[pin.SE3, ...]:
        """World poses of the named frames at q."""
        q = self.check_q(q)
        ids = [self.frame_id(n) for n in names]
        pin.framesForwardKinematics(self.model, self.data, q)
        self._owner = None
        return tuple(self.data.oMf[i].copy() for i in ids)

    def relative_pose(self, q: FloatArray) -> tuple[FloatArray, FloatArray]:
        """(p_r^1, R_r^1) of eq (1)-(2) at q."""
        o1, o2 = self.tool_poses(q)
        rel = o1.actInv(o2)
        return rel.translation.copy(), rel.rotation.copy()

    def relative_state(self, q: FloatArray) -> RelativeState:
        """Relative pose and relative Jacobian (eq 5-6) at q, in one kinematics pass."""
        return Configuration(self, q).relative()


class Configuration:
    """Kinematics of the cell at one joint configuration (like pink's ``Configuration``).

    One pinocchio pass (joint Jacobians and frame placements) at construction; frame states
    and the relative state are then read on demand and cached. Every task of a control
    cycle reads the same Configuration. If another Configuration of the same model has
    overwritten the pinocchio data since, the pass is redone before reading.
    """

    def __init__(self, model: DualArmModel, q: FloatArray) -> None:
        self.model = model
        self.q = model.check_q(q)
        self._frames: dict[str, FrameState] = {}
        self._relative: RelativeState | None = None
        self._compute()

    def _compute(self) -> None:
        m = self.model
        pin.computeJointJacobians(m.model, m.data, self.q)
        pin.updateFramePlacements(m.model, m.data)
        m._owner = self

    def _data(self) -> pin.Data:
        if self.model._owner is not self:
            self._compute()
        return self.model.data

    def frame(self, name: str) -> FrameState:
        """World pose and Jacobian (6, n) of frame ``name`` (LOCAL_WORLD_ALIGNED)."""
        state = self._frames.get(name)
        if state is None:
            m = self.model
            fid = m.frame_id(name)
            data = self._data()
            jac = pin.getFrameJacobian(m.model, data, fid, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
            placement = data.oMf[fid]
            state = FrameState(placement.translation.copy(), placement.rotation.copy(), jac)
            self._frames[name] = state
        return state

    def relative(self) -> RelativeState:
        """Relative pose of F2 in F1 and relative Jacobian of eq (5)-(6) (paper 000)."""
        if self._relative is None:
            m = self.model
            data = self._data()
            frame = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
            j1 = pin.getFrameJacobian(m.model, data, m._f1, frame)
            j2 = pin.getFrameJacobian(m.model, data, m._f2, frame)
            o1, o2 = data.oMf[m._f1], data.oMf[m._f2]
            rel = o1.actInv(o2)
            p_r1 = rel.translation.copy()
            jac = relative_jacobian(o1.rotation, p_r1, j1, j2)
            self._relative = RelativeState(position=p_r1, rotation=rel.rotation.copy(), jacobian=jac)
        return self._relative
