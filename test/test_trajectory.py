"""Tests of dualarm_control.trajectory: ruckig segments of relative pose and twist in F1."""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from dualarm_control import trajectory as trajmod
from dualarm_control.errors import DimensionError
from dualarm_control.trajectory import (
    MotionLimits,
    RelativeTrajectory,
    Segment,
    TargetSample,
    TrajectoryError,
)

SCREW_ANGLE = 2.0 * math.pi + 0.5
LIMITS = MotionLimits()
REL = 1e-9  # relative tolerance on kinematic limits


def rot_z(angle: float) -> np.ndarray:
    """Rotation about z [rad], written out (independent of the module under test)."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rot_x(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


P0 = np.array([0.01, -0.02, 0.15])
R0 = rot_x(math.pi) @ rot_z(0.3)  # peg pointing into the hole, arbitrary twist


def insertion_chain() -> RelativeTrajectory:
    """Approach (translation + tilt), pause, screw 2*pi + 0.5 about z with -2 cm, hold."""
    p1 = np.array([0.0, 0.0, 0.05])
    r1 = rot_x(math.pi) @ rot_z(0.1)
    approach = Segment.to_pose("approach", R0, p1, r1, hold=0.3)
    pause = Segment("pause", position=p1, axis=np.array([0.0, 0.0, 1.0]), angle=0.0, hold=0.5)
    screw = Segment.screw("screw", p1, np.array([0.0, 0.0, 1.0]), SCREW_ANGLE, -0.02, hold=0.4)
    back = Segment("retract", position=p1 + [0.0, 0.01, 0.0], axis=np.array([1.0, 0.0, 0.0]), angle=-0.2)
    return RelativeTrajectory(P0, R0, [approach, pause, screw, back], LIMITS)


@pytest.fixture(scope="module")
def chain() -> RelativeTrajectory:
    return insertion_chain()


@pytest.fixture(scope="module")
def dense(chain: RelativeTrajectory) -> list[TargetSample]:
    """Samples every 1 ms over the whole chain, plus the exact segment boundaries."""
    times = np.union1d(np.arange(0.0, chain.duration, 1e-3), chain.segment_start_times)
    return [chain.sample(float(t)) for t in times]


# --------------------------------------------------------------------------- limits


@pytest.mark.parametrize("field", [f for f in MotionLimits.__dataclass_fields__])
@pytest.mark.parametrize("bad", [0.0, -1.0, math.nan, math.inf, "fast", None, True])
def test_invalid_limits_raise_naming_field_and_value(field: str, bad: object) -> None:
    with pytest.raises(ValueError, match=field) as info:
        MotionLimits(**{field: bad})
    assert repr(bad) in str(info.value)


def test_limits_are_converted_to_float() -> None:
    lim = MotionLimits(max_linear_velocity=1, max_angular_jerk=np.float32(2.0))
    assert isinstance(lim.max_linear_velocity, float) and lim.max_linear_velocity == 1.0
    assert isinstance(lim.max_angular_jerk, float)


# --------------------------------------------------------------------------- segments


def test_segment_validation() -> None:
    z = np.array([0.0, 0.0, 1.0])
    with pytest.raises(DimensionError, match="position"):
        Segment("a", position=np.zeros(2), axis=z, angle=0.0)
    with pytest.raises(ValueError, match="axis"):
        Segment("a", position=np.zeros(3), axis=np.zeros(3), angle=0.1)
    with pytest.raises(ValueError, match="hold"):
        Segment("a", position=np.zeros(3), axis=z, angle=0.0, hold=-1.0)
    with pytest.raises(ValueError, match="angle"):
        Segment("a", position=np.zeros(3), axis=z, angle=math.nan)
    seg = Segment("a", position=[0, 0, 0], axis=[0.0, 2.0, 0.0], angle=1.0)
    np.testing.assert_array_equal(seg.axis, [0.0, 1.0, 0.0])  # normalized
    assert Segment("a", position=np.zeros(3), axis=np.zeros(3), angle=0.0).axis.tolist() == [0.0, 0.0, 1.0]
    with pytest.raises(ValueError):
        seg.position[0] = 1.0  # read-only


def test_to_pose_uses_shortest_rotation() -> None:
    r_b = rot_z(-2.5) @ R0
    seg = Segment.to_pose("a", R0, np.ones(3), r_b)
    assert seg.angle == pytest.approx(2.5)
    np.testing.assert_allclose(seg.axis, [0.0, 0.0, -1.0], atol=1e-12)
    np.testing.assert_allclose(pin.exp3(seg.axis * seg.angle) @ R0, r_b, atol=1e-12)
    same = Segment.to_pose("b", R0, np.ones(3), R0, hold=2.0)
    assert same.angle == 0.0 and same.axis.tolist() == [0.0, 0.0, 1.0] and same.hold == 2.0
    with pytest.raises(ValueError, match="rotation"):
        Segment.to_pose("c", R0, np.ones(3), 2.0 * R0)


def test_screw_constructor() -> None:
    seg = Segment.screw("s", [0.1, 0.2, 0.3], [0.0, 0.0, 3.0], SCREW_ANGLE, -0.02)
    np.testing.assert_allclose(seg.position, [0.1, 0.2, 0.28], atol=1e-15)
    np.testing.assert_array_equal(seg.axis, [0.0, 0.0, 1.0])
    assert seg.angle == SCREW_ANGLE
    with pytest.raises(ValueError, match="axis"):
        Segment.screw("s", np.zeros(3), np.zeros(3), 1.0, 0.0)


# --------------------------------------------------------------------------- trajectory


def test_construction_errors() -> None:
    with pytest.raises(ValueError, match="segment"):
        RelativeTrajectory(P0, R0, [])
    with pytest.raises(DimensionError):
        RelativeTrajectory(np.zeros(4), R0, [Segment("a", np.zeros(3), np.ones(3), 0.0)])
    with pytest.raises(ValueError, match="rotation"):
        RelativeTrajectory(P0, np.ones((3, 3)), [Segment("a", np.zeros(3), np.ones(3), 0.0)])


def test_ruckig_failure_raises_trajectory_error(monkeypatch: pytest.MonkeyPatch) -> None:
    real = trajmod.ruckig

    class FailingRuckig:
        def __init__(self, dofs: int) -> None:
            self.dofs = dofs

        def calculate(self, inp: object, traj: object) -> object:
            return real.Result.ErrorExecutionTimeCalculation

    monkeypatch.setattr(real, "Ruckig", FailingRuckig)
    with pytest.raises(TrajectoryError, match="segment 0 'move'.*ErrorExecutionTimeCalculation"):
        RelativeTrajectory(P0, R0, [Segment("move", P0 + 0.01, np.ones(3), 0.0)])


def test_start_and_end_poses_are_exact(chain: RelativeTrajectory) -> None:
    s0 = chain.sample(0.0)
    np.testing.assert_array_equal(s0.position, P0)
    np.testing.assert_array_equal(s0.rotation, R0)
    assert not s0.done and s0.segment == 0 and s0.segment_name == "approach"
    end = chain.sample(chain.duration)
    assert end.done and end.segment == 3 and end.segment_name == "retract"
    np.testing.assert_allclose(end.position, [0.0, 0.01, 0.05], atol=1e-15)
    expected_r = rot_x(-0.2) @ rot_z(SCREW_ANGLE) @ rot_x(math.pi) @ rot_z(0.1)
    np.testing.assert_allclose(end.rotation, expected_r, atol=1e-12)
    np.testing.assert_array_equal(end.rotation, chain.end_rotation)
    # just before the end, the retract motion has already converged onto the same pose
    near = chain.sample(chain.duration - 1e-9)
    np.testing.assert_allclose(near.position, end.position, atol=1e-12)
    np.testing.assert_allclose(near.rotation, end.rotation, atol=1e-12)


def test_before_start_and_after_end(chain: RelativeTrajectory) -> None:
    before = chain.sample(-1.0)
    np.testing.assert_array_equal(before.position, P0)
    assert not before.done and before.segment == 0
    assert np.all(before.twist == 0.0)
    for t in (chain.duration, chain.duration + 1e-6, chain.duration + 100.0):
        s = chain.sample(t)
        assert s.done and s.time == t
        assert np.all(s.twist == 0.0) and np.all(s.linear_acceleration == 0.0)
        np.testing.assert_array_equal(s.rotation, chain.end_rotation)
    with pytest.raises(ValueError):
        chain.sample(math.nan)


def test_durations_and_synchronization(chain: RelativeTrajectory) -> None:
    starts, motions = chain.segment_start_times, chain.segment_motion_durations
    holds = [s.hold for s in chain.segments]
    assert starts[0] == 0.0 and motions[1] == 0.0  # the pause has no motion
    for k in range(1, len(starts)):
        assert starts[k] == pytest.approx(starts[k - 1] + motions[k - 1] + holds[k - 1], abs=1e-12)
    assert chain.duration == pytest.approx(starts[-1] + motions[-1] + holds[-1], abs=1e-12)
    # the screw is limited by the angular velocity: at least angle / w_max
    assert motions[2] > SCREW_ANGLE / LIMITS.max_angular_velocity


def ruckig_4dof_duration(p_a: np.ndarray, seg: Segment, sync: object) -> float:
    """Duration of the 4-DoF formulation [p; s] of the brief, solved directly by ruckig."""
    inp = trajmod.ruckig.InputParameter(4)
    inp.current_position = [*p_a, 0.0]
    inp.target_position = [*seg.position, seg.angle]
    inp.max_velocity = [LIMITS.max_linear_velocity] * 3 + [LIMITS.max_angular_velocity]
    inp.max_acceleration = [LIMITS.max_linear_acceleration] * 3 + [LIMITS.max_angular_acceleration]
    inp.max_jerk = [LIMITS.max_linear_jerk] * 3 + [LIMITS.max_angular_jerk]
    inp.synchronization = sync
    traj = trajmod.ruckig.Trajectory(4)
    assert trajmod.ruckig.Ruckig(4).calculate(inp, traj) == trajmod.ruckig.Result.Working
    return traj.duration


def test_same_duration_as_ruckig_phase_synchronization(chain: RelativeTrajectory) -> None:
    phase = trajmod.ruckig.Synchronization.Phase
    for k in (0, 2, 3):
        p_a = chain.sample(chain.segment_start_times[k]).position
        expected = ruckig_4dof_duration(p_a, chain.segments[k], phase)
        assert chain.segment_motion_durations[k] == pytest.approx(expected, rel=1e-9)


def test_straight_line_when_ruckig_phase_falls_back_to_time() -> None:
    # ruckig's 4-DoF Synchronization.Phase silently degrades to Time on this segment
    # (the position then leaves the straight line); the path parameterization does not
    seg = Segment("mixed", P0 + [0.01432131, 0.05278333, -0.00453625], [0.3, -1.0, 0.2], 0.5110759)
    traj = RelativeTrajectory(P0, R0, [seg])
    d = seg.position - P0
    assert traj.duration >= ruckig_4dof_duration(P0, seg, trajmod.ruckig.Synchronization.Time) - 1e-12
    for t in np.linspace(0.0, traj.duration, 101):
        s = traj.sample(float(t))
        frac = float(np.dot(s.position - P0, d) / np.dot(d, d))
        np.testing.assert_allclose(s.position, P0 + frac * d, atol=1e-15)
        np.testing.assert_allclose(s.rotation, pin.exp3(seg.axis * seg.angle * frac) @ R0, atol=1e-12)


def test_twist_matches_finite_difference(chain: RelativeTrajectory) -> None:
    rng = np.random.default_rng(0)
    h = 1e-6
    times = np.concatenate((rng.uniform(0.0, chain.duration, 300), np.array(chain.segment_start_times[1:])))
    for t in times:
        s, a, b = chain.sample(t), chain.sample(t - h), chain.sample(t + h)
        np.testing.assert_allclose(s.linear_velocity, (b.position - a.position) / (2 * h), atol=1e-8)
        w_fd = pin.log3(b.rotation @ a.rotation.T) / (2 * h)
        np.testing.assert_allclose(s.angular_velocity, w_fd, atol=1e-8)
        # where the jerk switches on (e.g. a segment start) the central difference is off by
        # up to jerk * h / 4 (1.25e-6 for 5 rad/s^3)
        a_fd = (b.linear_velocity - a.linear_velocity) / (2 * h)
        np.testing.assert_allclose(s.linear_acceleration, a_fd, atol=2e-6)
        alpha_fd = (b.angular_velocity - a.angular_velocity) / (2 * h)
        np.testing.assert_allclose(s.angular_acceleration, alpha_fd, atol=2e-6)


def test_kinematic_limits_respected(dense: list[TargetSample]) -> None:
    v = np.array([s.linear_velocity for s in dense])
    a = np.array([s.linear_acceleration for s in dense])
    w = np.array([s.angular_velocity for s in dense])
    alpha = np.array([s.angular_acceleration for s in dense])
    assert np.max(np.abs(v)) <= LIMITS.max_linear_velocity * (1 + REL)
    assert np.max(np.abs(a)) <= LIMITS.max_linear_acceleration * (1 + REL)
    assert np.max(np.linalg.norm(w, axis=1)) <= LIMITS.max_angular_velocity * (1 + REL)
    assert np.max(np.linalg.norm(alpha, axis=1)) <= LIMITS.max_angular_acceleration * (1 + REL)
    # the screw reaches the angular velocity limit (the profile is not needlessly slow)
    assert np.max(np.linalg.norm(w, axis=1)) == pytest.approx(LIMITS.max_angular_velocity, rel=1e-9)
    # jerk from differences of the (continuous) acceleration: a mean value, so <= the max
    t = np.array([s.time for s in dense])
    dt = np.diff(t)[:, None]
    assert np.max(np.abs(np.diff(a, axis=0) / dt)) <= LIMITS.max_linear_jerk * (1 + 1e-6)
    assert np.max(np.linalg.norm(np.diff(alpha, axis=0) / dt, axis=1)) <= LIMITS.max_angular_jerk * (1 + 1e-6)


def test_continuity_at_segment_boundaries(chain: RelativeTrajectory) -> None:
    bounds = [*chain.segment_start_times[1:]]
    bounds += [t0 + m for t0, m in zip(chain.segment_start_times, chain.segment_motion_durations)]
    for tb in bounds:
        a, b = chain.sample(tb - 1e-9), chain.sample(tb)
        np.testing.assert_allclose(a.position, b.position, atol=1e-12)
        np.testing.assert_allclose(a.rotation, b.rotation, atol=1e-12)
        np.testing.assert_allclose(a.twist, b.twist, atol=1e-9)
        np.testing.assert_allclose(a.linear_acceleration, b.linear_acceleration, atol=1e-8)
        np.testing.assert_allclose(a.angular_acceleration, b.angular_acceleration, atol=1e-8)
    for k in range(len(chain.segments)):  # each segment starts at its predecessor's exact end
        p, r = chain.segment_end_pose(k)
        if k + 1 < len(chain.segments):
            s = chain.sample(chain.segment_start_times[k + 1])
            np.testing.assert_array_equal(s.position, p)
            np.testing.assert_array_equal(s.rotation, r)


def test_full_screw_turn(chain: RelativeTrajectory, dense: list[TargetSample]) -> None:
    k = 2
    p_a, r_a = chain.segment_end_pose(1)
    p_b, r_b = chain.segment_end_pose(k)
    np.testing.assert_allclose(r_b, rot_z(SCREW_ANGLE) @ r_a, atol=1e-12)
    np.testing.assert_allclose(p_b, p_a + [0.0, 0.0, -0.02], atol=1e-15)
    t0, t1 = chain.segment_start_times[k], chain.segment_start_times[k] + chain.segment_motion_durations[k]
    ts = np.linspace(t0, t1, 20001)
    samples = [chain.sample(float(t)) for t in ts]
    w = np.array([s.angular_velocity for s in samples])
    wz = w[:, 2]
    assert np.all(wz >= -1e-12)  # monotonic progress of the angle
    np.testing.assert_allclose(w[:, :2], 0.0, atol=1e-15)  # about the fixed axis only
    assert np.trapezoid(wz, ts) == pytest.approx(SCREW_ANGLE, abs=1e-4)
    # the position goes straight down the axis, in step with the angle (phase synchronization)
    for s in samples[::500]:
        frac_p = (s.position[2] - p_a[2]) / -0.02
        np.testing.assert_allclose(s.position[:2], p_a[:2], atol=1e-15)
        frac_r = pin.log3(s.rotation @ r_a.T)  # angle mod 2*pi: compare rotations instead
        np.testing.assert_allclose(pin.exp3(frac_r), rot_z(frac_p * SCREW_ANGLE), atol=1e-9)
    # beyond pi the sampled orientation keeps turning the same way (no shortest-path flip)
    mid = chain.sample(t0 + 0.75 * (t1 - t0))
    assert mid.angular_velocity[2] > 0.0


def test_hold_segments_hold(chain: RelativeTrajectory, dense: list[TargetSample]) -> None:
    for k, seg in enumerate(chain.segments):
        if seg.hold == 0.0:
            continue
        p, r = chain.segment_end_pose(k)
        # (start + motion duration) may round just below the end of the motion: skip 1 ns
        t_hold = chain.segment_start_times[k] + chain.segment_motion_durations[k] + 1e-9
        for t in np.linspace(t_hold, t_hold + seg.hold - 2e-9, 50):
            s = chain.sample(float(t))
            assert s.segment == k and s.segment_name == seg.name and not s.done
            np.testing.assert_array_equal(s.position, p)
            np.testing.assert_array_equal(s.rotation, r)
            assert np.all(s.twist == 0.0)


def test_zero_motion_segments() -> None:
    z = np.array([0.0, 0.0, 1.0])
    segs = [
        Segment("nothing", P0, z, 0.0),
        Segment("wait", P0, z, 0.0, hold=1.5),
        Segment("nothing again", P0, z, 0.0),
    ]
    traj = RelativeTrajectory(P0, R0, segs)
    assert traj.duration == 1.5 and traj.segment_motion_durations == [0.0, 0.0, 0.0]
    s = traj.sample(0.0)
    assert s.segment == 1 and s.segment_name == "wait"  # zero-length segments are skipped
    np.testing.assert_array_equal(s.position, P0)
    np.testing.assert_array_equal(s.rotation, R0)
    assert traj.sample(1.5).done and traj.sample(1.5).segment == 2


def test_sampling_is_deterministic(chain: RelativeTrajectory) -> None:
    other = insertion_chain()
    assert other.duration == chain.duration
    for t in np.linspace(-0.1, chain.duration + 0.1, 97):
        a, b = chain.sample(float(t)), other.sample(float(t))
        np.testing.assert_array_equal(a.position, b.position)
        np.testing.assert_array_equal(a.rotation, b.rotation)
        np.testing.assert_array_equal(a.twist, b.twist)
    a = chain.sample(3.0)
    a.position[0] = 99.0  # samples are copies: the trajectory is not affected
    assert chain.sample(3.0).position[0] != 99.0


# --------------------------------------------------------------------------- property test

coord = st.floats(-0.2, 0.2, allow_nan=False)
vec3 = st.tuples(coord, coord, coord).map(np.array)
unit = st.tuples(*[st.floats(-1.0, 1.0, allow_nan=False)] * 3).filter(lambda v: np.linalg.norm(v) > 0.1)
segment_spec = st.tuples(
    st.sampled_from(["pose", "screw", "raw"]),
    vec3,
    unit,
    st.floats(-7.0, 7.0, allow_nan=False),
    st.sampled_from([0.0, 0.0, 0.2]),
)


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(start=vec3, start_rotvec=unit, specs=st.lists(segment_spec, min_size=1, max_size=3))
def test_random_segments_property(start: np.ndarray, start_rotvec: tuple, specs: list) -> None:
    r_a = pin.exp3(np.array(start_rotvec) * 2.0)
    p_a = start
    segs = []
    ends = []
    for i, (kind, pos, axis, angle, hold) in enumerate(specs):
        axis = np.array(axis) / np.linalg.norm(axis)
        if kind == "pose":
            r_b = pin.exp3(axis * angle) @ r_a
            seg = Segment.to_pose(f"s{i}", r_a, pos, r_b, hold=hold)
        elif kind == "screw":
            seg = Segment.screw(f"s{i}", p_a, axis, angle, pos[0] * 0.2, hold=hold)
            r_b = pin.exp3(axis * angle) @ r_a
        else:
            seg = Segment(f"s{i}", pos, axis, angle, hold)
            r_b = pin.exp3(axis * angle) @ r_a
        segs.append(seg)
        ends.append((seg.position.copy(), r_b))
        p_a, r_a = seg.position, r_b
    traj = RelativeTrajectory(start, pin.exp3(np.array(start_rotvec) * 2.0), segs)
    for k, (p_b, r_b) in enumerate(ends):
        p, r = traj.segment_end_pose(k)
        np.testing.assert_array_equal(p, p_b)
        np.testing.assert_allclose(r, r_b, atol=1e-9)
    final = traj.sample(traj.duration)
    assert final.done and np.all(final.twist == 0.0)
    np.testing.assert_array_equal(final.position, ends[-1][0])
    h = 1e-6
    rng = np.random.default_rng(1)
    for t in rng.uniform(0.0, traj.duration, 40):
        s, a, b = traj.sample(t), traj.sample(t - h), traj.sample(t + h)
        assert np.max(np.abs(s.linear_velocity)) <= LIMITS.max_linear_velocity * (1 + REL)
        assert np.max(np.abs(s.linear_acceleration)) <= LIMITS.max_linear_acceleration * (1 + REL)
        assert np.linalg.norm(s.angular_velocity) <= LIMITS.max_angular_velocity * (1 + REL)
        assert np.linalg.norm(s.angular_acceleration) <= LIMITS.max_angular_acceleration * (1 + REL)
        np.testing.assert_allclose(s.linear_velocity, (b.position - a.position) / (2 * h), atol=1e-8)
        np.testing.assert_allclose(s.angular_velocity, pin.log3(b.rotation @ a.rotation.T) / (2 * h), atol=1e-8)
        np.testing.assert_allclose(s.rotation.T @ s.rotation, np.eye(3), atol=1e-12)
    for tb in traj.segment_start_times[1:]:
        a, b = traj.sample(tb - 1e-9), traj.sample(tb)
        np.testing.assert_allclose(a.position, b.position, atol=1e-12)
        np.testing.assert_allclose(a.rotation, b.rotation, atol=1e-12)
        np.testing.assert_allclose(a.twist, b.twist, atol=1e-9)
