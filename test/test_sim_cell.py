"""Tests of the pybullet cell (dualarm_sim.cell): lockstep stepping, command handling, URDF agreement."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pybullet as p
import pytest

from dualarm_control.errors import DimensionError
from dualarm_control.kinematics import (
    LEFT_TOOL,
    RIGHT_TOOL,
    DualArmModel,
    rotation_angle,
)
from dualarm_control.robot_params import load_robot
from dualarm_sim.cell import DualArmCell
from dualarm_sim.cell_config import CellConfig
from dualarm_sim.samples import CommandReport, JointSample

ARM_Q0 = [0.3, 0.5, -0.2, -1.0, 0.4, 0.6, 0.1]
Q0 = np.array(ARM_Q0 + [-a for a in ARM_Q0])
N = 14


@pytest.fixture(scope="module")
def model() -> DualArmModel:
    return DualArmModel()


@pytest.fixture
def cell() -> Iterator[DualArmCell]:
    with DualArmCell(initial_positions=Q0) as c:
        yield c


def run(c: DualArmCell, qd: np.ndarray | None, periods: int) -> JointSample:
    """Step ``periods`` control periods, sending ``qd`` before each one (nothing if None)."""
    sample = c.state()
    for _ in range(periods):
        if qd is not None:
            c.apply_command(qd)
        sample = c.step()
    return sample


def test_joint_names_match_the_pinocchio_model(cell: DualArmCell, model: DualArmModel) -> None:
    assert cell.joint_names == model.joint_names
    assert len(cell.joint_names) == N
    lo, hi = cell.position_limits
    np.testing.assert_allclose(lo, model.q_min)
    np.testing.assert_allclose(hi, model.q_max)
    np.testing.assert_allclose(cell.velocity_limits, model.qd_max)


def test_state_after_reset_equals_the_reset_positions(cell: DualArmCell) -> None:
    run(cell, np.full(N, 0.4), 5)
    q = Q0 + 0.1
    cell.reset(q)
    s = cell.state()
    assert s.time == 0.0
    np.testing.assert_allclose(s.positions, q, atol=1e-12)
    np.testing.assert_allclose(s.velocities, 0.0, atol=1e-12)
    assert not cell.timed_out
    assert not s.positions.flags.writeable


def test_reset_validates_its_input(cell: DualArmCell) -> None:
    with pytest.raises(DimensionError, match="13"):
        cell.reset(np.zeros(13))
    too_far = Q0.copy()
    too_far[3] = 3.0
    with pytest.raises(ValueError, match="left_joint_4"):
        cell.reset(too_far)


def test_constant_velocity_command_gives_v_times_t(cell: DualArmCell) -> None:
    """Under gravity the motors track within 1e-3 rad/s after one 5 ms period; 0.1 s -> dq = v T +- 2e-3 rad."""
    v = 0.5 * np.where(np.arange(N) % 2 == 0, 1.0, -1.0)
    first = run(cell, v, 1)
    np.testing.assert_allclose(first.velocities, v, atol=1e-3)
    s = run(cell, v, 19)
    assert s.time == pytest.approx(0.1)
    np.testing.assert_allclose(s.velocities, v, atol=1e-3)
    np.testing.assert_allclose(s.positions - Q0, v * 0.1, atol=2e-3)


def test_states_come_from_the_physics_clipped_command(cell: DualArmCell) -> None:
    v = np.zeros(N)
    v[0], v[8] = 10.0, -10.0
    report = cell.apply_command(v)
    assert report == CommandReport(accepted=True, clipped=2, reason=report.reason)
    assert "left_joint_1" in report.reason and "right_joint_2" in report.reason
    s = cell.step()
    limits = cell.velocity_limits
    assert s.velocities[0] == pytest.approx(limits[0], abs=1e-3)
    assert s.velocities[8] == pytest.approx(-limits[8], abs=1e-3)
    assert cell.apply_command(np.full(N, 0.1)) == CommandReport(True, 0, "")


def test_nan_command_is_rejected_and_arms_come_to_rest(cell: DualArmCell) -> None:
    run(cell, np.full(N, 0.5), 4)
    bad = np.full(N, 0.5)
    bad[5] = np.nan
    report = cell.apply_command(bad)
    assert not report.accepted and report.clipped == 0
    assert "left_joint_6" in report.reason
    before = cell.state().positions.copy()
    s = run(cell, None, 4)
    assert np.all(np.isfinite(s.positions))
    np.testing.assert_allclose(s.velocities, 0.0, atol=1e-3)
    assert np.abs(s.positions - before).max() < 0.5 * 0.005  # at most one period's worth of motion


@pytest.mark.parametrize("shape", [(13,), (15,), (2, 7), ()])
def test_wrong_command_shape_raises_dimension_error(cell: DualArmCell, shape: tuple[int, ...]) -> None:
    with pytest.raises(DimensionError, match="14"):
        cell.apply_command(np.zeros(shape))


def test_command_timeout_brings_arms_to_rest(cell: DualArmCell) -> None:
    cfg = cell.config
    v = np.full(N, 0.5)
    cell.apply_command(v)
    s = run(cell, None, cfg.timeout_periods + 1)  # the command is in force for command_timeout
    np.testing.assert_allclose(s.velocities, v, atol=1e-3)
    assert cell.timed_out
    s = run(cell, None, 3)
    np.testing.assert_allclose(s.velocities, 0.0, atol=1e-3)
    cell.apply_command(v)
    assert not cell.timed_out
    np.testing.assert_allclose(cell.step().velocities, v, atol=1e-3)


def test_no_command_before_the_first_one_holds_still(cell: DualArmCell) -> None:
    s = run(cell, None, 20)
    assert not cell.timed_out
    np.testing.assert_allclose(s.positions, Q0, atol=1e-4)


def test_joint_limits_are_enforced_by_pybullet(cell: DualArmCell) -> None:
    """Documents behaviour: pybullet's URDF joint-limit constraints stop a joint at its limit,
    even in velocity mode; the controller must still keep away from the limits."""
    q = Q0.copy()
    q[6] = 2.9  # left_joint_7, upper limit 2.96706 rad
    cell.reset(q)
    v = np.zeros(N)
    v[6] = 2.0
    s = run(cell, v, 20)  # would reach 2.9 + 0.2 rad without the limit
    upper = cell.position_limits[1][6]
    assert upper - 1e-3 < s.positions[6] <= upper + 1e-3
    assert abs(s.velocities[6]) < 1e-2


def test_a_step_after_pose_starts_from_the_posed_joints() -> None:
    """A step's first substep reuses the positions state() last read (one read of the physics less) only while
    nothing moved the joints: after pose() it reads them again. Two cells, the same commands: one reads its state
    after pose() (its reuse is then of the posed joints), the other does not; their next steps agree bit for bit."""
    moved = Q0 + 0.05
    steps = []
    with DualArmCell(initial_positions=Q0) as a, DualArmCell(initial_positions=Q0) as b:
        for c, read in ((a, False), (b, True)):
            run(c, np.full(N, 0.1), 3)  # its last step ended with state(): the positions a next step would reuse
            c.pose(moved)
            if read:
                c.state()
            c.apply_command(np.full(N, 0.1))
            steps.append(np.concatenate([c.step().positions, c.step().positions]))
    np.testing.assert_array_equal(steps[0], steps[1])
    assert np.abs(steps[0][:N] - moved).max() < 0.05  # it moved on from the posed joints, not from before them


def test_two_cells_in_one_process_are_independent() -> None:
    with DualArmCell(initial_positions=Q0) as a, DualArmCell(initial_positions=Q0) as b:
        assert a.client_id != b.client_id
        run(a, np.full(N, 0.5), 10)
        sb = run(b, None, 10)
        np.testing.assert_allclose(sb.positions, Q0, atol=1e-4)
        a.close()
        np.testing.assert_allclose(b.step().positions, Q0, atol=1e-4)
        with pytest.raises(RuntimeError, match="closed"):
            a.step()
        a.close()  # idempotent


@pytest.mark.parametrize("rate", [999.0, 1500.0, 1100.0, float("nan")])
def test_physics_rate_validation(rate: float) -> None:
    with pytest.raises(ValueError, match=str(rate)):
        CellConfig(physics_rate_hz=rate)


def test_physics_rate_multiple_gives_substeps() -> None:
    assert CellConfig().substeps == 5
    cfg = CellConfig(physics_rate_hz=2000.0)
    assert cfg.substeps == 10 and cfg.physics_dt == pytest.approx(5e-4)
    with DualArmCell(cfg, initial_positions=Q0) as c:
        s = run(c, np.full(N, 0.5), 2)
        assert s.time == pytest.approx(0.01)
        np.testing.assert_allclose(s.velocities, 0.5, atol=1e-3)


def _check_poses(c: DualArmCell, model: DualArmModel, q: np.ndarray) -> None:
    o1, o2 = model.tool_poses(q)
    for pin_pose, link in ((o1, LEFT_TOOL), (o2, RIGHT_TOOL)):
        pos, rot = c.link_pose(link)
        np.testing.assert_allclose(pos, pin_pose.translation, atol=1e-6)
        assert rotation_angle(rot, pin_pose.rotation) < 1e-6
    (p1, r1), (p2, r2) = c.link_pose(LEFT_TOOL), c.link_pose(RIGHT_TOOL)
    p_rel, r_rel = model.relative_pose(q)
    np.testing.assert_allclose(r1.T @ (p2 - p1), p_rel, atol=1e-6)
    assert rotation_angle(r1.T @ r2, r_rel) < 1e-6


def test_relative_pose_agrees_with_pinocchio(cell: DualArmCell, model: DualArmModel) -> None:
    """Same URDF in both: pybullet link frames == pinocchio frames at the sim's joint positions."""
    rng = np.random.default_rng(7)
    lo, hi = cell.position_limits
    for _ in range(5):
        cell.reset(rng.uniform(0.9 * lo, 0.9 * hi))
        _check_poses(cell, model, cell.state().positions)
    s = run(cell, rng.uniform(-0.5, 0.5, N), 10)
    _check_poses(cell, model, s.positions)


@pytest.fixture
def bare_cell() -> Iterator[DualArmCell]:
    """The LWR4 cell's URDF as generated, without the tool set's bodies (the peg's 0.3 kg beyond the
    sensor would add its weight and, under the force below, its inertia)."""
    with DualArmCell(CellConfig(urdf=load_robot().urdf), initial_positions=Q0) as c:
        yield c


def test_wrench_at_rest_and_under_an_external_force(bare_cell: DualArmCell) -> None:
    """Sign/frame of the sensor: wrench of the flange on the tool, in the right_tool frame."""
    cell = bare_cell
    assert np.array_equal(cell.wrench(), np.zeros(6))  # nothing measured before the first step
    run(cell, np.zeros(N), 2)
    w = cell.wrench()
    assert w.shape == (6,)
    _, rot = cell.link_pose(RIGHT_TOOL)
    np.testing.assert_allclose(w[:3], rot.T @ [0.0, 0.0, 0.001 * 9.81], atol=2e-3)  # holds the 1 g tool up
    np.testing.assert_allclose(w[3:], 0.0, atol=1e-4)
    pos, rot = cell.link_pose(RIGHT_TOOL)
    force, lever = np.array([3.0, -2.0, 10.0]), np.array([0.1, 0.0, 0.0])  # world [N], tool frame [m]
    # Driving the client directly only to inject a force for one substep (applyExternalForce lasts one step).
    link = next(
        j
        for j in range(p.getNumJoints(cell.body_id, physicsClientId=cell.client_id))
        if p.getJointInfo(cell.body_id, j, physicsClientId=cell.client_id)[12].decode() == RIGHT_TOOL
    )
    where = pos + rot @ lever
    p.applyExternalForce(cell.body_id, link, force, where, p.WORLD_FRAME, physicsClientId=cell.client_id)
    p.stepSimulation(physicsClientId=cell.client_id)
    f_tool = rot.T @ force
    w = cell.wrench()
    np.testing.assert_allclose(w[:3], -f_tool + rot.T @ [0.0, 0.0, 0.001 * 9.81], atol=2e-3)
    np.testing.assert_allclose(w[3:], -np.cross(lever, f_tool), atol=2e-3)


def test_cell_module_is_ros_free() -> None:
    code = (
        "import sys, dualarm_sim.cell; bad = {'rclpy', 'cyclonedds', 'rosbags'} & set(sys.modules); assert not bad, bad"
    )
    subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, cwd=Path(__file__).parents[1])


PAN_URDF = Path(__file__).resolve().parents[1] / "urdf" / "dualarm_cell_pan.urdf"
PAN_START = np.radians([-17.3, 91.343, 59.706, -80.623, 9.786, -85.028, 41.618,
                        136.0, 94.216, -133.402, 93.405, 36.843, 59.326, 0.0])  # pan_cleaning.yaml


def test_table_collides_with_the_arms_only_when_they_reach_it() -> None:
    """A table at z = 0.4 m (pan_cleaning) is clear of the start pose; raised to 0.9 m it cuts the arms."""
    with DualArmCell(CellConfig(urdf=PAN_URDF, table_height=0.4), initial_positions=PAN_START) as c:
        run(c, np.zeros(14), 2)
        assert c.table_contacts() == 0
    with DualArmCell(CellConfig(urdf=PAN_URDF, table_height=0.9), initial_positions=PAN_START) as c:
        run(c, np.zeros(14), 2)
        assert c.table_contacts() > 0
    with pytest.raises(ValueError, match="table_height"):
        CellConfig(table_height=float("nan"))


def test_contact_pairs_enable_only_the_named_links() -> None:
    """Brush and pan touch only when their pair is enabled; an unknown link name is refused."""
    with DualArmCell(CellConfig(urdf=PAN_URDF, contact_pairs=(("left_flange", "right_tool"),)),
                     initial_positions=PAN_START) as c:
        assert c.contact_force("left_flange", "right_tool") == 0.0  # 5 cm apart at the start
    with pytest.raises(ValueError, match="unknown link 'nope'"):
        DualArmCell(CellConfig(urdf=PAN_URDF, contact_pairs=(("left_flange", "nope"),)))


def test_visual_shapes_change_no_physics() -> None:
    """The cell loads without the URDF's visual meshes by default (CellConfig.visual_shapes): the
    same motion and contacts bit for bit as with them, on a robot whose meshes pybullet would load
    (the Panda pair, self-collision on), the arms driven into each other."""
    from dualarm_control.robot_params import load_robot

    robot = load_robot("panda_pair")
    samples = []
    for visual in (False, True):
        config = CellConfig.for_robot(robot, visual_shapes=visual)
        with DualArmCell(config, initial_positions=robot.ready) as c:
            n = len(c.joint_names)
            qd = np.zeros(n)
            qd[0], qd[n // 2] = -1.0, 1.0  # both shoulders turned inwards: the wrists meet after ~90 periods
            trace, contacts = [], []
            for _ in range(200):
                c.apply_command(qd)
                s = c.step()
                trace.append(np.concatenate((s.positions, s.velocities)))
                contacts.append(c.contacts())
            samples.append((np.array(trace), contacts))
    (plain, contacts_plain), (visual, contacts_visual) = samples
    assert np.abs(plain[-1, :n] - plain[0, :n]).max() > 0.1  # it moved
    assert sum(bool(c) for c in contacts_plain) > 50, "the arms should have met"
    np.testing.assert_array_equal(plain, visual)
    assert contacts_plain == contacts_visual
