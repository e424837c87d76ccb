"""A box held by both tools of the simulated cell, and the wrist force/torque sensors (issue 41, item 2).

The object is a pybullet box (``createMultiBody`` with a box collision shape, so that it has the inertia of a
solid box: I = m/12 diag(b^2 + c^2, a^2 + c^2, a^2 + b^2) for the edge lengths (a, b, c) [m]) placed at the
grasp frame (its pose in the left tool frame, ``grasp``) and held by two ``JOINT_FIXED`` constraints, one to
each tool link, each made where the tool is when the grasp closes (no squeeze at the start). The box collides
with nothing of the robot (``setCollisionFilterPair`` with every link: it sits between the hands and a box
created overlapping a link makes pybullet push it out, 1.7e5 N measured; cooperative-notes.md) but it does
with the cell's obstacles. A constraint's force limit is ``max_force`` (pybullet's default 500 N or N m lets a
heavy or squeezed object slip without a word).

Wrist F/T sensors: pybullet's joint force/torque sensors on the tools' fixed joints (``left_tool_joint``,
``right_tool_joint``). Sign and frame convention (tested, test/test_held_object.py): a reading
[Fx, Fy, Fz, Mx, My, Mz] is the wrench the flange exerts on the tool link, about the tool frame's origin,
in the tool frame [N, N m]. The wrench the hand exerts on the held object is then, in the world,
f = R_tool f_s, m = R_tool m_s (the tool links weigh 1 g: 0.0098 N each). At rest the two readings rotated
into the world sum to (m_box + 2 m_tool) g upwards.

``WristSensors`` adds what a real sensor adds: a constant bias per axis and white noise (seeded).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pybullet as p

from dualarm_control.arrays import FloatArray
from dualarm_control.robot import LEFT_TOOL, RIGHT_TOOL, TOOL_JOINTS

SIDES = (LEFT_TOOL, RIGHT_TOOL)


def _finite(name: str, values: tuple[float, ...], size: int) -> None:
    if len(values) != size or not all(isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
                                      for v in values):
        raise ValueError(f"{name} must be {size} finite numbers, got {values!r}")


@dataclass(frozen=True)
class HeldObjectConfig:
    """A box held by both tools (scenario key ``held_object``).

    Attributes:
        mass: m [kg], > 0.
        size: edge lengths (a, b, c) [m] along the object frame's x, y, z, each > 0.
        grasp_position: the object frame's origin (the box centre) in the left tool frame [m], (3,).
        grasp_rpy_deg: the object frame's orientation in the left tool frame (roll, pitch, yaw) [deg].
        max_force: each grasp constraint's force (and torque) limit [N, N m], > 0.
        grasp_time: sim time [s] the hands close on the box, >= 0; before it a fixture holds the box where it
            is (a fixed constraint to the world) and the hands are empty (the sensors read their bias).
        position: the box centre's world position at the start [m], (3,), or () (the default): at the grasp of
            the left tool's start pose. rpy_deg: its world orientation then (with ``position``) [deg].
        resting: no fixture: the box rests on what is under it (a support obstacle) until the grasp.
        release_time: sim time [s] the hands open (the grasp constraints are removed: the box stays where it
            was put), > ``grasp_time``; inf (the default): never.
    """

    mass: float = 2.0
    size: tuple[float, float, float] = (0.1, 0.1, 0.2)
    grasp_position: tuple[float, float, float] = (0.0, 0.0, 0.15)
    grasp_rpy_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)
    max_force: float = 1.0e5
    grasp_time: float = 0.0
    position: tuple[float, ...] = ()
    rpy_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)
    resting: bool = False
    release_time: float = math.inf

    def __post_init__(self) -> None:
        _finite("mass", (self.mass,), 1)
        if self.position:
            _finite("position", tuple(self.position), 3)
        _finite("rpy_deg", tuple(self.rpy_deg), 3)
        if not isinstance(self.resting, bool):
            raise TypeError(f"resting must be true or false, got {self.resting!r}")
        if isinstance(self.release_time, bool) or not isinstance(self.release_time, int | float) \
                or math.isnan(self.release_time) or self.release_time <= self.grasp_time:
            raise ValueError(f"release_time must be a time [s] after grasp_time ({self.grasp_time}), got "
                             f"{self.release_time!r}")
        _finite("grasp_time", (self.grasp_time,), 1)
        if self.grasp_time < 0:
            raise ValueError(f"grasp_time must be >= 0 [s], got {self.grasp_time}")
        _finite("size", tuple(self.size), 3)
        _finite("grasp_position", tuple(self.grasp_position), 3)
        _finite("grasp_rpy_deg", tuple(self.grasp_rpy_deg), 3)
        _finite("max_force", (self.max_force,), 1)
        if self.mass <= 0:
            raise ValueError(f"mass must be > 0 [kg], got {self.mass}")
        if min(self.size) <= 0:
            raise ValueError(f"size must be 3 edge lengths > 0 [m], got {self.size!r}")
        if self.max_force <= 0:
            raise ValueError(f"max_force must be > 0 [N], got {self.max_force}")

    @property
    def inertia(self) -> FloatArray:
        """Principal moments of the solid box about its centre [kg m^2], (3,): m/12 (b^2 + c^2, ...)."""
        a, b, c = self.size
        return self.mass / 12.0 * np.array((b * b + c * c, a * a + c * c, a * a + b * b))


@dataclass(frozen=True)
class WristSensorConfig:
    """The wrist F/T sensors' imperfections (scenario key ``wrist_sensors``).

    Attributes:
        noise_std: white noise on each force axis [N], >= 0. torque_noise_std: on each torque axis [N m], >= 0.
        left_bias, right_bias: constant offsets added to each sensor's reading [N, N m], (6,) each.
        seed: the noise's seed.
    """

    noise_std: float = 0.0
    torque_noise_std: float = 0.0
    left_bias: tuple[float, ...] = (0.0,) * 6
    right_bias: tuple[float, ...] = (0.0,) * 6
    seed: int = 0

    def __post_init__(self) -> None:
        _finite("noise_std", (self.noise_std,), 1)
        _finite("torque_noise_std", (self.torque_noise_std,), 1)
        _finite("left_bias", tuple(self.left_bias), 6)
        _finite("right_bias", tuple(self.right_bias), 6)
        if self.noise_std < 0 or self.torque_noise_std < 0:
            raise ValueError(f"noise_std and torque_noise_std must be >= 0, got {self.noise_std}, "
                             f"{self.torque_noise_std}")
        if not isinstance(self.seed, int) or isinstance(self.seed, bool):
            raise TypeError(f"seed must be an integer, got {self.seed!r}")


def _pose_matrix(position: FloatArray, rotation: FloatArray) -> FloatArray:
    out = np.eye(4)
    out[:3, :3], out[:3, 3] = rotation, position
    return out


def _quaternion(rotation: FloatArray) -> tuple[float, float, float, float]:
    """pybullet's (x, y, z, w) quaternion of a rotation matrix (3, 3)."""
    import pinocchio as pin

    q = pin.Quaternion(np.asarray(rotation, float))
    return (q.x, q.y, q.z, q.w)


def _rotation(quaternion: tuple[float, ...]) -> FloatArray:
    return np.array(p.getMatrixFromQuaternion(quaternion)).reshape(3, 3)


class HeldObject:
    """The box of a :class:`HeldObjectConfig` in a pybullet client, held by both tools of ``body``.

    Args:
        client: pybullet client id. body: the robot's body id. links: the robot's link indices by name
        (the tools must be there). n_links: the robot's link count (every link is filtered against the box).
    """

    def __init__(self, config: HeldObjectConfig, client: int, body: int, links: dict[str, int], n_links: int) -> None:
        import pinocchio as pin

        self.config = config
        self._cid, self._robot = client, body
        missing = [t for t in SIDES if t not in links]
        if missing:
            raise ValueError(f"held_object: the robot has no tool link {', '.join(missing)}")
        self._tools = {t: links[t] for t in SIDES}
        grasp = _pose_matrix(np.array(config.grasp_position, float),
                             pin.rpy.rpyToMatrix(*np.radians(np.array(config.grasp_rpy_deg, float))))
        world = self.tool_matrix(LEFT_TOOL) @ grasp
        if config.position:  # a box placed in the cell (on a support), not at the hands
            world = _pose_matrix(np.array(config.position, float),
                                 pin.rpy.rpyToMatrix(*np.radians(np.array(config.rpy_deg, float))))
        half = [0.5 * s for s in config.size]
        shape = p.createCollisionShape(p.GEOM_BOX, halfExtents=half, physicsClientId=client)
        visual = p.createVisualShape(p.GEOM_BOX, halfExtents=half, rgbaColor=(0.2, 0.5, 0.9, 1), physicsClientId=client)
        self.body = int(p.createMultiBody(config.mass, shape, visual, basePosition=world[:3, 3].tolist(),
                                          baseOrientation=_quaternion(world[:3, :3]), physicsClientId=client))
        for link in range(-1, n_links):  # filtered before the first step: the box may overlap the hands
            p.setCollisionFilterPair(body, self.body, link, -1, 0, physicsClientId=client)
        p.changeDynamics(self.body, -1, localInertiaDiagonal=config.inertia.tolist(), linearDamping=0.0,
                         angularDamping=0.0, physicsClientId=client)
        self.constraints: dict[str, int] = {}
        self._fixture: int | None = None
        self.released = False
        self._waiting = config.grasp_time > 0
        if self._waiting and not config.resting:
            self._fixture = int(p.createConstraint(self.body, -1, -1, -1, p.JOINT_FIXED, (0.0, 0.0, 0.0),
                                                   (0.0, 0.0, 0.0), world[:3, 3].tolist(),
                                                   childFrameOrientation=_quaternion(world[:3, :3]),
                                                   physicsClientId=client))
            p.changeConstraint(self._fixture, maxForce=config.max_force, physicsClientId=client)
        elif not self._waiting:
            self.grasp()
        for tool in SIDES:
            p.enableJointForceTorqueSensor(body, self._tool_joint(tool), True, physicsClientId=client)

    def _tool_joint(self, tool: str) -> int:
        name = TOOL_JOINTS[tool].encode()
        for j in range(p.getNumJoints(self._robot, physicsClientId=self._cid)):
            if p.getJointInfo(self._robot, j, physicsClientId=self._cid)[1] == name:
                return j
        raise ValueError(f"held_object: the robot has no joint {TOOL_JOINTS[tool]!r}")

    def tool_matrix(self, tool: str) -> FloatArray:
        """World pose (4, 4) of a tool link's frame (pybullet's forward kinematics)."""
        state = p.getLinkState(self._robot, self._tools[tool], computeForwardKinematics=True,
                               physicsClientId=self._cid)
        return _pose_matrix(np.array(state[4]), _rotation(state[5]))

    def object_matrix(self) -> FloatArray:
        """World pose (4, 4) of the object frame (the box centre)."""
        position, orientation = p.getBasePositionAndOrientation(self.body, physicsClientId=self._cid)
        return _pose_matrix(np.array(position), _rotation(orientation))

    def pose_vector(self) -> FloatArray:
        """The box centre's world pose as pybullet gives it: (x, y, z [m], qx, qy, qz, qw), (7,)."""
        position, orientation = p.getBasePositionAndOrientation(self.body, physicsClientId=self._cid)
        return np.array((*position, *orientation), dtype=float)

    @property
    def grasped(self) -> bool:
        """Whether the hands hold the box."""
        return bool(self.constraints)

    @property
    def waiting(self) -> bool:
        """Whether the box is still on its fixture (or support), the hands not yet closed (``grasp_time``)."""
        return self._waiting

    def grasp(self) -> None:
        """Close both hands on the box where it is now (no squeeze) and remove the fixture."""
        if self.grasped:
            return
        world = self.object_matrix()
        self.constraints = {tool: self._grasp(link, world) for tool, link in self._tools.items()}
        self._waiting = False
        if self._fixture is not None:
            p.removeConstraint(self._fixture, physicsClientId=self._cid)
            self._fixture = None

    def _grasp(self, link: int, world: FloatArray) -> int:
        """A fixed constraint from the tool link to the box where the box is now; pybullet's joint frames are
        given in each body's centre-of-mass frame (the tool link's inertial frame, the box's centre)."""
        cid = self._cid
        state = p.getLinkState(self._robot, link, computeForwardKinematics=True, physicsClientId=cid)
        com = _pose_matrix(np.array(state[0]), _rotation(state[1]))
        in_com = np.linalg.inv(com) @ world  # the box frame in the tool's centre-of-mass frame
        constraint = int(p.createConstraint(self._robot, link, self.body, -1, p.JOINT_FIXED, (0.0, 0.0, 0.0),
                                            parentFramePosition=in_com[:3, 3].tolist(),
                                            childFramePosition=(0.0, 0.0, 0.0),
                                            parentFrameOrientation=_quaternion(in_com[:3, :3]),
                                            childFrameOrientation=(0.0, 0.0, 0.0, 1.0), physicsClientId=cid))
        p.changeConstraint(constraint, maxForce=self.config.max_force, physicsClientId=cid)
        return constraint

    def readings(self) -> FloatArray:
        """Both wrist sensors' raw readings (module docstring), (2, 6): left, then right [N, N m]."""
        return np.array([p.getJointState(self._robot, self._tool_joint_index[t], physicsClientId=self._cid)[2]
                         for t in SIDES], dtype=float)

    @property
    def _tool_joint_index(self) -> dict[str, int]:
        if not hasattr(self, "_joint_cache"):
            self._joint_cache = {t: self._tool_joint(t) for t in SIDES}
        return self._joint_cache

    def constraint_wrenches(self) -> FloatArray:
        """Each grasp constraint's own force and torque (``getConstraintState``), (2, 6): a second reading."""
        return np.array([p.getConstraintState(self.constraints[t], physicsClientId=self._cid) for t in SIDES])

    def release(self) -> None:
        """Open both hands: remove the constraints (the box falls, or stays on what it was put on)."""
        for c in self.constraints.values():
            p.removeConstraint(c, physicsClientId=self._cid)
        self.released = self.released or bool(self.constraints)
        self.constraints = {}

    def remove(self) -> None:
        """Release and delete the box (a cell's reset grasps a new one)."""
        self.release()
        if self._fixture is not None:
            p.removeConstraint(self._fixture, physicsClientId=self._cid)
        p.removeBody(self.body, physicsClientId=self._cid)


@dataclass
class WristSensors:
    """Bias and noise of the two wrist sensors (:class:`WristSensorConfig`), applied to raw readings (2, 6)."""

    config: WristSensorConfig = field(default_factory=WristSensorConfig)

    def __post_init__(self) -> None:
        self._rng = np.random.default_rng(self.config.seed)
        c = self.config
        self._sigma = np.array([c.noise_std] * 3 + [c.torque_noise_std] * 3)
        self._bias = np.array((c.left_bias, c.right_bias), dtype=float)

    def measure(self, raw: FloatArray) -> FloatArray:
        """raw (2, 6) + bias + noise [N, N m], (2, 6)."""
        noise = self._sigma * self._rng.standard_normal((2, 6)) if self._sigma.any() else 0.0
        return np.asarray(raw, float) + self._bias + noise
