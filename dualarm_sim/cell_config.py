"""The settings of a simulated cell (:class:`CellConfig`) and the link pairs that collide in it
(:func:`robot_collision_pairs`); :mod:`dualarm_sim.cell` says what each physics choice is and why."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

from dualarm_control.obstacles import Obstacle
from dualarm_control.robot import RobotDescription
from dualarm_control.robot_params import load_robot
from dualarm_sim.held_object import HeldObjectConfig, WristSensorConfig

MIN_PHYSICS_RATE_HZ = 1000.0
_RATE_TOL = 1e-9  # relative tolerance of the "integer multiple" check


_PAIRS_CACHE: dict[tuple[object, ...], tuple[tuple[str, str], ...]] = {}


def robot_collision_pairs(robot: RobotDescription | str,
                          allowed: tuple[tuple[str, str], ...] = ()) -> tuple[tuple[str, str], ...]:
    """The link pairs the controller's collision model checks on ``robot``: the pairs of
    :class:`~dualarm_control.collision.CollisionModel` with the robot's ``collision_allowed``
    and ``allowed`` (link names of the resolved URDF; ValueError for an unknown one) left out.
    Cached per robot description and ``allowed`` (building the model takes 0.01-0.1 s)."""
    r = load_robot(robot)
    key = (r.name, r.urdf_xml, tuple(r.joint_names), r.collision_allowed, tuple(map(tuple, allowed)))
    if key not in _PAIRS_CACHE:
        # coal and pinocchio: imported for a robot's cell only
        from dualarm_control.collision import CollisionModel
        from dualarm_control.kinematics import DualArmModel

        model = CollisionModel(DualArmModel(r), allowed=tuple(r.collision_allowed) + tuple(allowed))
        _PAIRS_CACHE[key] = tuple(model.pairs)
    return _PAIRS_CACHE[key]


def _check_positive(name: str, value: float) -> None:
    if not (math.isfinite(value) and value > 0.0):
        raise ValueError(f"{name}={value!r} must be a finite positive number")


@dataclass(frozen=True)
class CellConfig:
    """Simulation settings.

    Attributes:
        urdf: cell URDF, the same file pinocchio loads.
        control_period: duration of one :meth:`DualArmCell.step` [s]; one command per period.
        physics_rate_hz: physics substep rate [Hz]; >= 1000 and an integer multiple of
            ``1 / control_period``.
        command_timeout: sim time [s] a command stays in force; afterwards the arms are
            brought to rest (zero velocity command: they hold their position), like FRI / ros2_control.
        gravity: gravity along world z [m/s^2].
        motor_force_scale: joint-motor force limit as a multiple of the URDF effort
            limits [-]; see the module docstring for why it is 10.
        position_gain: gain of the joint position controller, in (0, 1] [-]: the fraction
            of the integrated command's position error corrected per physics substep.
        table_height: world z of a table top [m], or None (no table).
        contact_pairs: pairs of link names that make contact with each other on purpose (the
            pan and the brush; not counted as contacts).
        collision_pairs: pairs of link names that collide and whose contacts are counted
            (:meth:`DualArmCell.contacts`); the robot's collision model's pairs in
            :meth:`for_robot`. Every other link pair (but ``contact_pairs``) never makes contact.
        solver_iterations: iterations of pybullet's constraint solver per substep
            (``numSolverIterations``; pybullet's default is 50). See the module docstring.
        joints: the commanded joints, in command order (the robot's arms); empty: every movable
            joint of the URDF, in file order (a viewer's cell).
        held: (joint, position) of the joints held still (the robot's locked joints), by
            pybullet's joint position control at ``motor_force_scale`` times their effort.
        visual_shapes: load the URDF's visual meshes too (``getCameraImage``: the video); off,
            pybullet skips them (``URDF_IGNORE_VISUAL_SHAPES``), which changes no physics (bit for
            bit, tested) and loads a cell with meshes 20-100x faster (the Panda pair's: 1.2 s against
            0.011 s; a sweep builds one cell per run).
        obstacles: static obstacles (:mod:`dualarm_control.obstacles`), one pybullet body each.
        held_object: a box held by both tools from the start (:mod:`dualarm_sim.held_object`), or None.
        wrist_sensors: the wrist F/T sensors' bias and noise (:meth:`DualArmCell.wrist_wrenches`).
    """

    urdf: Path = field(default_factory=lambda: load_robot().urdf_path)
    control_period: float = 0.005
    physics_rate_hz: float = 1000.0
    command_timeout: float = 0.05
    gravity: float = -9.81
    motor_force_scale: float = 10.0
    position_gain: float = 1.0
    table_height: float | None = None
    contact_pairs: tuple[tuple[str, str], ...] = ()
    collision_pairs: tuple[tuple[str, str], ...] = ()
    solver_iterations: int = 20
    joints: tuple[str, ...] = ()
    held: tuple[tuple[str, float], ...] = ()
    visual_shapes: bool = False
    obstacles: tuple[Obstacle, ...] = ()
    held_object: HeldObjectConfig | None = None
    wrist_sensors: WristSensorConfig = field(default_factory=WristSensorConfig)

    @classmethod
    def for_robot(cls, robot: RobotDescription | str, allowed: tuple[tuple[str, str], ...] = (),
                  collisions: bool = True, **settings: object) -> CellConfig:
        """The cell of a robot description: its resolved URDF, its arms' joints commanded, its
        locked joints held, and with ``collisions`` the collision model's link pairs colliding
        (:func:`robot_collision_pairs`; ``allowed``: more link pairs that never collide, besides
        the robot's ``collision_allowed`` and the ``contact_pairs`` setting). ``settings``: the
        other fields."""
        r = load_robot(robot)
        contact = settings.get("contact_pairs", ())
        pairs = robot_collision_pairs(r, tuple(allowed) + tuple(contact)) if collisions else ()  # type: ignore[arg-type]
        return cls(urdf=r.urdf_path, joints=tuple(r.joint_names), held=tuple(r.locked_positions().items()),
                   collision_pairs=pairs, **settings)  # type: ignore[arg-type]

    def __post_init__(self) -> None:
        if self.table_height is not None and not math.isfinite(self.table_height):
            raise ValueError(f"table_height={self.table_height!r} must be finite or None")
        _check_positive("control_period", self.control_period)
        _check_positive("command_timeout", self.command_timeout)
        _check_positive("motor_force_scale", self.motor_force_scale)
        if not (isinstance(self.solver_iterations, int) and self.solver_iterations >= 1):
            raise ValueError(f"solver_iterations={self.solver_iterations!r} must be an integer >= 1")
        if not 0.0 < self.position_gain <= 1.0:
            raise ValueError(f"position_gain={self.position_gain!r} must be in (0, 1]")
        if not math.isfinite(self.gravity):
            raise ValueError(f"gravity={self.gravity!r} must be finite")
        rate = self.physics_rate_hz
        if not (math.isfinite(rate) and rate >= MIN_PHYSICS_RATE_HZ):
            raise ValueError(f"physics_rate_hz={rate!r} must be >= {MIN_PHYSICS_RATE_HZ:g} Hz")
        ratio = rate * self.control_period
        if abs(ratio - round(ratio)) > _RATE_TOL * max(1.0, ratio):
            raise ValueError(
                f"physics_rate_hz={rate!r} must be an integer multiple of 1/control_period = "
                f"{1.0 / self.control_period:g} Hz"
            )

    @property
    def substeps(self) -> int:
        """Physics substeps per control period [-]."""
        return round(self.physics_rate_hz * self.control_period)

    @property
    def physics_dt(self) -> float:
        """Physics substep duration [s]."""
        return self.control_period / self.substeps

    @property
    def timeout_periods(self) -> int:
        """Number of control periods a command stays in force after the one it was sent for [-]."""
        return math.floor(self.command_timeout / self.control_period + 1e-9)
