"""Scenarios: initial configuration + relative motion segments, read from ROS-style YAML.

A scenario file is a parameter file (``/**: ros__parameters: scenario: ...``) so the sim
node (initial configuration), the trajectory node (segments) and the in-process experiment
read the same keys. Registry: every ``config/scenarios/<name>.yaml`` is scenario ``<name>``.

Keys under ``scenario.`` (flattened names):
  name, description, initial_positions_deg (14 doubles: left 1..7, right 1..7),
  settle_time [s], limits.<MotionLimits field>, segments (ordered list of names), and per
  segment ``<seg>.type``: ``pose`` (``position`` [m] and ``rpy_deg`` of the peg frame F2 in
  the hole frame F1) or ``screw`` (``axis`` in F1, ``angle_deg``, ``advance`` [m]); ``<seg>.hold`` [s].
  Optional ``urdf``: the cell URDF's file name in ``urdf/`` (default ``dualarm_cell.urdf``).
  A task scenario (paper 001) has ``tasks`` instead of ``segments``: see
  :mod:`dualarm_control.task_scenario`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pinocchio as pin

from dualarm_control.errors import ScenarioError
from dualarm_control.kinematics import FloatArray
from dualarm_control.params import ParameterError, read_params_file
from dualarm_control.paths import config_path, share_dir
from dualarm_control.trajectory import MotionLimits, RelativeTrajectory, Segment

if TYPE_CHECKING:
    from dualarm_control.task_scenario import TaskScenario

PREFIX = "scenario."
DEFAULT_URDF = "dualarm_cell.urdf"


@dataclass(frozen=True)
class SegmentSpec:
    """One segment as written in the file (resolved against the start pose later)."""

    name: str
    kind: str  # "pose" | "screw"
    position: FloatArray | None = None
    rotation: FloatArray | None = None
    axis: FloatArray | None = None
    angle: float = 0.0
    advance: float = 0.0
    hold: float = 0.0


@dataclass(frozen=True)
class Scenario:
    """A validated scenario.

    Attributes:
        name, description: labels.
        initial_positions: joint positions at start [rad], (14,).
        segments: motion segments in order.
        limits: ruckig limits of the relative motion.
        settle_time: control time after the trajectory ends [s] (error convergence).
        source: file it came from.
        urdf: the cell URDF's file name in ``urdf/``.
        tasks: the task part of a task scenario (paper 001), else None.
    """

    name: str
    description: str
    initial_positions: FloatArray
    segments: tuple[SegmentSpec, ...]
    limits: MotionLimits
    settle_time: float
    source: Path
    urdf: str = DEFAULT_URDF
    tasks: TaskScenario | None = None

    @property
    def urdf_path(self) -> Path:
        """Path of the scenario's cell URDF."""
        return share_dir() / "urdf" / self.urdf

    def trajectory(self, start_position: FloatArray, start_rotation: FloatArray) -> RelativeTrajectory:
        """The ruckig relative trajectory from the measured start pose through all segments."""
        if not self.segments:
            raise ScenarioError(f"scenario {self.name!r} is a task scenario (paper 001) without relative motion "
                                "segments: run it with 'dualarm experiment' (constraint_based solver)")
        segments: list[Segment] = []
        p, r = np.asarray(start_position, float), np.asarray(start_rotation, float)
        for spec in self.segments:
            if spec.kind == "pose":
                assert spec.position is not None and spec.rotation is not None
                seg = Segment.to_pose(spec.name, r, spec.position, spec.rotation, hold=spec.hold)
            else:
                assert spec.axis is not None
                seg = Segment.screw(spec.name, p, spec.axis, spec.angle, spec.advance, hold=spec.hold)
            segments.append(seg)
            p = np.asarray(seg.position)
            r = pin.exp3(seg.axis * seg.angle) @ r
        return RelativeTrajectory(start_position, start_rotation, segments, self.limits)


def scenario_names() -> list[str]:
    """Names of the scenarios shipped in config/scenarios/."""
    return sorted(p.stem for p in config_path("scenarios").glob("*.yaml"))


def scenario_file(name_or_path: str) -> Path:
    """Path of a scenario given by registry name or file path (ScenarioError if unknown)."""
    path = Path(name_or_path)
    if path.suffix in (".yaml", ".yml"):
        if not path.is_file():
            raise ScenarioError(f"scenario file not found: {path}")
        return path
    candidate = config_path("scenarios", f"{name_or_path}.yaml")
    if not candidate.is_file():
        raise ScenarioError(f"unknown scenario {name_or_path!r}; valid choices: {', '.join(scenario_names())}")
    return candidate


def load_scenario(name_or_path: str) -> Scenario:
    """Load and validate a scenario by registry name or path."""
    path = scenario_file(name_or_path)
    try:
        flat = read_params_file(path, "trajectory_node")
    except ParameterError as exc:
        raise ScenarioError(str(exc)) from None
    return scenario_from_parameters(flat, path)


def _get(flat: Mapping[str, Any], key: str, default: Any = None) -> Any:
    full = PREFIX + key
    if full in flat:
        return flat[full]
    if default is None:
        raise ScenarioError(f"scenario parameter '{full}' is missing")
    return default


def _vector(flat: Mapping[str, Any], key: str, size: int) -> FloatArray:
    value = _get(flat, key)
    if not isinstance(value, list) or len(value) != size or not all(
        isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) for v in value
    ):
        raise ScenarioError(f"scenario parameter '{PREFIX}{key}': got {value!r}, expected a list of {size} numbers")
    return np.array(value, dtype=float)


def _number(flat: Mapping[str, Any], key: str, default: float | None = None) -> float:
    value = _get(flat, key, default)
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ScenarioError(f"scenario parameter '{PREFIX}{key}': got {value!r}, expected a number")
    return float(value)


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


def scenario_from_parameters(flat: Mapping[str, Any], source: Path) -> Scenario:
    """Build a Scenario from flattened parameters (as read from the file or declared in a node)."""
    tasks = None
    if PREFIX + "tasks" in flat:
        from dualarm_control.task_scenario import parse_task_scenario

        tasks = parse_task_scenario(flat)
    names = _get(flat, "segments", [] if tasks is not None else None)
    if not isinstance(names, list) or not all(isinstance(n, str) for n in names) or not (names or tasks):
        raise ScenarioError(f"scenario parameter '{PREFIX}segments': got {names!r}, expected a list of segment names")
    specs = []
    for seg in names:
        kind = _get(flat, f"{seg}.type")
        hold = _number(flat, f"{seg}.hold", 0.0)
        if kind == "pose":
            rpy = np.radians(_vector(flat, f"{seg}.rpy_deg", 3))
            specs.append(SegmentSpec(seg, "pose", position=_vector(flat, f"{seg}.position", 3),
                                     rotation=pin.rpy.rpyToMatrix(*rpy), hold=hold))
        elif kind == "screw":
            specs.append(SegmentSpec(seg, "screw", axis=_vector(flat, f"{seg}.axis", 3),
                                     angle=math.radians(_number(flat, f"{seg}.angle_deg", 0.0)),
                                     advance=_number(flat, f"{seg}.advance", 0.0), hold=hold))
        else:
            raise ScenarioError(f"scenario parameter '{PREFIX}{seg}.type': got {kind!r}, expected one of: pose, screw")
    limits = _motion_limits(flat)
    settle = _number(flat, "settle_time", 1.0)
    if settle < 0:
        raise ScenarioError(f"scenario parameter '{PREFIX}settle_time': got {settle}, expected >= 0")
    urdf = _get(flat, "urdf", DEFAULT_URDF)
    if not isinstance(urdf, str) or not (share_dir() / "urdf" / urdf).is_file():
        raise ScenarioError(f"scenario parameter '{PREFIX}urdf': got {urdf!r}, expected a file name in "
                            f"{share_dir() / 'urdf'}")
    return Scenario(
        name=str(_get(flat, "name")),
        description=str(_get(flat, "description", "")),
        initial_positions=np.radians(_vector(flat, "initial_positions_deg", 14)),
        segments=tuple(specs),
        limits=limits,
        settle_time=settle,
        source=source,
        urdf=urdf,
        tasks=tasks,
    )
