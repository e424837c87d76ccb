"""Step-driven pybullet simulation of the dual-arm cell, velocity-commanded like KUKA FRI.

One :meth:`DualArmCell.step` advances exactly one control period (default 5 ms) made of
``physics_rate_hz * control_period`` physics substeps. The arms follow joint velocity
commands as a KUKA FRI robot does: the command is integrated into a joint position
reference, which the robot's own joint position controller holds (see below). The state
returned is read back from the physics (``getJointStates``), never taken from the
reference. Real-time pacing is left to the caller (the ROS node), so the class also runs
in lockstep in tests.

Physics choices (all measured on ``urdf/dualarm_cell.urdf``):

* Joint position control: every physics substep the velocity motors
  (``VELOCITY_CONTROL``) get the target q̇_cmd + position_gain (q_ref - q) / Δt_phys,
  clipped to the URDF velocity limits, where q_ref is the integrated command at the start
  of the substep and q the measured position (pybullet's own ``POSITION_CONTROL`` with
  velocity gain 1 computes the same target, but without the velocity limit). At the
  default ``position_gain`` 1 the reference's position error is removed in one substep
  when the motor's force allows. q_ref advances by q̇_cmd Δt_phys per substep, stays inside
  the joint limits and within ``MAX_LAG`` of the measured position (no wind-up against an
  obstacle). At zero command the arms hold their position under gravity: a 6e-7 rad offset
  and no drift over 60 s. With the bare velocity motors used before, every joint sagged at
  a constant velocity error of about 6e-4 rad/s (3.6e-2 rad in 60 s at zero command) and
  lagged its integrated command by 1.5e-4 rad 0.1 s into a 0.5 rad/s step (now 7e-7 rad).
* Motor forces are ``motor_force_scale`` (default 10) times the URDF effort limits. The
  upstream controller is kinematic and expects FRI-like behaviour, where the robot's own
  high-gain joint controller makes joints follow the commanded velocity. With the bare
  URDF efforts the shoulder joints (2 and 4) saturate for about 15 ms after a 0.5 rad/s
  step under gravity; at 10x the joints are within 1e-4 rad/s of a 0.5 rad/s step after one
  5 ms period (right joint 2 saturates in the first 1 ms substep and catches up its 1.5e-4
  rad lag in the next).
* The constraint solver runs 20 iterations per substep (``CellConfig.solver_iterations``;
  pybullet's default 50): a step takes 0.07 instead of 0.10 ms here. The figures stay: the
  velocity step above, Table I l0 12.524 / 3.998 / 5.397 (5.396 at 50), tracking errors
  within 1 %, the pan-cleaning force variant's force and circle metrics equal in the printed
  digits. At 10 iterations a 0.5 rad/s step reached only 0.485 rad/s after 5 ms (joint 6).
* Link linear/angular damping (pybullet defaults 0.04) is set to 0; the URDF joint damping
  (0.5 N m s/rad) is kept, the motors overcome it.
* Inertias come from the URDF (``URDF_USE_INERTIA_FROM_FILE``), as in pinocchio.
* Contacts between the arms and intended contacts (the brush on the pan): only the link pairs the
  controller's collision model checks, and the scenario's contact pairs, collide
  (:mod:`dualarm_sim.collision_filter` says how and why).
* ``CellConfig.table_height`` adds a table: a static 1.2 x 1.6 x 0.05 m box in front of the
  torso (centre at x = 0.7 m, clear of the torso) whose top is at that world height; it collides with every link.
* ``CellConfig.obstacles`` (a scenario's ``obstacles``, :mod:`dualarm_control.obstacles`; docs/obstacles.md):
  one static body each (:mod:`dualarm_sim.obstacles`), colliding with every link. An obstacle named
  ``table`` is the table of :meth:`DualArmCell.table_contacts` when ``table_height`` is None.
* Joint position limits ARE enforced by pybullet (it creates joint-limit constraints from
  the URDF ``<limit>``, also in velocity mode): a joint commanded past its limit stops
  there (overshoot of a few 1e-5 rad). Keeping away from the limits is still the
  controller's job.
"""

from __future__ import annotations

import contextlib
import math
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING

import numpy as np
import pybullet as p

from dualarm_control.arrays import FloatArray
from dualarm_control.errors import DimensionError
from dualarm_control.robot import RIGHT_TOOL, TOOL_JOINTS
from dualarm_sim.cell_config import CellConfig
from dualarm_sim.collision_filter import filter_link_pairs
from dualarm_sim.held_object import (
    HeldObject,
    WristSensors,
)
from dualarm_sim.obstacles import add_obstacle_bodies, add_table
from dualarm_sim.samples import CommandReport, JointSample

if TYPE_CHECKING:  # typing.Self is 3.11+ but ROS Humble runs 3.10: type-checking only
    from typing import Self


SENSOR_JOINT = TOOL_JOINTS[RIGHT_TOOL]
"""The F/T sensor: the fixed joint of F2 (every resolved URDF has it, :mod:`dualarm_control.robot`)."""
MAX_LAG = 0.01
"""Largest distance [rad] the position reference may run ahead of (or behind) a joint that does not
follow it (an obstacle, a saturated motor); about 5x a joint's motion in one substep at 2 rad/s."""
CONTACT_DISTANCE = 0.0
"""A contact point counts as a contact at a distance <= this [m] (pybullet also keeps points up to
its contact threshold apart, which the solver gives zero impulse)."""


def _readonly(a: FloatArray) -> FloatArray:
    a.setflags(write=False)
    return a


class DualArmCell:
    """The simulated cell: two 7-DOF arms, joint velocity commands in, joint states out.

    Each instance owns its own pybullet DIRECT client, so several cells can coexist in a
    process. Usage::

        with DualArmCell() as cell:
            report = cell.apply_command(qd)    # once per control period
            sample = cell.step()              # advance one period, read the physics

    A command stays in force for ``command_timeout`` of sim time; with no fresher command
    the arms are commanded to zero velocity and :attr:`timed_out` becomes True.
    Before the first command the arms hold their position (zero velocity command, not a time-out).
    """

    _last_q: FloatArray | None
    """The joints' positions as :meth:`state` last read them, until anything moves them (the next step reuses them)."""

    def __init__(self, config: CellConfig | None = None, initial_positions: FloatArray | None = None) -> None:
        """Connect a DIRECT pybullet client, load the URDF and reset to ``initial_positions``.

        Args:
            config: simulation settings (defaults to ``CellConfig()``).
            initial_positions: joint positions [rad], (n,); zeros (clipped into each joint's range) if None.
        """
        self.config = config if config is not None else CellConfig()
        if not Path(self.config.urdf).is_file():
            raise FileNotFoundError(f"cell URDF not found: {self.config.urdf}")
        cid = p.connect(p.DIRECT)
        if cid < 0:
            raise RuntimeError("pybullet: could not create a DIRECT physics client")
        self._cid: int | None = cid
        try:
            self._load()
            # default: zero, or the nearest point of a joint's range that excludes zero
            self.reset(np.clip(np.zeros(len(self.joint_names)), self._q_min, self._q_max)
                       if initial_positions is None else initial_positions)
        except BaseException:
            self.close()
            raise

    # ---- setup -------------------------------------------------------------------------
    def _load(self) -> None:
        cid = self._client
        p.setGravity(0.0, 0.0, self.config.gravity, physicsClientId=cid)
        p.setPhysicsEngineParameter(fixedTimeStep=self.config.physics_dt, numSubSteps=0,
                                    numSolverIterations=self.config.solver_iterations, physicsClientId=cid)
        contacts = bool(self.config.contact_pairs or self.config.collision_pairs)
        flags = (p.URDF_USE_INERTIA_FROM_FILE | (p.URDF_USE_SELF_COLLISION if contacts else 0)
                 | (0 if self.config.visual_shapes else p.URDF_IGNORE_VISUAL_SHAPES))
        self._body = p.loadURDF(str(self.config.urdf), useFixedBase=True, flags=flags, physicsClientId=cid)
        n_joints = p.getNumJoints(self._body, physicsClientId=cid)
        infos = [p.getJointInfo(self._body, j, physicsClientId=cid) for j in range(n_joints)]
        self._joint_index = {info[1].decode(): j for j, info in enumerate(infos)}
        self._link_index = {p.getBodyInfo(self._body, physicsClientId=cid)[0].decode(): -1}  # the base: -1
        self._link_index.update({info[12].decode(): j for j, info in enumerate(infos)})
        movable = [j for j, info in enumerate(infos) if info[2] != p.JOINT_FIXED]
        if self.config.joints:
            unknown = [n for n in self.config.joints if n not in self._joint_index
                       or infos[self._joint_index[n]][2] == p.JOINT_FIXED]
            if unknown:
                raise ValueError(f"cell joints not movable in {self.config.urdf}: {', '.join(unknown)}")
            movable = [self._joint_index[n] for n in self.config.joints]
        self.joint_names: list[str] = [infos[j][1].decode() for j in movable]
        self._idx = movable
        self._q_min = _readonly(np.array([infos[j][8] for j in movable]))
        self._q_max = _readonly(np.array([infos[j][9] for j in movable]))
        self._effort = _readonly(np.array([infos[j][10] for j in movable]))
        self._qd_max = _readonly(np.array([infos[j][11] for j in movable]))
        self._forces = (self.config.motor_force_scale * self._effort).tolist()
        for link in range(-1, len(infos)):
            p.changeDynamics(self._body, link, linearDamping=0.0, angularDamping=0.0, physicsClientId=cid)
        self._hold(infos)
        self._table: int | None = None
        self._pair_names: dict[tuple[int, int], tuple[str, str]] = {}  # counted pairs, both index orders
        self.collision_pairs: list[tuple[str, str]] = []
        """The link pairs that collide and are counted (``config.collision_pairs``)."""
        if contacts:
            self._pair_names = filter_link_pairs(self._body, cid, self._link_index, self.config, len(infos))
            self.collision_pairs = list(dict.fromkeys(self._pair_names.values()))
        if self.config.table_height is not None:
            self._table = add_table(self.config.table_height, cid)
        self.obstacle_bodies: dict[str, int] = add_obstacle_bodies(self.config.obstacles, cid)
        """The obstacles' pybullet body ids by name (``config.obstacles``)."""
        if self._table is None:
            self._table = self.obstacle_bodies.get("table")
        self.grasp_on_motion = False
        """A held object's ``grasp_time`` counts from the first non-zero command, not from the reset
        (:meth:`count_grasp_from_motion`)."""
        self.held_object: HeldObject | None = None
        """The held box (``config.held_object``), grasped at every :meth:`reset`."""
        self._wrist = WristSensors(self.config.wrist_sensors)
        self._sensor = self._joint_index.get(SENSOR_JOINT)
        if self._sensor is not None:
            p.enableJointForceTorqueSensor(self._body, self._sensor, True, physicsClientId=cid)

    def _hold(self, infos: list[tuple[object, ...]]) -> None:
        """The held joints: teleported to their positions and held there by position control."""
        names = [n for n, _ in self.config.held]
        unknown = [n for n in names if n not in self._joint_index]
        if unknown:
            raise ValueError(f"held joints not in {self.config.urdf}: {', '.join(unknown)}")
        self._held_idx = [self._joint_index[n] for n in names]
        self._held_q = [float(v) for _, v in self.config.held]
        self.held_names: list[str] = names
        if not names:
            return
        forces = [max(self.config.motor_force_scale * float(infos[j][10]), 1.0) for j in self._held_idx]  # type: ignore[arg-type]
        p.setJointMotorControlArray(self._body, self._held_idx, p.POSITION_CONTROL, targetPositions=self._held_q,
                                    forces=forces, physicsClientId=self._client)

    def contact_force(self, link_a: str, link_b: str) -> float:
        """Sum of the normal contact forces between two links of the cell [N] (last substep)."""
        a, b = self._link_index[link_a], self._link_index[link_b]
        points = p.getContactPoints(self._body, self._body, a, b, physicsClientId=self._client)
        return float(sum(c[9] for c in points))

    def contacts(self) -> dict[tuple[str, str], float]:
        """The counted link pairs (:attr:`collision_pairs`) in contact after the last step, each
        with its deepest contact point's distance [m] (<= 0: minus the penetration depth), from
        the last physics substep (one ``getContactPoints`` call). Empty before the first step
        after a reset, and when the cell has no collision pairs."""
        if not self._stepped or not self._pair_names:
            return {}
        out: dict[tuple[str, str], float] = {}
        names = self._pair_names
        for c in p.getContactPoints(self._body, self._body, physicsClientId=self._client):
            if c[8] > CONTACT_DISTANCE:
                continue
            a, b = c[3], c[4]
            pair = names.get((a, b) if a < b else (b, a))
            if pair is not None and c[8] < out.get(pair, math.inf):
                out[pair] = float(c[8])
        return out

    def link_index(self, link: str) -> int:
        """pybullet's link index of a URDF link in :attr:`body_id` (-1 for the base; KeyError
        naming the link otherwise)."""
        if link not in self._link_index:
            raise KeyError(f"unknown link {link!r} in {self.config.urdf.name}")
        return self._link_index[link]

    def pose(self, positions: FloatArray) -> None:
        """Teleport the commanded joints to ``positions`` [rad], (n,), for inspection (distances,
        drawing): no limit check, the reference, command and sim time are kept (a simulation
        restarts with :meth:`reset`). DimensionError for a wrong shape, ValueError if not finite."""
        q = self._check_vector(positions, "pose positions")
        if not np.isfinite(q).all():
            raise ValueError(f"pose positions must be finite, got {q.tolist()}")
        self._last_q = None
        for j, qj in zip(self._idx, q.tolist()):
            p.resetJointState(self._body, j, qj, 0.0, physicsClientId=self._client)

    def table_contacts(self) -> int:
        """Number of contact points between the cell and the table (0 without a table)."""
        if self._table is None:
            return 0
        return len(p.getContactPoints(self._body, self._table, physicsClientId=self._client))

    def _require_open(self) -> int:
        """Return the pybullet client id; raise RuntimeError once the cell is closed."""
        if self._cid is None:
            raise RuntimeError("DualArmCell is closed")
        return self._cid

    @property
    def _client(self) -> int:
        return self._require_open()

    # ---- read-only properties ----------------------------------------------------------
    @property
    def client_id(self) -> int:
        """pybullet physics client id (for inspection/visualisation; do not step it directly)."""
        return self._client

    @property
    def body_id(self) -> int:
        """pybullet body id of the cell in :attr:`client_id`."""
        return self._body

    @property
    def position_limits(self) -> tuple[FloatArray, FloatArray]:
        """(lower, upper) joint position limits [rad], each (14,), from the URDF."""
        return self._q_min, self._q_max

    @property
    def velocity_limits(self) -> FloatArray:
        """Joint velocity limits [rad/s], (14,), from the URDF; commands are clipped to them."""
        return self._qd_max

    @property
    def effort_limits(self) -> FloatArray:
        """URDF joint effort limits [N m], (14,) (motor forces are these times motor_force_scale)."""
        return self._effort

    @property
    def time(self) -> float:
        """Sim time [s] since the last reset."""
        return self._steps * self.config.control_period

    @property
    def timed_out(self) -> bool:
        """True if the last accepted command is older than ``command_timeout`` (sim time).

        Then the next :meth:`step` commands zero velocity. False before the first command.
        """
        return self._cmd_step is not None and self._steps - self._cmd_step > self.config.timeout_periods

    # ---- commands and stepping ---------------------------------------------------------
    def reset(self, positions: FloatArray) -> None:
        """Teleport the joints to ``positions`` [rad] (14,), zero velocity, sim time 0, no command.

        Raises:
            DimensionError: wrong shape.
            ValueError: non-finite value or a position outside the URDF limits.
        """
        q = self._check_vector(positions, "reset positions")
        bad = [
            f"{n}={float(v)!r}"
            for n, v, lo, hi in zip(self.joint_names, q, self._q_min, self._q_max)
            if not lo <= v <= hi
        ]
        if bad:
            raise ValueError(f"reset positions outside the joint limits or non-finite: {', '.join(bad)}")
        self._last_q = None
        for j, qj in zip(self._idx, q):
            p.resetJointState(self._body, j, float(qj), 0.0, physicsClientId=self._client)
        for j, qj in zip(self._held_idx, self._held_q):
            p.resetJointState(self._body, j, qj, 0.0, physicsClientId=self._client)
        if self.config.held_object is not None:
            if self.held_object is not None:
                self.held_object.remove()
            self.held_object = HeldObject(self.config.held_object, self._client, self._body, self._link_index,
                                          p.getNumJoints(self._body, physicsClientId=self._client))
        self._grasp_from: int | None = None if self.grasp_on_motion else 0  # the step the grasp clock starts at
        self._reference = q  # the integrated command the joint position controller holds [rad]
        self._target = np.zeros(len(self._idx))
        self._cmd_step: int | None = None
        self._steps = 0
        self._stepped = False

    def apply_command(self, velocities: FloatArray) -> CommandReport:
        """Set the joint velocity command [rad/s], (14,), for the coming control periods.

        Non-finite commands are rejected and the arms commanded to rest; values beyond the
        URDF velocity limits are clipped. Both are reported.

        Raises:
            DimensionError: wrong shape.
        """
        self._require_open()
        qd = self._check_vector(velocities, "velocity command")
        finite = np.isfinite(qd)
        if not finite.all():
            self._target = np.zeros_like(qd)
            names = [n for n, ok in zip(self.joint_names, finite) if not ok]
            return CommandReport(False, 0, f"non-finite velocity at {', '.join(names)}; arms commanded to rest")
        over = np.abs(qd) > self._qd_max
        self._target = np.clip(qd, -self._qd_max, self._qd_max)
        self._cmd_step = self._steps
        if self._grasp_from is None and np.any(qd != 0.0):
            self._grasp_from = self._steps
        if not over.any():
            return CommandReport(True)
        names = [n for n, o in zip(self.joint_names, over) if o]
        return CommandReport(True, int(over.sum()), f"clipped to the velocity limits: {', '.join(names)}")

    @property
    def reference(self) -> FloatArray:
        """The joint position controller's reference [rad], (n,): the integrated command (a copy)."""
        return np.array(self._reference)

    def hold(self, mask: np.ndarray) -> None:
        """Zero the velocity command of the joints in ``mask`` (bool, (n,)): they hold their reference
        (a position interface's last command), the command timeout unchanged."""
        self._target = np.where(mask, 0.0, self._target)

    def step(self) -> JointSample:
        """Advance one control period (``substeps`` physics steps) and return the measured state.

        Each substep the joint position controller sets the motors' velocity target
        clip(q̇_cmd + position_gain (q_ref - q) / Δt_phys, ±q̇_max) (module docstring), then
        q_ref += q̇_cmd Δt_phys, kept inside the joint limits.
        """
        cid, body, idx = self._client, self._body, self._idx
        target = np.zeros_like(self._target) if self.timed_out else self._target
        dt = self.config.physics_dt
        gain = self.config.position_gain / dt
        reference = self._reference
        qd_max, qd_min = self._qd_max, -self._qd_max
        advance = target * dt
        last = self._last_q  # nothing moved the joints since state() read them: the same values, one read less
        self._last_q = None
        for _ in range(self.config.substeps):  # np.minimum(np.maximum()) is np.clip, without its dispatch
            q = last if last is not None else np.array([s[0] for s in p.getJointStates(body, idx, physicsClientId=cid)])
            last = None
            velocity = np.minimum(np.maximum(target + gain * (reference - q), qd_min), qd_max)
            p.setJointMotorControlArray(body, idx, p.VELOCITY_CONTROL, targetVelocities=velocity.tolist(),
                                        forces=self._forces, physicsClientId=cid)
            p.stepSimulation(physicsClientId=cid)
            reference = np.minimum(np.maximum(reference + advance, self._q_min), self._q_max)
        self._steps += 1
        self._stepped = True
        held = self.held_object
        if held is not None and held.waiting and self._grasp_from is not None and \
                (self._steps - self._grasp_from) * self.config.control_period >= held.config.grasp_time - 1e-9:
            held.grasp()  # the hands close at the end of this period
        elif held is not None and held.grasped and self._grasp_from is not None and \
                (self._steps - self._grasp_from) * self.config.control_period >= held.config.release_time - 1e-9:
            held.release()  # the hands open at the end of this period
        sample = self.state()
        self._reference = np.clip(reference, sample.positions - MAX_LAG, sample.positions + MAX_LAG)
        return sample

    def state(self) -> JointSample:
        """Current joint state read from the physics, without stepping."""
        states = p.getJointStates(self._body, self._idx, physicsClientId=self._client)
        q = _readonly(np.array([s[0] for s in states]))
        qd = np.array([s[1] for s in states])
        self._last_q = q  # the next step's first substep starts from it (pose() and reset() forget it)
        return JointSample(time=self.time, positions=q, velocities=_readonly(qd))

    def held_state(self) -> tuple[FloatArray, FloatArray]:
        """Positions [rad or m] and velocities of the held joints (``held_names``), read from the physics."""
        if not self._held_idx:
            return np.zeros(0), np.zeros(0)
        states = p.getJointStates(self._body, self._held_idx, physicsClientId=self._client)
        return np.array([s[0] for s in states]), np.array([s[1] for s in states])

    def wrench(self) -> FloatArray:
        """Force/torque [Fx, Fy, Fz (N), Mx, My, Mz (N m)] measured at ``right_tool_joint``, (6,).

        As pybullet gives it: the wrench the right flange exerts on the ``right_tool`` link,
        about the tool-frame origin (the peg tip), expressed in the ``right_tool`` frame,
        from the last physics substep. So an external force F on the peg reads as -F; at
        rest the reading is the tool link's weight (1 g, ~0.0098 N) pointing up. Zeros until
        the first step after a reset.
        """
        if not self._stepped or self._sensor is None:
            return np.zeros(6)
        return np.array(p.getJointState(self._body, self._sensor, physicsClientId=self._client)[2], dtype=float)

    def count_grasp_from_motion(self) -> None:
        """Count a held object's ``grasp_time`` from the first non-zero command from now on (this run and every
        reset): a real-time node, whose controller sends zero commands before its task starts."""
        self.grasp_on_motion = True
        if self._cmd_step is None:
            self._grasp_from = None

    def wrist_wrenches(self) -> FloatArray:
        """Both wrist F/T sensors' readings with their bias and noise, (2, 6): left, right [N, N m], each the
        wrench the flange exerts on the tool link about the tool frame's origin in the tool frame
        (:mod:`dualarm_sim.held_object`). Zeros (and the bias) until the first step; ValueError without a
        held object (the sensors are those of a held object's cell)."""
        if self.held_object is None:
            raise ValueError("the cell has no held object, so no wrist sensors (CellConfig.held_object)")
        raw = self.held_object.readings() if self._stepped else np.zeros((2, 6))
        return self._wrist.measure(raw)

    def link_pose(self, link: str) -> tuple[FloatArray, FloatArray]:
        """World pose of a URDF link frame from pybullet's forward kinematics.

        Returns:
            position [m], (3,), and rotation matrix, (3, 3).
        """
        if link not in self._link_index:
            raise KeyError(f"unknown link {link!r}")
        ls = p.getLinkState(
            self._body, self._link_index[link], computeForwardKinematics=True, physicsClientId=self._client
        )
        rot = np.array(p.getMatrixFromQuaternion(ls[5])).reshape(3, 3)
        return np.array(ls[4]), rot

    # ---- helpers and lifetime ----------------------------------------------------------
    def _check_vector(self, values: FloatArray, what: str) -> FloatArray:
        v = np.asarray(values, dtype=float)
        if v.shape != (len(self._idx),):
            raise DimensionError(f"{what}: expected {len(self._idx)} values, got shape {v.shape}")
        return v.copy()

    def close(self) -> None:
        """Disconnect the pybullet client; idempotent."""
        cid = getattr(self, "_cid", None)  # absent if __init__ failed early
        if cid is not None:
            self._cid = None
            if p.isConnected(cid):
                p.disconnect(cid)

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    def __del__(self) -> None:
        with contextlib.suppress(Exception):  # interpreter shutdown: pybullet may be gone
            self.close()
