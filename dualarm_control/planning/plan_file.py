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


def read_plan(path: str | Path, joint_names: list[str]) -> Plan:
    """:class:`Plan` of a plan.json; ScenarioError when its joints do not match ``joint_names``."""
    doc = load_plan(path)
    if list(doc.get("joint_names", [])) != list(joint_names):
        raise ScenarioError(f"plan {path}: joint names {doc.get('joint_names')} differ from the model's")
    q = np.array([point["configuration_rad"] for point in doc["points"]], dtype=float)
    if q.ndim != 2 or q.shape[1] != len(joint_names) or not np.all(np.isfinite(q)):
        raise ScenarioError(f"plan {path}: configurations of shape {q.shape}, expected (h, {len(joint_names)})")
    return Plan(str(doc["scenario"]), tuple(joint_names), q)
