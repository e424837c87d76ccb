"""Static obstacles of a cell, from a scenario's configuration (issue 42, part 1; docs/obstacles.md).

A scenario lists its obstacles by name, as it lists its tasks, and gives each one's keys under its
name (flattened ``scenario.<name>.*``, the form a ROS parameter file has)::

    obstacles: [table, fixture]
    table:   {type: box, size: [1.2, 1.6, 0.05], position: [0.7, 0.0, 0.375]}
    fixture: {type: cylinder, radius: 0.04, length: 0.5, position: [0.6, 0.0, 0.75], rpy: [0, 0, 0]}

Types (sizes in m, angles in rad), each with an optional pose in the world frame of the cell (the
frame the robot's URDF is built in: pinocchio's universe, pybullet's world): ``position`` [x, y, z]
(default 0) and ``rpy`` [roll, pitch, yaw] (default 0; R = Rz(yaw) Ry(pitch) Rx(roll), as URDF,
pinocchio and pybullet):

* ``box``: ``size`` [x, y, z], the full side lengths, centred on the position;
* ``sphere``: ``radius``;
* ``cylinder``: ``radius`` and ``length``, its axis the z axis of its pose, centred on the position;
* ``plane``: a half-space, everything on the far side of a plane: ``normal`` [x, y, z] (out of the
  obstacle, into the free side; normalised) and ``offset`` [m] (the obstacle is n.x <= offset), or
  ``height`` alone (the horizontal plane z = height, the obstacle below it). No pose;
* ``mesh``: ``file`` (a .obj or .stl file, relative to the scenario file) and ``scale`` (one number
  or [x, y, z], default 1); as the robot's meshes, its convex hull is what collides.

Refused with a :class:`~dualarm_control.errors.ScenarioError` naming the key and the value: a value
that is not a finite number (NaN, inf, a string, a bool), a size <= 0, a list of the wrong length,
an unknown type (the message names the known ones), an unknown key of an obstacle, a missing mesh
file, a name that is not an identifier, given twice, or one of the scenario's own keys, and more
than :data:`MAX_OBSTACLES` obstacles.

This module is plain data (numpy only): the collision model makes coal shapes of them
(:mod:`dualarm_control.collision.obstacles`), the simulator pybullet bodies (:mod:`dualarm_sim.obstacles`).
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

from dualarm_control.errors import ScenarioError

FloatArray = npt.NDArray[np.float64]
Vector3 = tuple[float, float, float]

MAX_OBSTACLES = 32
"""Most obstacles a scenario may declare: each adds a shape pair per arm link to the collision
model (the LWR4 cell: 16 links), which the per-cycle broadphase mostly skips; a scene needing more
(a point cloud) is the issue's second part."""
OBSTACLES_KEY = "obstacles"
"""The scenario key that lists the obstacles' names."""
LABEL_PREFIX = "obstacle:"
"""An obstacle's name in the collision model (its shape, link and pair labels): ``obstacle:<name>``."""
TABLE = "table"
"""The obstacle whose top is the table plane of paper 001's f6 task (``table_height``)."""
RESERVED = frozenset({
    "name", "description", "robot", "robot_starts", "initial_positions_deg", "settle_time", "limits", "tasks",
    "segments", "goals", "duration", "convergence_time", "table_height", "gains", "contact_links", "force",
    "collision_allowed", "obstacles", "moving_obstacles", "plugins", "urdf", "corner", "plan", "baseline", "execution"})
"""Scenario keys an obstacle cannot be named (its keys would be theirs)."""
_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")
MESH_SUFFIXES = (".obj", ".stl")
"""Mesh files both coal (assimp) and pybullet read."""


def rpy_matrix(rpy: Sequence[float]) -> FloatArray:
    """R = Rz(yaw) Ry(pitch) Rx(roll), (3, 3) (URDF's, pinocchio's ``rpyToMatrix``, pybullet's)."""
    r, p, y = (float(v) for v in rpy)
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


@dataclass(frozen=True)
class Obstacle:
    """An obstacle's name and pose in the world frame of the cell (module docstring).

    Attributes:
        name: its scenario name (the collision model calls it ``obstacle:<name>``).
        position: [m] (x, y, z). rpy: [rad] (roll, pitch, yaw).
    """

    name: str
    position: Vector3 = (0.0, 0.0, 0.0)
    rpy: Vector3 = (0.0, 0.0, 0.0)
    kind: ClassVar[str] = ""

    @property
    def label(self) -> str:
        """``obstacle:<name>``: its name in the collision model's pairs and in a stall's reason."""
        return LABEL_PREFIX + self.name

    @property
    def rotation(self) -> FloatArray:
        """Its orientation in the world, (3, 3)."""
        return rpy_matrix(self.rpy)

    def top(self) -> float | None:
        """The world z [m] of its top face when that is horizontal (a box or cylinder whose z axis is
        vertical, a horizontal plane); None otherwise (a table must have one)."""
        return None

    def _vertical_top(self, half: float) -> float | None:
        axis = self.rotation[:, 2]
        if abs(abs(float(axis[2])) - 1.0) > 1e-12:
            return None
        return self.position[2] + half


@dataclass(frozen=True)
class Box(Obstacle):
    """A box: ``size`` [m] (x, y, z), the full side lengths, centred on the position."""

    size: Vector3 = (1.0, 1.0, 1.0)
    kind: ClassVar[str] = "box"

    def top(self) -> float | None:
        return self._vertical_top(self.size[2] / 2.0)


@dataclass(frozen=True)
class Sphere(Obstacle):
    """A sphere of ``radius`` [m] about the position."""

    radius: float = 0.1
    kind: ClassVar[str] = "sphere"


@dataclass(frozen=True)
class Cylinder(Obstacle):
    """A cylinder: ``radius`` and ``length`` [m], along its pose's z axis, centred on the position."""

    radius: float = 0.1
    length: float = 0.1
    kind: ClassVar[str] = "cylinder"

    def top(self) -> float | None:
        return self._vertical_top(self.length / 2.0)


@dataclass(frozen=True)
class Plane(Obstacle):
    """The half-space n.x <= offset: ``normal`` (unit, out of the obstacle) and ``offset`` [m]."""

    normal: Vector3 = (0.0, 0.0, 1.0)
    offset: float = 0.0
    kind: ClassVar[str] = "plane"

    def top(self) -> float | None:
        return self.offset if self.normal == (0.0, 0.0, 1.0) else None


@dataclass(frozen=True)
class Mesh(Obstacle):
    """A mesh file (its convex hull collides) scaled by ``scale`` (x, y, z)."""

    file: Path = Path()
    scale: Vector3 = (1.0, 1.0, 1.0)
    kind: ClassVar[str] = "mesh"


TYPES: dict[str, type[Obstacle]] = {cls.kind: cls for cls in (Box, Sphere, Cylinder, Plane, Mesh)}
"""The obstacle types by their ``type`` key."""
_KEYS: dict[str, tuple[str, ...]] = {
    "box": ("size",), "sphere": ("radius",), "cylinder": ("radius", "length"),
    "plane": ("normal", "offset", "height"), "mesh": ("file", "scale")}
_POSE = ("position", "rpy")


def _finite(key: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ScenarioError(f"scenario parameter '{key}': got {value!r}, expected a finite number")
    return float(value)


def _positive(key: str, value: Any) -> float:
    out = _finite(key, value)
    if out <= 0.0:
        raise ScenarioError(f"scenario parameter '{key}': got {value!r}, expected a size > 0 [m]")
    return out


def _vector(key: str, value: Any, positive: bool = False) -> Vector3:
    if not isinstance(value, list | tuple) or len(value) != 3:
        raise ScenarioError(f"scenario parameter '{key}': got {value!r}, expected a list of 3 numbers")
    x, y, z = (_positive(key, v) if positive else _finite(key, v) for v in value)
    return x, y, z


HELD_PREFIX = "held:"
"""A held object's name in the collision model: ``held:<name>``."""


@dataclass(frozen=True)
class AttachedBox(Box):
    """A box fixed to a frame of the robot while it is held (issue 41, item 4): ``position`` [m] and ``rpy``
    [rad] give its centre in ``frame`` (the left tool's), ``size`` [m] its sides. The collision model carries it
    as a link of the arm that moves the frame (:mod:`dualarm_control.collision.obstacles`), not as world
    geometry; the simulator's box is :mod:`dualarm_sim.held_object`'s."""

    frame: str = "left_tool"
    kind: ClassVar[str] = "attached_box"

    @property
    def label(self) -> str:
        """``held:<name>``: its link name in the collision model's pairs."""
        return HELD_PREFIX + self.name


def parse_obstacles(flat: Mapping[str, Any], base: Path, prefix: str = "scenario.") -> tuple[Obstacle, ...]:
    """The obstacles of flattened scenario parameters (module docstring); () without ``obstacles``.

    Args:
        flat: the scenario file's flattened parameters. base: the directory mesh files are relative
            to (the scenario file's). prefix: the keys' prefix.

    Raises:
        ScenarioError: naming the key and the value (module docstring).
    """
    key = prefix + OBSTACLES_KEY
    names = flat.get(key, [])
    if names in ([], [""], (), ""):
        return ()
    if not isinstance(names, list | tuple) or not all(isinstance(n, str) for n in names):
        raise ScenarioError(f"scenario parameter '{key}': got {names!r}, expected a list of obstacle names")
    if len(names) > MAX_OBSTACLES:
        raise ScenarioError(f"scenario parameter '{key}': {len(names)} obstacles, more than the "
                            f"{MAX_OBSTACLES} a scenario may declare")
    tasks = flat.get(prefix + "tasks", [])
    out: list[Obstacle] = []
    for name in names:
        if not _NAME.match(name) or name in RESERVED:
            raise ScenarioError(f"scenario parameter '{key}': {name!r} is not a valid obstacle name (an identifier, "
                                f"not one of the scenario's keys: {', '.join(sorted(RESERVED))})")
        if name in (o.name for o in out):
            raise ScenarioError(f"scenario parameter '{key}': obstacle {name!r} is listed twice")
        if isinstance(tasks, list) and name in tasks:
            raise ScenarioError(f"scenario parameter '{key}': {name!r} is also a task's name")
        out.append(_obstacle(flat, prefix + name + ".", name, base))
    return tuple(out)


def _obstacle(flat: Mapping[str, Any], sub: str, name: str, base: Path) -> Obstacle:
    """One obstacle from its ``<sub>*`` keys."""
    values = {k[len(sub):]: v for k, v in flat.items() if k.startswith(sub)}
    kind = values.pop("type", None)
    if kind not in TYPES:
        raise ScenarioError(f"scenario parameter '{sub}type': got {kind!r}, expected one of: {', '.join(TYPES)}")
    valid = _KEYS[kind] + (() if kind == "plane" else _POSE)
    unknown = sorted(set(values) - set(valid))
    if unknown:
        raise ScenarioError(f"scenario parameter '{sub}{unknown[0]}': unknown key of a {kind} obstacle "
                            f"(got {values[unknown[0]]!r}); valid: type, {', '.join(valid)}")
    missing = [k for k in _KEYS[kind] if k not in values and kind not in ("plane", "mesh")]
    if missing:
        raise ScenarioError(f"scenario parameter '{sub}{missing[0]}' is missing (a {kind} obstacle)")
    pose: dict[str, Vector3] = {k: _vector(sub + k, values[k]) for k in _POSE if k in values}
    if kind == "box":
        return Box(name, size=_vector(sub + "size", values["size"], positive=True), **pose)
    if kind == "sphere":
        return Sphere(name, radius=_positive(sub + "radius", values["radius"]), **pose)
    if kind == "cylinder":
        return Cylinder(name, radius=_positive(sub + "radius", values["radius"]),
                        length=_positive(sub + "length", values["length"]), **pose)
    if kind == "plane":
        return _plane(values, sub, name)
    return _mesh(values, sub, name, base, pose)


def _plane(values: Mapping[str, Any], sub: str, name: str) -> Plane:
    if "height" in values:
        if "normal" in values or "offset" in values:
            raise ScenarioError(f"scenario parameter '{sub}height': a plane has a height or a normal and an "
                                "offset, not both")
        return Plane(name, normal=(0.0, 0.0, 1.0), offset=_finite(sub + "height", values["height"]))
    if "normal" not in values or "offset" not in values:
        raise ScenarioError(f"scenario parameter '{sub}{'offset' if 'normal' in values else 'normal'}' is missing "
                            "(a plane: normal and offset, or height)")
    normal = np.array(_vector(sub + "normal", values["normal"]))
    length = float(np.linalg.norm(normal))
    if not length > 1e-9:
        raise ScenarioError(f"scenario parameter '{sub}normal': got {values['normal']!r}, expected a non-zero vector")
    nx, ny, nz = (float(v) for v in normal / length)
    return Plane(name, normal=(nx, ny, nz), offset=_finite(sub + "offset", values["offset"]) / length)


def _mesh(values: Mapping[str, Any], sub: str, name: str, base: Path, pose: Mapping[str, Vector3]) -> Mesh:
    file = values.get("file")
    if not isinstance(file, str) or not file:
        raise ScenarioError(f"scenario parameter '{sub}file': got {file!r}, expected a mesh file path")
    path = Path(file) if Path(file).is_absolute() else base / file
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise ScenarioError(f"scenario parameter '{sub}file': got {file!r}, expected a {' or '.join(MESH_SUFFIXES)} "
                            "file")
    if not path.is_file():
        raise ScenarioError(f"scenario parameter '{sub}file': got {file!r}, no such file ({path})")
    scale = values.get("scale", 1.0)
    if isinstance(scale, int | float) and not isinstance(scale, bool):
        s = _positive(sub + "scale", scale)
        sizes: Vector3 = (s, s, s)
    else:
        sizes = _vector(sub + "scale", scale, positive=True)
    return Mesh(name, file=path.resolve(), scale=sizes, **pose)


def table_top(obstacles: Sequence[Obstacle]) -> float | None:
    """The world z [m] of the top of the obstacle named :data:`TABLE` (None without one);
    ScenarioError when its top is not horizontal (a tilted box, a sphere)."""
    table = next((o for o in obstacles if o.name == TABLE), None)
    if table is None:
        return None
    top = table.top()
    if top is None:
        raise ScenarioError(f"obstacle {TABLE!r} ({table.kind}): a table needs a horizontal top (a box or cylinder "
                            "with its z axis vertical, or a plane with normal [0, 0, 1])")
    return top
