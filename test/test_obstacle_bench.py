"""``dualarm bench --obstacles N`` (docs/obstacles.md): the parts run on a small case, and bad counts are refused.
The figures themselves are measured by the command, not asserted here (they are the machine's)."""

from __future__ import annotations

import subprocess
import sys
import time

import numpy as np
import pytest

from dualarm_control.app.bench.obstacles import (
    MOVE_AMPLITUDE,
    NEAR,
    bench_cloud,
    format_obstacle_bench,
    moving_snapshots,
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


def test_moving_snapshots_swing_the_same_shapes_with_their_velocities() -> None:
    """The moving scene: one snapshot per cycle, the same names and shape objects (as the intake keeps them), each
    within the amplitude of its place, its velocity the derivative of its position (central differences)."""
    m = DualArmModel("lwr4_cell")
    c = CollisionModel(m, allowed=m.description.collision_allowed)
    path = np.asarray(m.description.ready, dtype=float)[None, :]
    obstacles = scattered_obstacles(4, LiveDistances(c.model, c.geometry), path, clearance=NEAR)
    period = 0.005
    snapshots = moving_snapshots(obstacles, 400, period)
    assert len(snapshots) == 400
    for snapshot in snapshots:
        assert [o.name for o in snapshot] == [o.name for o in obstacles]
        assert all(a.shape is b.shape for a, b in zip(snapshot, obstacles))
        assert all(np.linalg.norm(a.position - b.position) <= MOVE_AMPLITUDE + 1e-12 for a, b in zip(snapshot, obstacles))
    swing = max(np.linalg.norm(a.position - b.position) for s in snapshots for a, b in zip(s, obstacles))
    assert swing > 0.9 * MOVE_AMPLITUDE
    for k in range(1, 399):
        for before, now, after in zip(snapshots[k - 1], snapshots[k], snapshots[k + 1]):
            np.testing.assert_allclose(now.velocity, (after.position - before.position) / (2 * period), atol=1e-5)


def test_cloud_intake_is_timed_in_periods() -> None:
    cloud = bench_cloud(0.005, repetitions=3, points=20_000)
    assert cloud["voxels"] > 100 and cloud["worker_p50_ms"] > 0.0
    assert cloud["worker_p50_periods"] == cloud["worker_p50_ms"] / 5.0
    row = {"obstacles": 20, "rows_mean": 1.0, "with_p50_ms": 1.0, "with_p99_ms": 2.0, "without_p50_ms": 1.0,
           "without_p99_ms": 2.0, "ratio_p50": 1.0, "ratio_p99": 1.0}
    text = format_obstacle_bench({"standard_qp | >= 3.5 cm": row, "sparse_qp | >= 3.5 cm": {**row, "paired_ratio_p50": 1.25}},
                                 cloud)
    assert "| standard_qp | >= 3.5 cm | 20 |" in text and "20000 points" in text
    assert text.splitlines()[2].endswith("| 1.00x / 1.00x | - |") and text.splitlines()[3].endswith("| 1.25x |")


def test_the_paired_ratio_is_the_median_of_each_cycles_ratio(monkeypatch: pytest.MonkeyPatch) -> None:
    """On a clock of the test's own (each step advances it by its case's duration): a controller that adds 0.3 to
    every cycle of a bimodal set (half 0.2, half 1.0). Per cycle the ratio is 2.5 or 1.3, their median 1.9; the p50s
    fall between the modes (0.6 and 0.9), their ratio 1.5."""
    from dualarm_control.app.bench.obstacles import interleaved

    now = [0.0]
    monkeypatch.setattr(time, "perf_counter", lambda: now[0])

    class Timed:
        def __init__(self, extra: float) -> None:
            self.extra = extra

        def step(self, q: float, target: object) -> object:
            now[0] += q + self.extra
            return type("Cycle", (), {"reports": {}})()

    row = interleaved(Timed(0.3), Timed(0.0), [(0.2, None)] * 10 + [(1.0, None)] * 10)  # type: ignore[arg-type]
    assert row["paired_ratio_p50"] == pytest.approx(1.9)
    assert row["ratio_p50"] == pytest.approx(1.5)


def test_bad_counts_are_refused() -> None:
    for count in ("300", "-1"):
        out = subprocess.run([sys.executable, "-m", "dualarm_control.app.cli", "bench", "--obstacles", count],
                             check=False, capture_output=True, text=True, timeout=120)
        assert out.returncode == 2 and "--obstacles" in out.stderr, (count, out.stderr[-500:])
