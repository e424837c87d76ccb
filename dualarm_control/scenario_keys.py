"""The readers of a scenario file's keys (``scenario.<key>`` of its flattened parameters): each gives
the value or a ScenarioError naming the full key and what it expected."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
import numpy.typing as npt

from dualarm_control.errors import ScenarioError

PREFIX = "scenario."
"""The scenario parameters' prefix in the trajectory node's parameter file."""


def get(flat: Mapping[str, Any], key: str, default: Any = None) -> Any:
    """``scenario.<key>`` of flattened parameters; ScenarioError naming the full key when missing without default."""
    full = PREFIX + key
    if full in flat:
        return flat[full]
    if default is None:
        raise ScenarioError(f"scenario parameter '{full}' is missing")
    return default


def vector(flat: Mapping[str, Any], key: str, size: int) -> npt.NDArray[np.float64]:
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
