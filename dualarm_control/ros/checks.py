"""ROS-free checks of received values, shared by the input decoders (:mod:`.convert`) and the
command outputs' decoders (:mod:`dualarm_control.outputs`): finiteness, and joints matched by name."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np


def finite(values: np.ndarray) -> bool:
    """Every entry finite (the sum first: one pass in the common case; overflow is checked entrywise)."""
    return math.isfinite(float(values.sum())) or bool(np.isfinite(values).all())


def joint_indices(names: Sequence[str], order: Mapping[str, int], what: str) -> list[int] | str:
    """Index in ``names`` of each of the model's joints (``order``: name -> model index), or why not.

    Order is mapped by name; extra names (joints the controller does not drive) are ignored;
    a missing or duplicated name makes the message unusable.
    """
    position = {name: i for i, name in enumerate(names)}
    if len(position) != len(names):
        duplicates = sorted({n for n in names if names.count(n) > 1})
        return f"{what} has duplicate joint names {duplicates[:3]}"
    missing = [n for n in order if n not in position]
    if missing:
        return f"{what} is missing {len(missing)} of the {len(order)} joints, e.g. {missing[:3]} (got {list(names)[:3]}...)"
    return [position[n] for n in order]
