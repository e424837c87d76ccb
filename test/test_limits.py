"""Tests of dualarm_control.limits: velocity bounds of eq (21)-(23) and repulsive velocity of eq (24)-(25)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from dualarm_control.kinematics import DualArmModel
from dualarm_control.limits import (
    Constraint,
    JointLimits,
    Limit,
    VelocityLimit,
    acceleration_bounds,
    apply_limits,
    repulsive_velocity,
    velocity_bounds,
)

FINITE = {"allow_nan": False, "allow_infinity": False}


@dataclass(frozen=True)
class Case:
    """Random limits, a period, and a configuration strictly inside the limits."""

    limits: JointLimits
    period: float
    q: np.ndarray
    fractions: np.ndarray  # in [0, 1], to pick qd in [lower, upper]


@st.composite
def cases(draw: st.DrawFn) -> Case:
    n = draw(st.integers(1, 14))
    floats = st.floats(-3.0, 3.0, **FINITE)
    lows = np.array(draw(st.lists(floats, min_size=n, max_size=n)))
    spans = np.array(draw(st.lists(st.floats(1e-3, 6.0, **FINITE), min_size=n, max_size=n)))
    qd_max = np.array(draw(st.lists(st.floats(1e-2, 4.0, **FINITE), min_size=n, max_size=n)))
    period = draw(st.sampled_from([1e-3, 5e-3, 1e-2, 0.1]))
    where = np.array(draw(st.lists(st.floats(0.0, 1.0, **FINITE), min_size=n, max_size=n)))
    fractions = np.array(draw(st.lists(st.floats(0.0, 1.0, **FINITE), min_size=n, max_size=n)))
    q = lows + where * spans
    highs = lows + spans
    q = np.clip(q, lows, highs)  # where * span can round past the upper limit
    return Case(JointLimits(lows, highs, qd_max), period, q, fractions)


def eq23(q: np.ndarray, q_min: np.ndarray, q_max: np.ndarray, qd_max: np.ndarray, period: float) -> tuple:
    """Eq (23) transcribed element by element with Python's max/min."""
    lower = np.array([max(-v, (lo - x) / period) for x, lo, v in zip(q, q_min, qd_max, strict=True)])
    upper = np.array([min(v, (hi - x) / period) for x, hi, v in zip(q, q_max, qd_max, strict=True)])
    return lower, upper


def eq25_scalar(q: float, q_min: float, q_max: float, qd_max: float, alpha: float) -> float:
    """Eq (24)-(25) for one joint, alpha in (0, 1], q in [q_min, q_max]; qd_min = -qd_max."""
    low_star = q_min + alpha * (q_max - q_min) / 2
    high_star = q_max - alpha * (q_max - q_min) / 2
    if low_star < q < high_star:
        return 0.0
    if q_min <= q <= low_star:
        return (q - low_star) ** 2 / (q_min - low_star) ** 2 * qd_max
    if high_star <= q <= q_max:
        return (q - high_star) ** 2 / (q_max - high_star) ** 2 * -qd_max
    raise AssertionError("q outside [q_min, q_max]: eq (25) does not define it")


@settings(max_examples=200, deadline=None, derandomize=True)
@given(cases())
def test_any_velocity_inside_the_bounds_keeps_q_inside_the_limits(case: Case) -> None:
    """q + qd T in [q_min, q_max] (1e-12) and |qd| <= qd_max for any qd in the eq (23) bounds."""
    lim = case.limits
    lower, upper = velocity_bounds(case.q, lim, case.period)
    assert np.all(lower <= upper)
    for qd in (lower, upper, lower + case.fractions * (upper - lower)):
        q_next = case.q + qd * case.period
        assert np.all(q_next >= lim.q_min - 1e-12)
        assert np.all(q_next <= lim.q_max + 1e-12)
        assert np.all(np.abs(qd) <= lim.qd_max * (1 + 1e-12))  # lower + 1.0 * (upper - lower) may round up


@settings(max_examples=200, deadline=None, derandomize=True)
@given(cases())
def test_bounds_equal_eq23_elementwise(case: Case) -> None:
    """velocity_bounds vs a scalar transcription of eq (23)."""
    lim = case.limits
    lower, upper = velocity_bounds(case.q, lim, case.period)
    ref_lower, ref_upper = eq23(case.q, lim.q_min, lim.q_max, lim.qd_max, case.period)
    np.testing.assert_array_equal(lower, ref_lower)
    np.testing.assert_array_equal(upper, ref_upper)


def test_bounds_lead_back_into_the_range_for_a_joint_outside_it() -> None:
    """Documented (issue 11): beyond q_max the bounds never cross; they ask for the way back (T = 0.1)."""
    lim = JointLimits(np.array([-1.0]), np.array([1.0]), np.array([2.0]))
    lower, upper = velocity_bounds(np.array([1.05]), lim, 0.1)  # eq (23) unchanged: back by 0.05 in one step
    assert lower[0] == pytest.approx(-2.0) and upper[0] == pytest.approx(-0.5)
    lower, upper = velocity_bounds(np.array([1.5]), lim, 0.1)  # 0.5 beyond > qd_max T: back at the velocity limit
    assert lower[0] == pytest.approx(-2.0) and upper[0] == pytest.approx(-2.0)
    lower, upper = velocity_bounds(np.array([1.0]), lim, 0.1)  # at the limit: stay or move back
    assert lower[0] == pytest.approx(-2.0) and upper[0] == 0.0
    lower, upper = velocity_bounds(np.array([-1.5]), lim, 0.1)
    assert lower[0] == pytest.approx(2.0) and upper[0] == pytest.approx(2.0)


@settings(max_examples=200, deadline=None, derandomize=True)
@given(cases(), st.floats(1e-3, 1.0, **FINITE))
def test_repulsive_velocity_matches_eq25(case: Case, alpha: float) -> None:
    """repulsive_velocity vs a direct scalar transcription of eq (24)-(25)."""
    lim = case.limits
    out = repulsive_velocity(case.q, lim, alpha)
    ref = [eq25_scalar(*args, alpha) for args in zip(case.q, lim.q_min, lim.q_max, lim.qd_max, strict=True)]
    np.testing.assert_allclose(out, ref, rtol=1e-9, atol=1e-12)


@settings(max_examples=200, deadline=None, derandomize=True)
@given(cases(), st.floats(1e-3, 1.0, **FINITE))
def test_repulsive_velocity_pushes_away_from_the_near_limit(case: Case, alpha: float) -> None:
    """Sign: >= 0 in the lower half of the range, <= 0 in the upper half; |qd_r| <= qd_max."""
    lim = case.limits
    out = repulsive_velocity(case.q, lim, alpha)
    mid = (lim.q_min + lim.q_max) / 2
    assert np.all(out[case.q < mid] >= 0.0)
    assert np.all(out[case.q > mid] <= 0.0)
    assert np.all(np.abs(out) <= lim.qd_max)


def test_repulsive_velocity_zero_inside_continuous_at_thresholds_and_extreme_at_limits() -> None:
    """Hand-computed thresholds (alpha = 0.2 on [-1, 3]: q* = -0.6, 2.6); values at and near them."""
    lim = JointLimits(np.array([-1.0]), np.array([3.0]), np.array([1.5]))
    alpha = 0.2

    def f(x: float) -> float:
        return float(repulsive_velocity(np.array([x]), lim, alpha)[0])

    for x in np.linspace(-0.6 + 1e-9, 2.6 - 1e-9, 101):
        assert f(float(x)) == 0.0
    for threshold in (-0.6, 2.6):
        assert f(threshold) == pytest.approx(0.0, abs=1e-15)
        for d in (1e-3, 1e-5, 1e-7):  # quadratic onset: |qd_r| = qd_max (d / 0.4)^2 -> 0
            assert abs(f(threshold - d)) <= 1.5 * (d / 0.4) ** 2 * (1 + 1e-6)
            assert abs(f(threshold + d)) <= 1.5 * (d / 0.4) ** 2 * (1 + 1e-6)
    assert f(-1.0) == pytest.approx(1.5, rel=1e-12)
    assert f(3.0) == pytest.approx(-1.5, rel=1e-12)
    assert f(-0.8) == pytest.approx(1.5 * 0.25, rel=1e-12)  # halfway: (0.2 / 0.4)^2
    assert f(2.8) == pytest.approx(-1.5 * 0.25, rel=1e-12)
    assert f(-2.0) == pytest.approx(1.5) and f(4.0) == pytest.approx(-1.5)  # saturated beyond the limits


def test_repulsive_velocity_on_the_real_model_limits() -> None:
    """One joint of the URDF model placed at 99 % of its upper range: eq (25) by hand, others 0."""
    model = DualArmModel()
    lim = JointLimits(model.q_min, model.q_max, model.qd_max)
    q = (model.q_min + model.q_max) / 2
    i = 3
    q[i] = model.q_max[i] - 0.01 * (model.q_max[i] - model.q_min[i])
    out = repulsive_velocity(q, lim, 0.1)
    half = 0.05 * (model.q_max[i] - model.q_min[i])
    expected = -((q[i] - (model.q_max[i] - half)) / half) ** 2 * model.qd_max[i]
    assert out[i] == pytest.approx(expected, rel=1e-12)
    assert expected == pytest.approx(-(0.8**2) * model.qd_max[i], rel=1e-9)
    assert np.count_nonzero(out) == 1


def test_alpha_zero_disables_repulsion() -> None:
    """alpha = 0: thresholds coincide with the limits, the module returns 0 everywhere (documented)."""
    lim = JointLimits(np.array([-1.0, -1.0]), np.array([1.0, 1.0]), np.array([1.0, 1.0]))
    np.testing.assert_array_equal(repulsive_velocity(np.array([-1.0, 1.0]), lim, 0.0), 0.0)


@pytest.mark.parametrize("alpha", [-0.1, 1.0001, float("nan")])
def test_alpha_outside_unit_interval_raises(alpha: float) -> None:
    """alpha outside [0, 1] (or NaN) raises ValueError naming alpha."""
    lim = JointLimits(np.array([-1.0]), np.array([1.0]), np.array([1.0]))
    with pytest.raises(ValueError, match="alpha"):
        repulsive_velocity(np.array([0.0]), lim, alpha)


def test_joint_limits_validation() -> None:
    """JointLimits rejects crossed position limits, non-positive velocity limits, mismatched shapes, bad scale."""
    one = np.array([1.0])
    with pytest.raises(ValueError, match="q_min"):
        JointLimits(one, one, one)
    with pytest.raises(ValueError, match="qd_max"):
        JointLimits(-one, one, 0 * one)
    with pytest.raises(ValueError, match="shapes"):
        JointLimits(-one, np.array([1.0, 2.0]), one)
    lim = JointLimits(-one, one, 2 * one)
    np.testing.assert_array_equal(lim.scaled_velocity(0.25).qd_max, [0.5])
    for factor in (0.0, 1.5):
        with pytest.raises(ValueError, match="scale"):
            lim.scaled_velocity(factor)


# ---- acceleration bound (issue 8) ------------------------------------------------------------


@settings(max_examples=200, deadline=None, derandomize=True)
@given(cases(), st.floats(0.5, 50.0, **FINITE), st.floats(-1.0, 1.0, **FINITE))
def test_acceleration_bounds_stay_inside_eq23_and_around_the_previous_command(
    case: Case, a_max: float, previous_share: float
) -> None:
    """lower' <= upper', inside eq (23); inside prev +- a T whenever that range meets eq (23) and the stop speed."""
    lower, upper = velocity_bounds(case.q, case.limits, case.period)
    previous = previous_share * case.limits.qd_max
    acc = np.full(case.q.shape, a_max)
    lo, up = acceleration_bounds(lower, upper, case.q, case.limits, previous, acc, case.period)
    assert np.all(lo <= up)
    assert np.all(lo >= lower - 1e-12) and np.all(up <= upper + 1e-12)
    step = a_max * case.period
    meets = (previous - step <= upper) & (previous + step >= lower)
    assert np.all(lo[meets] >= np.minimum(previous - step, up)[meets] - 1e-12)
    assert np.all(up[meets] <= np.maximum(previous + step, lo)[meets] + 1e-12)


def test_acceleration_bound_caps_the_speed_toward_a_near_limit() -> None:
    """Toward a limit d away, the speed is capped at the stop speed for a_max / 2: v^2/a + v T/2 <= d."""
    limits = JointLimits(np.array([-1.0]), np.array([1.0]), np.array([2.0]))
    q, period, a_max = np.array([0.99]), 0.005, np.array([10.0])
    lower, upper = velocity_bounds(q, limits, period)
    assert upper[0] == pytest.approx(2.0)  # eq (23) alone: still full speed 1 cm before the limit
    lo, up = acceleration_bounds(lower, upper, q, limits, np.array([0.3]), a_max, period)
    v, a, d = up[0], 5.0, 0.01
    assert v == pytest.approx(-a * period / 2 + np.sqrt((a * period / 2) ** 2 + 2 * a * d))  # 0.304 < 0.3 + a T
    assert lo[0] == pytest.approx(0.3 - 10.0 * period)
    # a previous speed above the stop speed: braking at a_max wins over the stop speed
    lo, up = acceleration_bounds(lower, upper, q, limits, np.array([0.5]), a_max, period)
    assert lo[0] == up[0] == pytest.approx(0.5 - 10.0 * period)


def test_position_limits_win_over_the_acceleration_bound() -> None:
    """At a limit with a large previous speed toward it, eq (23) (stop) wins: lower' = upper' = eq (23)'s upper."""
    limits = JointLimits(np.array([-1.0]), np.array([1.0]), np.array([2.0]))
    q = np.array([1.0])
    lower, upper = velocity_bounds(q, limits, 0.005)
    lo, up = acceleration_bounds(lower, upper, q, limits, np.array([1.5]), np.array([1.0]), 0.005)
    assert lo[0] == up[0] == pytest.approx(0.0)


@dataclass(frozen=True)
class HalfSpeed(Limit):
    """A box limit of a test's own: every joint at most half its velocity limit (a user's new limit),
    listed with the package's priority of a user limit (after eq (23)'s)."""

    qd_max: np.ndarray
    name: str = "half_speed"

    def constraints(self, configuration: Any, previous: np.ndarray) -> Constraint:
        return Constraint(-0.5 * self.qd_max, 0.5 * self.qd_max)


@dataclass(frozen=True)
class Joints:
    """The one attribute of a Configuration the joint limits read: q [rad] (n,)."""

    q: np.ndarray


@settings(max_examples=100, deadline=None, derandomize=True)
@given(cases())
def test_limits_intersect_whatever_their_order(case: Case) -> None:
    """Issue 39: the box of every limit holds whichever comes first; VelocityLimit used to overwrite the box,
    losing a limit applied before it. Brute force: the intersection computed elementwise here."""
    mine = HalfSpeed(case.limits.qd_max)
    eq23 = VelocityLimit(case.limits, case.period)
    zero = np.zeros_like(case.q)
    lower, upper = velocity_bounds(case.q, case.limits, case.period)
    want = (np.maximum(lower, -0.5 * case.limits.qd_max), np.minimum(upper, 0.5 * case.limits.qd_max))
    for order in ((mine, eq23), (eq23, mine)):
        got = apply_limits(order, Joints(case.q), zero)  # type: ignore[arg-type]
        np.testing.assert_array_equal(got.lower, want[0])
        np.testing.assert_array_equal(got.upper, want[1])
