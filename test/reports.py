"""Comparing two ``dualarm report`` outputs (their metrics.json): every metric equal to a tolerance."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import pytest


def report_metrics(out: Path) -> dict[str, dict[str, Any]]:
    """The metrics.json ``dualarm report BAG --output OUT`` wrote: per run label, metric -> value."""
    return dict(json.loads((out / "metrics.json").read_text()))


def assert_same_report(want: dict[str, dict[str, Any]], got: dict[str, dict[str, Any]], abs_tol: float = 1e-6
                       ) -> int:
    """Every numeric metric of ``got`` equals ``want``'s to ``abs_tol`` (the cycle and solve times, wall-clock
    measurements, excepted; NaN where NaN); the number of metrics compared (at least 10)."""
    assert list(got) == list(want)
    compared = 0
    for label, metrics in want.items():
        for key, value in metrics.items():
            if "cycle_time" in key or "solve_time" in key or not isinstance(value, (int, float)):
                continue
            if isinstance(value, float) and math.isnan(value):
                assert math.isnan(got[label][key]), key
                continue
            assert got[label][key] == pytest.approx(value, abs=abs_tol), key
            compared += 1
    assert compared >= 10, want
    return compared
