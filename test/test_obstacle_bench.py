"""``dualarm bench --obstacles N`` (docs/obstacles.md): the parts run on a small case, and bad counts are refused.
The figures themselves are measured by the command, not asserted here (they are the machine's)."""

from __future__ import annotations

import subprocess
import sys

import numpy as np

from dualarm_control.app.bench.obstacles import (
    NEAR,
    bench_cloud,
    format_obstacle_bench,
    scattered_obstacles,
)
from dualarm_control.collision import CollisionModel
from dualarm_control.collision.live import LiveDistances
from dualarm_control.kinematics import DualArmModel


def test_scattered_obstacles_keep_their_clearance() -> None:
    m = DualArmModel("lwr4_cell")
    c = CollisionModel(m, allowed=m.description.collision_allowed)
    distances = LiveDistances(c.model, c.geometry)
    path = np.asarray(m.description.ready, dtype=float) + np.linspace(0.0, 0.2, 40)[:, None]
    obstacles = scattered_obstacles(5, distances, path, clearance=NEAR)
    assert len(obstacles) == 5
    for q in path[::20]:
        pairs = distances.near(q, tuple(obstacles), NEAR)
        assert not len(pairs) or pairs.distance.min() >= NEAR


def test_cloud_intake_is_timed_in_periods() -> None:
    cloud = bench_cloud(0.005, repetitions=3, points=20_000)
    assert cloud["voxels"] > 100 and cloud["worker_p50_ms"] > 0.0
    assert cloud["worker_p50_periods"] == cloud["worker_p50_ms"] / 5.0
    row = {"obstacles": 20, "rows_mean": 1.0, "with_p50_ms": 1.0, "with_p99_ms": 2.0, "without_p50_ms": 1.0,
           "without_p99_ms": 2.0, "ratio_p50": 1.0, "ratio_p99": 1.0}
    text = format_obstacle_bench({"standard_qp | >= 3.5 cm": row}, cloud)
    assert "| standard_qp | >= 3.5 cm | 20 |" in text and "20000 points" in text


def test_bad_counts_are_refused() -> None:
    for count in ("300", "-1"):
        out = subprocess.run([sys.executable, "-m", "dualarm_control.app.cli", "bench", "--obstacles", count],
                             check=False, capture_output=True, text=True, timeout=120)
        assert out.returncode == 2 and "--obstacles" in out.stderr, (count, out.stderr[-500:])
