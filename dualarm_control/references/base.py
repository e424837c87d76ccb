"""The reference-source interface of a scenario, and the readers of the scenario file's keys.

A scenario (:class:`dualarm_control.scenario.Scenario`) is the cell (URDF, initial
configuration), the motion limits and ONE reference source: what the controller is asked to
follow. The kinds today:

* ``segments`` (paper 000, :class:`~dualarm_control.references.segments.SegmentsSource`):
  relative pose/screw segments, timed by ruckig from the measured start pose and streamed as
  relative targets (/relative_target) to the relative pose task;
* ``tasks`` (paper 001, :class:`~dualarm_control.references.tasks.TasksSource`): a set of
  tasks with gains and bounds evaluated at the cycle's time, optionally closed over a force
  sensor (/wrench); no target stream;
* ``plan`` (paper 003, :class:`~dualarm_control.references.plan.PlanSource`): a planned
  joint trajectory (/joint_reference) tracked in joint space.

A fourth source, e.g. timed relative goals and twists replanned online by ruckig (issue 18),
is one more class with these members; the consumers (runner, nodes, report) read only them.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any, ClassVar, Protocol

import numpy as np

from dualarm_control.errors import ScenarioError
from dualarm_control.kinematics import FloatArray

PREFIX = "scenario."

RELATIVE_TARGET = "/relative_target"
JOINT_REFERENCE = "/joint_reference"
WRENCH = "/wrench"


class ReferenceSource(Protocol):
    """What a scenario's controller follows (module docstring).

    Attributes:
        kind: "segments", "tasks", "plan" (issue 18: "goals"): names the report's figures and
            the run record's optional fields (task values where there are tasks, force where
            there is force).
        streams: the topics a controller cycle consumes besides /joint_states, in the node
            (the source decides what the controller node subscribes): segments
            (/relative_target), plan (/joint_reference), tasks with force (/wrench), none
            for tasks without force.

    Methods:
        describe(): one line for logs ("3 segments", "6 tasks", "plan <file>").
    """

    kind: ClassVar[str]

    @property
    def streams(self) -> tuple[str, ...]: ...

    def describe(self) -> str: ...


def get(flat: Mapping[str, Any], key: str, default: Any = None) -> Any:
    """``scenario.<key>`` of flattened parameters; ScenarioError naming the full key when missing without default."""
    full = PREFIX + key
    if full in flat:
        return flat[full]
    if default is None:
        raise ScenarioError(f"scenario parameter '{full}' is missing")
    return default


def vector(flat: Mapping[str, Any], key: str, size: int) -> FloatArray:
    """``scenario.<key>`` as ``size`` finite numbers; ScenarioError naming the key and value otherwise."""
    value = get(flat, key)
    if not isinstance(value, list) or len(value) != size or not all(
        isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) for v in value
    ):
        raise ScenarioError(f"scenario parameter '{PREFIX}{key}': got {value!r}, expected a list of {size} numbers")
    return np.array(value, dtype=float)


def number(flat: Mapping[str, Any], key: str, default: float | None = None) -> float:
    """``scenario.<key>`` as a finite number; ScenarioError naming the key and value otherwise."""
    value = get(flat, key, default)
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ScenarioError(f"scenario parameter '{PREFIX}{key}': got {value!r}, expected a number")
    return float(value)
