"""Reading a plan.json (written by ``dualarm plan``) for execution: format tag, scenario, configurations."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from dualarm_control.errors import ScenarioError
from dualarm_control.kinematics import FloatArray

PLAN_FORMAT = "dualarm_control/plan/1"
LIMIT_TOLERANCE = 1e-9
"""[rad] a planned configuration may lie this far beyond a joint limit (rounding of the optimiser's bound)."""


def load_plan(path: str | Path) -> dict[str, Any]:
    """Read a plan.json and check its format tag (ScenarioError naming the file otherwise)."""
    p = Path(path)
    if not p.is_file():
        raise ScenarioError(f"plan {p}: file not found")
    try:
        doc = json.loads(p.read_text())
    except json.JSONDecodeError as exc:
        raise ScenarioError(f"plan {p}: not JSON ({exc})") from None
    if not isinstance(doc, dict) or doc.get("format") != PLAN_FORMAT:
        got = doc.get("format") if isinstance(doc, dict) else None
        raise ScenarioError(f"plan {p}: not a {PLAN_FORMAT} document (format={got!r})")
    return doc


@dataclass(frozen=True)
class Plan:
    """What execution needs of a plan.

    Attributes:
        scenario: name of the scenario whose path was planned (``scenario.corner.*``).
        joint_names: joint order of the configurations (the model's).
        configurations: planned q_i, (h, 14) [rad], one per path sample.
    """

    scenario: str
    joint_names: tuple[str, ...]
    configurations: FloatArray


def read_plan(path: str | Path, joint_names: list[str], q_min: FloatArray | None = None,
              q_max: FloatArray | None = None) -> Plan:
    """:class:`Plan` of a plan.json; ScenarioError naming the file and what is wrong when its joints do not
    match ``joint_names``, a configuration has another joint count, is not finite, or (with ``q_min`` and
    ``q_max`` [rad], the model's limits) lies beyond the joint limits."""
    doc = load_plan(path)
    if list(doc.get("joint_names", [])) != list(joint_names):
        raise ScenarioError(f"plan {path}: joint names {doc.get('joint_names')} differ from the model's")
    points = doc.get("points")
    if not isinstance(points, list) or not points:
        raise ScenarioError(f"plan {path}: 'points' must be a non-empty list, got {type(points).__name__}")
    rows = []
    for i, point in enumerate(points):
        row = point.get("configuration_rad") if isinstance(point, dict) else None
        if not isinstance(row, list) or len(row) != len(joint_names):
            count = len(row) if isinstance(row, list) else "no"
            raise ScenarioError(f"plan {path}: point {i} has {count} joint values, expected {len(joint_names)}")
        try:
            rows.append([float(v) for v in row])
        except (TypeError, ValueError):
            raise ScenarioError(f"plan {path}: point {i} has a value that is not a number: {row}") from None
    q = np.array(rows, dtype=float)
    bad = np.argwhere(~np.isfinite(q))
    if len(bad):
        i, j = bad[0]
        raise ScenarioError(f"plan {path}: point {i}, joint {joint_names[j]}: {q[i, j]} is not finite")
    if q_min is not None and q_max is not None:
        beyond = np.argwhere((q < np.asarray(q_min) - LIMIT_TOLERANCE) | (q > np.asarray(q_max) + LIMIT_TOLERANCE))
        if len(beyond):
            i, j = beyond[0]
            raise ScenarioError(f"plan {path}: point {i}, joint {joint_names[j]}: {q[i, j]:.6g} rad is beyond the "
                                f"joint limits [{q_min[j]:.6g}, {q_max[j]:.6g}] ({len(beyond)} values beyond)")
    return Plan(str(doc["scenario"]), tuple(joint_names), q)
