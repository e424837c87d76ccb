"""ROS-free checks of received values, shared by the input decoders (:mod:`.convert`) and the
command outputs' decoders (:mod:`dualarm_control.outputs`): finiteness, and joints matched by name."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np

from dualarm_control.errors import InputRejected


def finite(values: np.ndarray) -> bool:
    """Every entry finite (the sum first: one pass in the common case; overflow is checked entrywise)."""
    return math.isfinite(float(values.sum())) or bool(np.isfinite(values).all())


def joint_indices(names: Sequence[str], order: Mapping[str, int], what: str) -> list[int]:
    """Index in ``names`` of each of the model's joints (``order``: name -> model index).

    Order is mapped by name; extra names (joints the controller does not drive) are ignored;
    a missing or duplicated name makes the message unusable: :class:`InputRejected` (``field``
    ``name``, ``value`` the duplicated or the missing names), its reason naming ``what``.
    """
    position = {name: i for i, name in enumerate(names)}
    if len(position) != len(names):
        duplicates = sorted({n for n in names if names.count(n) > 1})
        raise InputRejected(f"{what} has duplicate joint names {duplicates[:3]}", "name", duplicates)
    missing = [n for n in order if n not in position]
    if missing:
        raise InputRejected(f"{what} is missing {len(missing)} of the {len(order)} joints, e.g. {missing[:3]} "
                            f"(got {list(names)[:3]}...)", "name", missing)
    return [position[n] for n in order]
