"""Reading a robot description: its parameter file, by registry name or path, validated.

The robot is data (DESIGN.md): one ROS-style parameter file per robot
(``config/robots/<name>.yaml``, keys under ``robot.``) is the only place a robot is named. The
core builds its model from it (:class:`~dualarm_control.kinematics.DualArmModel`), the simulator
loads the same resolved URDF, and ``/robot_description`` carries it.

Keys (flattened, under ``robot.``):
  ``name``; ``urdf``: a path, a file name in the package's ``urdf/``, or
  ``example-robot-data:<path under robots/>``;
  ``left_joints``, ``right_joints``: each arm's joint names, base to tip (1 to 12 each; the two may
  differ); every other movable joint of the URDF is locked at ``locked.<joint>`` (default 0, or
  the middle of its range when 0 is outside it);
  ``left_tool``, ``right_tool``: links of the URDF (F1, F2), with optional fixed offsets
  ``left_tool_offset`` / ``right_tool_offset`` (x y z [m] roll pitch yaw [deg]);
  ``pair: true`` for two copies of a single-arm URDF, placed by ``left_base`` / ``right_base``
  (x y z [m] roll pitch yaw [deg] in the world): the joint and link names above are then the
  single-arm URDF's, and the model prefixes them ``left_`` / ``right_``;
  ``ready_positions_deg``: a start configuration of the arms' joints (left then right) in which
  the tools face each other; optional ``acceleration_limit`` [rad/s^2] (one value or one per joint);
  optional ``collision_allowed``: link pairs whose shapes may touch (``"link_a link_b"`` strings, as
  the resolved URDF names the links: the cell's peg and hole, shapes that overlap by design), never
  checked by the collision limit (:mod:`dualarm_control.collision`): only shapes that overlap by
  construction (an SRDF's disable_collisions), never the two arms' ends (the task allows those);
  optional ``tools``: a tool set (``config/tools/<name>.yaml`` or a YAML path): bodies fixed to the
  tool frames, links of the resolved URDF (:mod:`dualarm_control.tool_bodies`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from dualarm_control.params import ParameterError, link_pairs, read_params_file
from dualarm_control.paths import registry_file, registry_names
from dualarm_control.robot import IDENTITY, Pose6, RobotDescription
from dualarm_control.robot_files import PREFIX, RobotError, _key, urdf_file
from dualarm_control.tool_bodies import ToolSet, load_tool_set, tool_set_names

DEFAULT_ROBOT = "lwr4_cell"
KEYS = ("name", "description", "urdf", "left_joints", "right_joints", "left_tool", "right_tool",
        "left_tool_offset", "right_tool_offset", "pair", "left_base", "right_base", "ready_positions_deg",
        "acceleration_limit", "collision_allowed", "tools")


def robot_defaults(robot: RobotDescription) -> dict[str, Any]:
    """The controller parameters a robot sets by default (a parameter file given after overrides them)."""
    return {"acceleration_limit": list(robot.acceleration_limit)} if robot.acceleration_limit else {}


# ---- reading a description --------------------------------------------------------------

def robot_names() -> list[str]:
    """Names of the robots shipped in config/robots/."""
    return registry_names("robots")


def robot_file(name_or_path: str) -> Path:
    """Path of a robot description by registry name or file path (RobotError if unknown)."""
    return registry_file("robots", name_or_path, "robot", RobotError, " (or a YAML file of your own, docs/robots.md)")


_LOADED: dict[Path, tuple[int, RobotDescription]] = {}
"""Descriptions read in this process, by file (with its mtime): a process builds each once."""


def load_robot(name_or_path: str | RobotDescription = DEFAULT_ROBOT) -> RobotDescription:
    """Load and validate a robot description by registry name or path (cached per file)."""
    if isinstance(name_or_path, RobotDescription):
        return name_or_path
    path = robot_file(name_or_path).resolve()
    stamp = path.stat().st_mtime_ns
    cached = _LOADED.get(path)
    if cached is not None and cached[0] == stamp:
        return cached[1]
    try:
        flat = read_params_file(path, "robot")
    except ParameterError as exc:
        raise RobotError(str(exc)) from None
    robot = robot_from_parameters(flat, path)
    robot.resolved  # noqa: B018 - validate the URDF side now, so that a bad file fails at load
    _LOADED[path] = (stamp, robot)
    return robot


def _names(flat: Mapping[str, Any], key: str) -> tuple[str, ...]:
    value = flat.get(PREFIX + key)
    if not isinstance(value, list) or not value or not all(isinstance(v, str) and v for v in value):
        raise RobotError(f"robot parameter {_key(key)}: got {value!r}, expected a list of joint names")
    if len(value) > 12:
        raise RobotError(f"robot parameter {_key(key)}: got {len(value)} joints, expected at most 12 per arm")
    if len(set(value)) != len(value):
        twice = sorted({v for v in value if value.count(v) > 1})
        raise RobotError(f"robot parameter {_key(key)}: {', '.join(twice)} listed twice")
    return tuple(value)


def _text(flat: Mapping[str, Any], key: str, default: str | None = None) -> str:
    value = flat.get(PREFIX + key, default)
    if not isinstance(value, str) or not value:
        raise RobotError(f"robot parameter {_key(key)}: got {value!r}, expected a non-empty string")
    return value


def _numbers(flat: Mapping[str, Any], key: str, size: int | None, default: Sequence[float] | None = None
             ) -> tuple[float, ...]:
    value = flat.get(PREFIX + key, default)
    ok = isinstance(value, list | tuple) and all(
        isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) for v in value)
    if not ok or (size is not None and len(value) != size):
        what = f"{size} finite numbers" if size is not None else "a list of finite numbers"
        raise RobotError(f"robot parameter {_key(key)}: got {value!r}, expected {what}")
    return tuple(float(v) for v in value)


def _pose(flat: Mapping[str, Any], key: str) -> Pose6:
    x, y, z, r, p, w = _numbers(flat, key, 6, IDENTITY)
    return (x, y, z, r, p, w)


def robot_from_parameters(flat: Mapping[str, Any], source: Path | None = None) -> RobotDescription:
    """Build a RobotDescription from flattened ``robot.*`` parameters; RobotError naming the key."""
    known = {PREFIX + k for k in KEYS}
    for key in flat:
        if key.startswith(PREFIX) and key not in known and not key.startswith(PREFIX + "locked."):
            raise RobotError(f"robot parameter '{key}': unknown key; valid keys: {', '.join(KEYS)}, locked.<joint>")
    if not any(k.startswith(PREFIX) for k in flat):
        raise RobotError(f"robot description {source}: no 'robot:' parameters (docs/robots.md)")
    left, right = _names(flat, "left_joints"), _names(flat, "right_joints")
    pair = flat.get(PREFIX + "pair", False)
    if not isinstance(pair, bool):
        raise RobotError(f"robot parameter {_key('pair')}: got {pair!r}, expected true or false")
    both = sorted(set(left) & set(right))
    if both and not pair:
        raise RobotError(f"robot parameters {_key('left_joints')} and {_key('right_joints')}: "
                         f"{', '.join(both)} in both arms")
    ready = _numbers(flat, "ready_positions_deg", None)
    if len(ready) != len(left) + len(right):
        raise RobotError(f"robot parameter {_key('ready_positions_deg')}: got {len(ready)} values, expected "
                         f"{len(left) + len(right)} ({len(left)} left then {len(right)} right joints)")
    acc = _numbers(flat, "acceleration_limit", None, ())
    if acc and (len(acc) not in (1, len(left) + len(right)) or any(a <= 0 for a in acc)):
        raise RobotError(f"robot parameter {_key('acceleration_limit')}: got {list(acc)}, expected values > 0, "
                         f"one for all joints or {len(left) + len(right)}")
    locked = []
    for key, value in flat.items():
        if key.startswith(PREFIX + "locked."):
            if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
                raise RobotError(f"robot parameter '{key}': got {value!r}, expected a finite number")
            locked.append((key[len(PREFIX + "locked."):], float(value)))
    base = source.parent if source is not None else Path.cwd()
    return RobotDescription(
        name=_text(flat, "name"), description=str(flat.get(PREFIX + "description", "")),
        urdf=urdf_file(_text(flat, "urdf"), base), left_joints=left, right_joints=right,
        left_tool=_text(flat, "left_tool"), right_tool=_text(flat, "right_tool"),
        left_tool_offset=_pose(flat, "left_tool_offset"), right_tool_offset=_pose(flat, "right_tool_offset"),
        pair=pair, left_base=_pose(flat, "left_base"), right_base=_pose(flat, "right_base"),
        locked=tuple(locked), ready_positions=tuple(math.radians(v) for v in ready),
        acceleration_limit=acc, collision_allowed=_link_pairs(flat, "collision_allowed"),
        tools=_tools(flat, base), source=source)


def _tools(flat: Mapping[str, Any], base: Path) -> ToolSet | None:
    """``robot.tools``: a tool set's name or YAML path (relative to the description's folder), or none."""
    value = flat.get(PREFIX + "tools", "")
    if value == "":
        return None
    if not isinstance(value, str):
        raise RobotError(f"robot parameter {_key('tools')}: got {value!r}, expected a tool set's name "
                         f"({', '.join(tool_set_names())}) or a YAML path")
    return load_tool_set(value, base)


def _link_pairs(flat: Mapping[str, Any], key: str) -> tuple[tuple[str, str], ...]:
    """``robot.<key>``: a list of ``"link_a link_b"`` strings as pairs (RobotError naming a bad entry)."""
    try:
        return link_pairs(flat.get(PREFIX + key, []), PREFIX + key)
    except ParameterError as exc:
        raise RobotError(f"robot parameter {_key(key)}: {exc.expected}") from None
