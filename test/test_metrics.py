"""Tests of dualarm_control.metrics (Table I norms, limit violations, percentiles) on hand-made data."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dualarm_control.metrics import (
    active_set_switches_per_s,
    joint_limit_metrics,
    l0_norms,
    limit_violations,
    max_joint_acceleration,
    percentiles,
    velocity_norm_metrics,
)


def test_norms_of_two_hand_made_samples() -> None:
    """Two samples of 3 joints, period 0.5 s: every mean and integral computed by hand."""
    qd = np.array([[3.0, -4.0, 0.0], [1e-3, 0.0, -2.0]])  # 1e-3 exactly is NOT active (strict >)
    m = velocity_norm_metrics(qd, period=0.5)
    assert m.duration_s == 1.0
    assert m.l0_mean == pytest.approx((2 + 1) / 2)
    assert m.l1_mean == pytest.approx((7.0 + 2.001) / 2)
    assert m.l2_mean == pytest.approx((5.0 + math.sqrt(4.0 + 1e-6)) / 2)
    assert m.l0_integral == pytest.approx(3 * 0.5)
    assert m.l1_integral == pytest.approx(9.001 * 0.5)
    assert m.l2_integral == pytest.approx((5.0 + math.sqrt(4.000001)) * 0.5)


def test_activity_threshold_is_strict() -> None:
    """|qd| = 1e-3 is inactive, the next double above it is active, sign does not matter."""
    above = np.nextafter(1e-3, 1.0)
    qd = np.array([[1e-3, -1e-3, above, -above, 0.0]])
    np.testing.assert_array_equal(l0_norms(qd), [2.0])
    assert velocity_norm_metrics(qd, 0.005).l0_mean == 2.0
    np.testing.assert_array_equal(l0_norms(qd, threshold=0.0), [4.0])


def test_integral_is_mean_times_duration() -> None:
    """For random data (seeded), each integral equals its mean times N * period (zero-order hold)."""
    rng = np.random.default_rng(3)
    qd = rng.normal(0.0, 0.01, (37, 14))
    period = 0.005
    m = velocity_norm_metrics(qd, period)
    assert m.duration_s == pytest.approx(37 * period)
    for p in ("l0", "l1", "l2"):
        assert getattr(m, f"{p}_integral") == pytest.approx(getattr(m, f"{p}_mean") * m.duration_s, rel=1e-12)
    assert m.l1_integral == pytest.approx(np.abs(qd).sum() * period, rel=1e-12)
    assert m.l2_integral == pytest.approx(sum(math.sqrt(float(row @ row)) for row in qd) * period, rel=1e-12)


@pytest.mark.parametrize("bad", [np.zeros((0, 14)), np.zeros(14), np.zeros((2, 3, 4))])
def test_norm_metrics_reject_bad_shapes(bad: np.ndarray) -> None:
    """Empty or non-2D arrays raise ValueError naming the shape."""
    with pytest.raises(ValueError, match="shape"):
        velocity_norm_metrics(bad, 0.005)


def test_limit_violations_count_rows() -> None:
    """Rows with any joint outside [lower - tol, upper + tol] are counted once, hand-checked."""
    lower, upper = np.array([-1.0, -2.0]), np.array([1.0, 2.0])
    values = np.array([
        [0.0, 0.0],  # inside
        [1.05, 2.5],  # two joints out: one row
        [-1.0, 2.0],  # on the limits: inside
        [1.0 + 0.5e-3, 0.0],  # within the tolerance
        [0.0, -2.01],  # out
    ])
    assert limit_violations(values, lower, upper, tolerance=1e-3) == 2
    assert limit_violations(values, lower, upper, tolerance=0.0) == 3
    assert limit_violations(values, lower, upper, tolerance=1.0) == 0


def test_percentiles() -> None:
    """Median and p99 of 0..100 are 50 and 99; an empty sample gives NaNs."""
    assert percentiles(np.arange(101.0)) == (50.0, 99.0)
    assert percentiles(np.arange(101.0), (0.0, 100.0)) == (0.0, 100.0)
    assert all(math.isnan(v) for v in percentiles(np.array([])))


def test_max_joint_acceleration_by_hand() -> None:
    """Largest |dqd| / T over joints and cycles; 0 for one sample."""
    qd = np.array([[0.0, 0.1], [0.02, 0.1], [0.02, -0.2]])
    assert max_joint_acceleration(qd, 0.005) == pytest.approx(0.3 / 0.005)
    assert max_joint_acceleration(qd[:1], 0.005) == 0.0


def test_active_set_switches_per_s_by_hand() -> None:
    """Joints entering or leaving |qd| > 1e-3, counted per cycle, over N T seconds."""
    qd = np.array([[0.0, 0.5, 0.0], [0.01, 0.5, 0.0], [0.0, 0.0, 0.002], [0.0, 0.0, 0.002]])
    # cycle 1: joint 0 enters (1); cycle 2: joint 0 leaves, 1 leaves, 2 enters (3); cycle 3: none
    assert active_set_switches_per_s(qd, 0.5) == pytest.approx(4 / (4 * 0.5))
    assert active_set_switches_per_s(np.full((5, 2), 1e-3), 0.5) == 0.0  # exactly 1e-3 is not active


def test_joint_limit_metrics_on_a_hand_computed_trajectory() -> None:
    """Issue 43: two joints, limits [-1, 1] and [0, 2], alpha 0.2 (zone: margin < 0.1 of the range), T = 0.01 s.
    Joint 0 at 0, 0.7, 0.85, 0.95 has margins 0.5, 0.15, 0.075, 0.025 (two cycles in the zone); joint 1 stays
    at mid-range; the final state (0.9, 1.0) has margin 0.05."""
    cycles = np.array([[0.0, 1.0], [0.7, 1.0], [0.85, 1.0], [0.95, 1.0]])
    m = joint_limit_metrics(cycles, np.array([0.9, 1.0]), np.array([-1.0, 0.0]), np.array([1.0, 2.0]), 0.2, 0.01)
    assert m.min_margin == pytest.approx(0.025)
    assert m.final_margin == pytest.approx(0.05)
    assert m.zone_joint_seconds == pytest.approx(0.02)
    assert m.zone_joints == 1 and m.alpha == 0.2
    # depth (0.1 - m) / 0.1 of the two zone cycles: 0.25 and 0.75, times 0.01 s
    assert m.zone_depth_seconds == pytest.approx(0.01)
    beyond = joint_limit_metrics(np.array([[1.1, 1.0]]), np.array([1.1, 1.0]), np.array([-1.0, 0.0]),
                                 np.array([1.0, 2.0]), 0.2, 0.01)
    assert beyond.min_margin == pytest.approx(-0.05) and beyond.zone_joint_seconds == pytest.approx(0.01)
    none = joint_limit_metrics(cycles, cycles[0], np.array([-1.0, 0.0]), np.array([1.0, 2.0]), 0.0, 0.01)
    assert none.zone_joint_seconds == 0.0 and none.zone_joints == 0  # alpha 0: no zone
