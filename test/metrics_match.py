"""One comparison of a bag's metrics with the in-process run's (the lockstep-over-ROS tests)."""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from typing import Any

WALL_CLOCK = ("cycle_time_p50_s", "cycle_time_p99_s")
"""Measured on the wall clock, not reproducible: left out of every comparison."""


def assert_same_metrics(got: Mapping[str, Any], expected: Mapping[str, Any], rel_tol: float = 0.0,
                        ignore: Iterable[str] = ()) -> None:
    """The same keys, and every value but the wall-clock ones and ``ignore`` equal: exactly with ``rel_tol`` 0
    (NaN equals NaN), else floats within ``rel_tol`` (and 1e-12 absolute); the failure names the key."""
    assert set(got) == set(expected), set(got) ^ set(expected)
    skip = set(WALL_CLOCK) | set(ignore)
    for key, value in expected.items():
        if key in skip:
            continue
        found = got[key]
        if isinstance(value, float) and math.isnan(value):
            assert math.isnan(float(found)), (key, found, value)
        elif isinstance(value, float) and rel_tol > 0.0:
            assert math.isclose(float(found), value, rel_tol=rel_tol, abs_tol=1e-12), (key, found, value)
        else:
            assert found == value, (key, found, value)
