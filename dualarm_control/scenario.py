"""Scenarios: the cell (URDF, initial configuration), the motion limits and one reference source.

A scenario file is a parameter file (``/**: ros__parameters: scenario: ...``) so the sim
node (initial configuration), the trajectory node (segments) and the in-process experiment
read the same keys. Registry: every ``config/scenarios/<name>.yaml`` is scenario ``<name>``.

Keys under ``scenario.`` (flattened names):
  name, description; ``robot``: a robot description's name (``config/robots/``) or a YAML path
  (relative to the scenario file; default ``lwr4_cell``, :mod:`dualarm_control.robot`);
  ``obstacles`` (static obstacles by name, each one's keys under its name: :mod:`dualarm_control.obstacles`);
  ``acceleration_limit`` (the controller's default joint acceleration bound in this cell [rad/s^2], one value
  or one per joint, over the robot's; a parameter given to the controller overrides it);
  ``initial_positions_deg`` (one value per joint of the robot, left then right; default: the
  robot's ready positions); ``robot_starts.<robot name>``: the start on another robot (used when
  the run's robot, e.g. ``--robot``, is that one; else its ready positions); settle_time [s], limits.<MotionLimits field>; and the keys of the
  reference source
  (:mod:`dualarm_control.references`): ``tasks`` (paper 001,
  :mod:`dualarm_control.references.tasks`) or else ``segments`` (paper 000,
  :mod:`dualarm_control.references.segments`) or ``goals`` (issue 18: timed relative goals and
  twists, :mod:`dualarm_control.references.goals`). A planned joint trajectory (paper 003) comes
  from a plan file (:class:`~dualarm_control.references.plan.PlanSource`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np

from dualarm_control.collision import CollisionModel
from dualarm_control.controller import ControllerParams, acceleration_limit_problem
from dualarm_control.errors import ScenarioError
from dualarm_control.kinematics import DualArmModel, FloatArray
from dualarm_control.moving_obstacles import MovingObstacle, parse_moving_obstacles
from dualarm_control.obstacles import AttachedBox, Obstacle, parse_obstacles
from dualarm_control.params import (
    ParameterError,
    ParamSpec,
    link_pairs,
    read_params_file,
)
from dualarm_control.paths import registry_file, registry_names
from dualarm_control.references.base import ReferenceSource
from dualarm_control.references.goals import GoalsSource, parse_goals_source
from dualarm_control.references.segments import SegmentsSource, parse_segments
from dualarm_control.references.tasks import TasksSource, parse_tasks
from dualarm_control.robot import RobotDescription
from dualarm_control.robot_files import RobotError
from dualarm_control.robot_params import DEFAULT_ROBOT, load_robot, robot_defaults
from dualarm_control.scenario_keys import PREFIX, get, number, vector
from dualarm_control.trajectory import MotionLimits, RelativeTrajectory


@dataclass(frozen=True)
class Scenario:
    """A validated scenario.

    Attributes:
        name, description: labels.
        initial_positions: joint positions at start [rad], (n,) (the robot's joints).
        reference: what the controller follows (:mod:`dualarm_control.references`).
        limits: ruckig limits of the relative motion.
        settle_time: control time after the trajectory ends [s] (error convergence).
        source: file it came from.
        robot: the robot description the scenario runs on.
        collision_allowed: link pairs the collision limit never checks (``scenario.collision_allowed``).
        obstacles: static obstacles of the cell (``scenario.obstacles``): the collision limit avoids
            them, the simulator has them (docs/obstacles.md).
        moving_obstacles: shapes that come in and go out (``scenario.moving_obstacles``, a hand): live
            obstacles of the collision limit, moved bodies of the simulator.
        acceleration_limit: the controller's default joint acceleration bound [rad/s^2] in this cell
            (``scenario.acceleration_limit``; empty: the robot's, :meth:`controller_defaults`).
    """

    name: str
    description: str
    initial_positions: FloatArray
    reference: ReferenceSource
    limits: MotionLimits
    settle_time: float
    source: Path
    robot: RobotDescription = field(default_factory=load_robot)
    collision_allowed: tuple[tuple[str, str], ...] = ()
    obstacles: tuple[Obstacle, ...] = ()
    moving_obstacles: tuple[MovingObstacle, ...] = ()
    acceleration_limit: tuple[float, ...] = ()

    def controller_defaults(self) -> dict[str, Any]:
        """The controller parameters this cell sets by default, as parameter values (a parameter given to the
        controller, in a file or on the command line, overrides them): the robot's joint acceleration bound
        (``robot.acceleration_limit``), the scenario's in its place when it has one (busy_cell: two rows
        pressing on one plate from both sides make the commands alternate without it, docs/obstacles.md)."""
        defaults = robot_defaults(self.robot)
        if self.acceleration_limit:
            defaults["acceleration_limit"] = list(self.acceleration_limit)
        return defaults

    @property
    def held_bodies(self) -> tuple[AttachedBox, ...]:
        """The held object as a body of the collision model (issue 41, item 4): a box on the left tool's frame
        at its grasp (``held_object``), or () without one."""
        held = self.tasks.held if self.tasks is not None else None
        if held is None:
            return ()
        from dualarm_sim.held_object import (
            HeldObjectConfig,  # the simulator's box: one definition of its keys
        )

        box = HeldObjectConfig(**held.held_object)
        roll, pitch, yaw = (math.radians(v) for v in box.grasp_rpy_deg)
        return (AttachedBox(name="held_object", size=box.size, position=box.grasp_position, rpy=(roll, pitch, yaw)),)

    @property
    def collision_pairs_allowed(self) -> tuple[tuple[str, str], ...]:
        """``collision_allowed`` and, with a held object, the held box against the right hand (which grasps
        it; the left one is its own arm's, at joint distance 0)."""
        return self.collision_allowed + tuple((body.label, "right_tool") for body in self.held_bodies)

    @property
    def robot_pairs_allowed(self) -> tuple[tuple[str, str], ...]:
        """``collision_allowed`` without the pairs naming a held object or an obstacle (``held:``, ``obstacle:``,
        e.g. a carried box against the support it is put on): the robot's own links' pairs, for the simulator."""
        return tuple(pair for pair in self.collision_allowed
                     if not any(name.startswith(("held:", "obstacle:")) for name in pair))

    def controller_params(self, params: ControllerParams) -> ControllerParams:
        """``params`` with the scenario's allowed contacts added to the collision limit's
        (``scenario.collision_allowed``: e.g. the assembly's tools, which meet on purpose) and its
        obstacles (``scenario.obstacles``, and a held object fixed to the left tool) as the limit's."""
        obstacles = self.obstacles + self.held_bodies
        if not self.collision_allowed and not obstacles and not self.moving_obstacles:
            return params
        collision = replace(params.collision, allowed=tuple(params.collision.allowed) + self.collision_pairs_allowed,
                            obstacles=obstacles,
                            live_obstacles=max(params.collision.live_obstacles, len(self.moving_obstacles)))
        return replace(params, collision=collision)

    def collision_model(self, model: DualArmModel) -> CollisionModel:
        """The collision model a controller runs this scenario with (the robot's allowed pairs and the
        scenario's, its obstacles and held object, default settings; shared on ``model``): what a stall's
        reason names."""
        return CollisionModel.shared(model, (*model.description.collision_allowed, *self.collision_pairs_allowed),
                                     self.obstacles + self.held_bodies)

    @property
    def tasks(self) -> TasksSource | None:
        """The tasks source of a task scenario (paper 001), else None."""
        return self.reference if isinstance(self.reference, TasksSource) else None

    @property
    def urdf_path(self) -> Path:
        """Path of the robot's resolved URDF (what pinocchio and pybullet load)."""
        return self.robot.urdf_path

    def end_pose(self, start: FloatArray, model: Any, period: float) -> tuple[FloatArray, FloatArray]:
        """The relative pose (position [m] (3,), rotation (3, 3)) the reference ends at, from the
        start configuration ``start`` (n,) [rad]: the last segment's end, the script's last goal
        or jog at rest (ScenarioError for a source without an end pose: tasks)."""
        if not isinstance(self.reference, SegmentsSource | GoalsSource):
            raise ScenarioError(f"scenario {self.name!r} has no relative end pose ({self.reference.kind})")
        return self.reference.end_pose(model, start, self.limits, period)

    def trajectory(self, start_position: FloatArray, start_rotation: FloatArray) -> RelativeTrajectory:
        """The ruckig relative trajectory from the measured start pose through the scenario's segments."""
        if not isinstance(self.reference, SegmentsSource):
            raise ScenarioError(f"scenario {self.name!r} is a task scenario (paper 001) without relative motion "
                                "segments: run it with 'dualarm experiment' (constraint_based solver)")
        return self.reference.trajectory(start_position, start_rotation, self.limits)


ROBOT_PARAMETER = ParamSpec("robot", "", "robot description (config/robots/<name>.yaml or a YAML path; '': the "
                            "scenario's robot, docs/robots.md)", read_only=True)


def scenario_names() -> list[str]:
    """Names of the scenarios shipped in config/scenarios/."""
    return registry_names("scenarios")


def scenario_file(name_or_path: str) -> Path:
    """Path of a scenario given by registry name or file path (ScenarioError if unknown)."""
    return registry_file("scenarios", name_or_path, "scenario", ScenarioError)


def load_scenario(name_or_path: str, robot: str | RobotDescription | None = None, *,
                  reference: ReferenceSource | None = None) -> Scenario:
    """Load and validate a scenario by registry name or path, on its robot or on ``robot``
    (``--robot``: a name or a YAML path; '' or None: the scenario's). ``reference``: the cell of the file (robot,
    start, obstacles, allowed contacts, controller defaults) tracking this source instead of the file's (which
    is then not read: a plan's scenario may have none)."""
    path = scenario_file(name_or_path)
    try:
        flat = read_params_file(path, "trajectory_node")
    except ParameterError as exc:
        raise ScenarioError(str(exc)) from None
    return scenario_from_parameters(flat, path, robot or None, reference=reference)


def _link_pairs(flat: Mapping[str, Any]) -> tuple[tuple[str, str], ...]:
    """``scenario.collision_allowed``: 'link_a link_b' strings (``left_tool right_tool``: the two end
    effectors, :class:`~dualarm_control.collision.CollisionModel`) as pairs; ScenarioError naming a bad entry."""
    try:
        return link_pairs(get(flat, "collision_allowed", []), f"{PREFIX}collision_allowed")
    except ParameterError as exc:
        raise ScenarioError(f"scenario parameter '{PREFIX}collision_allowed': {exc.expected}") from None


def _acceleration_limit(flat: Mapping[str, Any], n: int) -> tuple[float, ...]:
    """``scenario.acceleration_limit`` [rad/s^2]: one value or ``n``, each > 0 (empty or missing: none); ScenarioError
    naming the key and value otherwise."""
    value = get(flat, "acceleration_limit", [])
    if not isinstance(value, list) or len(value) not in (0, 1, n) or any(isinstance(v, bool) for v in value) \
            or acceleration_limit_problem(value):
        raise ScenarioError(f"scenario parameter '{PREFIX}acceleration_limit': got {value!r}, expected values > 0 "
                            f"[rad/s^2], one for all joints or {n} (one per joint)")
    return tuple(float(v) for v in value)


def _motion_limits(flat: Mapping[str, Any]) -> MotionLimits:
    """MotionLimits from the ``scenario.limits.*`` keys; ScenarioError naming the full key and value.

    Each limit must be a finite number > 0 (bool, strings, NaN/inf, 0 and negatives are
    refused); an unknown key is refused with the valid names.
    """
    prefix = PREFIX + "limits."
    valid = [f.name for f in fields(MotionLimits)]
    values: dict[str, float] = {}
    for key, value in flat.items():
        if not key.startswith(prefix):
            continue
        name = key[len(prefix):]
        if name not in valid:
            raise ScenarioError(f"scenario parameter '{key}': unknown limit; valid names: {', '.join(valid)}")
        if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value) or value <= 0:
            raise ScenarioError(f"scenario parameter '{key}': got {value!r}, expected a finite number > 0")
        values[name] = float(value)
    return MotionLimits(**values)


def scenario_robot(flat: Mapping[str, Any], source: Path, robot: str | RobotDescription | None = None
                   ) -> tuple[RobotDescription, bool]:
    """The robot a scenario runs on, and whether it is the scenario's own (so that its
    ``initial_positions_deg`` apply): ``robot`` (an override) or the file's ``scenario.robot``."""
    own = get(flat, "robot", DEFAULT_ROBOT)
    if not isinstance(own, str) or not own:
        raise ScenarioError(f"scenario parameter '{PREFIX}robot': got {own!r}, expected a robot name or a YAML path")
    if own.endswith((".yaml", ".yml")) and not Path(own).is_absolute():
        own = str(source.parent / own)
    try:
        own_robot = load_robot(own)
    except RobotError as exc:
        raise ScenarioError(f"scenario parameter '{PREFIX}robot': {exc}") from None
    try:
        chosen = own_robot if robot is None else load_robot(robot)
    except RobotError as exc:
        raise ScenarioError(f"--robot: {exc}") from None
    return chosen, chosen == own_robot


def _reference(flat: Mapping[str, Any], source: Path) -> ReferenceSource:
    """The scenario's reference: its tasks (paper 001), its goals stream, or its segments."""
    if PREFIX + "tasks" in flat:
        return parse_tasks(flat, source.parent)
    if PREFIX + "goals" in flat:
        return parse_goals_source(flat[PREFIX + "goals"], flat)
    return parse_segments(flat)


def scenario_from_parameters(flat: Mapping[str, Any], source: Path, robot: str | RobotDescription | None = None, *,
                             reference: ReferenceSource | None = None) -> Scenario:
    """Build a Scenario from flattened parameters (as read from the file or declared in a node),
    on its own robot or on ``robot`` (its ready positions are then the start); tracking ``reference``
    instead of the file's own when given."""
    if reference is None:
        reference = _reference(flat, Path(source))
    limits = _motion_limits(flat)
    settle = number(flat, "settle_time", 1.0)
    if settle < 0:
        raise ScenarioError(f"scenario parameter '{PREFIX}settle_time': got {settle}, expected >= 0")
    if PREFIX + "urdf" in flat:
        raise ScenarioError(f"scenario parameter '{PREFIX}urdf': a scenario names its robot now "
                            f"('{PREFIX}robot: NAME|PATH', config/robots/; docs/robots.md)")
    chosen, own = scenario_robot(flat, source, robot)
    if own and PREFIX + "initial_positions_deg" in flat:
        start = np.radians(vector(flat, "initial_positions_deg", chosen.nq))
    elif PREFIX + f"robot_starts.{chosen.name}" in flat:
        start = np.radians(vector(flat, f"robot_starts.{chosen.name}", chosen.nq))
    else:
        start = chosen.ready
    outside = [f"{n} = {math.degrees(v):.4g} deg" for n, v, lo, hi in zip(
        chosen.joint_names, start, chosen.resolved_limits[0], chosen.resolved_limits[1], strict=True)
        if not lo - 1e-9 <= v <= hi + 1e-9]
    if outside:
        raise ScenarioError(f"scenario {source}: the start on robot {chosen.name!r} is outside the joint limits: "
                            + ", ".join(outside))
    return Scenario(
        acceleration_limit=_acceleration_limit(flat, chosen.nq),
        collision_allowed=_link_pairs(flat),
        obstacles=(static := parse_obstacles(flat, Path(source).parent)),
        moving_obstacles=parse_moving_obstacles(flat, static),
        name=str(get(flat, "name")),
        description=str(get(flat, "description", "")),
        initial_positions=start,
        reference=reference,
        limits=limits,
        settle_time=settle,
        source=source,
        robot=chosen,
    )
