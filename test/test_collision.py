"""Collision distances and the velocity damper (issue 27, part 1; the package dualarm_control/collision/).

* The rows dd_dq against finite differences of coal's distances, near contact, on the LWR4 cell
  and on Baxter (separated pairs, and penetrating ones with EPA's coarser accuracy).
* The distances against pybullet's ``getClosestPoints`` on the same URDF (LWR4 cell).
* The pair selection (joint distances, allowed pairs, left-right pairs, the broadphase), the
  witness points' geometry, determinism, the damper's rows by hand, and a kinematic loop where the
  rows keep two arms driven into each other at the safety distance.
"""

from __future__ import annotations

import functools
import itertools
import math

import coal
import numpy as np
import pinocchio as pin
import pybullet as p
import pytest

from dualarm_control.collision import (
    WORLD,
    CollisionModel,
    CollisionParams,
    NearPairs,
    PairDistance,
    velocity_damper_rows,
)
from dualarm_control.collision.shapes import bounding_sphere
from dualarm_control.errors import ParameterError
from dualarm_control.kinematics import DualArmModel
from dualarm_control.qp import QPProblem, make_backend
from dualarm_control.robot_files import RobotError
from dualarm_sim.cell import DualArmCell
from dualarm_sim.cell_config import CellConfig

# no ROS node, no wall-clock verdict: make test runs it at idle CPU priority beside the parallel tests (docs/testing.md)
pytestmark = pytest.mark.background

ROBOTS = ("lwr4_cell", "baxter")
NEAR = 0.15
"""A pair is near contact below this distance [m]."""
H = 1e-4
"""Finite-difference step [rad] for separated pairs (see test_rows_are_the_derivative_of_the_distance)."""
STEPS = H * np.array([0.5, 0.7, 1.0, 1.4, 2.0])
SWITCH_SPEED = 50.0
"""Witness points moving faster than this [m/rad] between q - s v and q + s v have jumped."""


@functools.cache
def kinematics(name: str) -> DualArmModel:
    return DualArmModel(name)


@functools.cache
def collision_model(name: str) -> CollisionModel:
    return CollisionModel(kinematics(name))


def by_pair(distances: list[PairDistance]) -> dict[tuple[str, str], PairDistance]:
    return {(d.link_a, d.link_b): d for d in distances}


def near_contact(c: CollisionModel, count: int, seed: int) -> list[np.ndarray]:
    """``count`` random configurations inside the limits where a left link and a right link are
    near contact (1 mm < d < NEAR): uniform samples, kept when they qualify."""
    m = c.kinematics
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(100 * count):
        q = rng.uniform(m.q_min, m.q_max)
        if any(c.link_side(d.link_a) == "left" and c.link_side(d.link_b) == "right" and d.distance > 1e-3
               for d in c.distances(q, NEAR)):
            out.append(q)
            if len(out) == count:
                return out
    raise AssertionError(f"only {len(out)} near-contact configurations in {100 * count} samples")


def finite_differences(c: CollisionModel, q: np.ndarray, v: np.ndarray, steps: np.ndarray,
                       pairs: list[PairDistance]) -> tuple[list[float], list[PairDistance]]:
    """For each pair: the median of the central differences (d(q + s v) - d(q - s v)) / (2 s) over
    ``steps``, or NaN when the closest shapes change or a witness point jumps (the closest features
    are not unique there: d has a kink and no derivative); and the pairs skipped so."""
    plus = [by_pair(c.distances(q + s * v)) for s in steps]
    minus = [by_pair(c.distances(q - s * v)) for s in steps]
    out, skipped = [], []
    for d in pairs:
        key, shapes = (d.link_a, d.link_b), (d.geometry_a, d.geometry_b)
        ends = [(a[key], b[key], s) for a, b, s in zip(plus, minus, steps, strict=True)]
        switch = any((x.geometry_a, x.geometry_b) != shapes for a, b, _ in ends for x in (a, b)) or any(
            max(np.linalg.norm(a.point_a - b.point_a), np.linalg.norm(a.point_b - b.point_b)) > SWITCH_SPEED * 2 * s
            for a, b, s in ends)
        if switch:
            skipped.append(d)
            out.append(math.nan)
        else:
            out.append(float(np.median([(a.distance - b.distance) / (2 * s) for a, b, s in ends])))
    return out, skipped


FD_STEP = 1e-4
"""Central-difference step [rad] of the property test (test_polished_rows_are_the_derivative_of_coals_distance)."""
KINK = 1e-6
"""A pair is not smooth over the stencil when its one-sided slopes at h and 2h disagree by more than this [m/rad]."""


def smooth_central_difference(d: list[float], h: float) -> tuple[float, bool]:
    """The central difference (d(+h) - d(-h)) / (2h) from d = [d(-2h), d(-h), d(0), d(h), d(2h)],
    and whether d is smooth over the stencil: for a smooth d the one-sided slopes' difference grows
    linearly with the step, s+(2h) - s-(2h) = 2 (s+(h) - s-(h)) + O(h^2), while a kink (a change of
    closest features) inside the stencil breaks that by about the slopes' jump."""
    s_plus, s_minus = (d[3] - d[2]) / h, (d[2] - d[1]) / h
    s2_plus, s2_minus = (d[4] - d[2]) / (2 * h), (d[2] - d[0]) / (2 * h)
    return (d[3] - d[1]) / (2 * h), abs((s2_plus - s2_minus) - 2 * (s_plus - s_minus)) <= KINK


def test_kink_detector() -> None:
    """smooth_central_difference keeps a smooth cubic and flags |x| with its kink inside the stencil."""
    h = FD_STEP
    grid = [k * h for k in (-2, -1, 0, 1, 2)]
    value, smooth = smooth_central_difference([0.3 + 2 * x - 5 * x * x + 7 * x ** 3 for x in grid], h)
    assert smooth and value == pytest.approx(2.0, abs=1e-6)
    assert not smooth_central_difference([abs(x + 0.5 * h) for x in grid], h)[1]


@pytest.mark.parametrize("name", ROBOTS)
def test_polished_rows_are_the_derivative_of_coals_distance(name: str) -> None:
    """The issue's property: for random configurations near contact, d_dot = dd_dq @ v equals the
    finite difference of coal's distance to 1e-6 m/rad.

    Sampling: q uniform inside the limits (seed 3) until 60 configurations have a pair with 0 < d
    < 0.10 m (the influence distance; the robot's allowed pairs left out); every such pair, one
    random unit joint direction v per configuration, rows from ``distances(q, within=0.10,
    polish=True)``.
    Step: central differences at h = 1e-4 rad: truncation h^2/6 d''' below 1e-8 m/rad; coal's d
    is within 1e-12 / d of the true distance (its duality gap) and that error is smooth in q in
    practice. Measured (docs/collision.md): the differences agree from h = 1e-3 to 1e-5 rad to
    1e-8 m/rad (the rows' errors, not the differences', dominate); at 1e-6 the noise shows.
    Excluded, without looking at the row: pairs whose closest shapes change within +-2h, whose
    distance reaches 0 there (EPA's 1e-6 m accuracy), or which are not smooth over the stencil
    (smooth_central_difference): at most 2 %.
    Asserted: 99.5 % within 1e-6 m/rad and all within 2e-6 (measured: LWR4 max 1.7e-7, Baxter one
    pair at 1.4e-6, the rest within 1e-6). The check can fail: the same comparison on the rows with the sign flipped, or with the
    angular part (p x n)^T J_w dropped, fails for more than 90 % of the pairs.
    """
    m = kinematics(name)
    c = CollisionModel(m, allowed=m.description.collision_allowed)
    rng = np.random.default_rng(3)
    h, within = FD_STEP, 0.10
    shape_index = {g.name: i for i, g in enumerate(c.geometry.geometryObjects)}
    errors, excluded, flipped, linear = [], 0, [], []
    configurations = 0
    while configurations < 60:
        q = rng.uniform(m.q_min, m.q_max)
        pairs = [d for d in c.distances(q, within, polish=True) if d.distance > 0.0]
        if not pairs:
            continue
        configurations += 1
        jac = c.data.J.copy()
        v = rng.normal(size=q.size)
        v /= np.linalg.norm(v)
        stencil = [by_pair(c.distances(q + k * h * v, within + 0.01)) for k in (-2, -1, 0, 1, 2)]
        for d in pairs:
            key, shapes = (d.link_a, d.link_b), (d.geometry_a, d.geometry_b)
            ends = [s.get(key) for s in stencil]
            values = [x.distance for x in ends if x is not None and (x.geometry_a, x.geometry_b) == shapes]
            if len(values) < 5 or min(values) <= 0.0:
                excluded += 1
                continue
            fd, smooth = smooth_central_difference(values, h)
            if not smooth:
                excluded += 1
                continue
            errors.append(abs(fd - d.dd_dq @ v))
            flipped.append(abs(fd + d.dd_dq @ v))
            row_linear = np.zeros(q.size)  # n^T J_v with the world-origin velocity only: no angular part
            for shape, sign in ((d.geometry_a, -1.0), (d.geometry_b, 1.0)):
                joint = c._shape_joint[shape_index[shape]]
                row_linear += sign * (d.normal @ jac[:3]) * c._support[joint]
            linear.append(abs(fd - row_linear @ v))
    e = np.array(errors)
    fraction = excluded / (len(e) + excluded)
    wrong_sign, no_angular = np.mean(np.array(flipped) > 1e-6), np.mean(np.array(linear) > 1e-6)
    summary = (f"{name}: {configurations} configurations, {len(e)} pairs kept, {excluded} excluded ({fraction:.1%}); "
               f"|fd - row| median {np.median(e):.1e}, max {e.max():.1e} m/rad; wrong rows fail: sign flipped "
               f"{wrong_sign:.0%}, angular part dropped {no_angular:.0%}")
    print(summary)
    assert len(e) >= 80 and fraction <= 0.02, summary
    # Baxter keeps one pair at 1.4e-6 (seed 3): a hull's facet or edge against a rim, a feature
    # polish_witness does not refine (GJK's points kept); all others within 1e-6
    assert np.mean(e <= 1e-6) >= 0.995 and e.max() <= 2e-6, summary
    assert wrong_sign > 0.9 and no_angular > 0.9, summary


@pytest.mark.parametrize("name", ["lwr4_cell", "lwr4_pan_cell", "baxter", "panda_pair", "ur5_pair"])
def test_ready_configuration_is_clear_of_every_checked_pair(name: str) -> None:
    """With the robot's collision_allowed pairs, no checked pair is closer than the safety distance
    (0.03 m) at its ready configuration, inter-arm pairs included (config/robots/*.yaml)."""
    try:
        m = DualArmModel(name)
    except RobotError as error:
        if "example-robot-data" in str(error):
            pytest.skip(str(error))
        raise
    c = CollisionModel(m, allowed=m.description.collision_allowed)
    near = c.distances(np.asarray(m.description.ready_positions), CollisionParams().safety_distance)
    assert not near, [(d.link_a, d.link_b, round(d.distance, 4)) for d in near]


@pytest.mark.parametrize("name", ROBOTS)
def test_rows_of_penetrating_pairs(name: str) -> None:
    """The same for penetrating pairs (-2 cm < d < -1 mm): EPA's depth is accurate to its 1e-6 m
    tolerance, so the steps are 10 times larger (0.5 to 2 x 1e-3 rad: noise about 1e-3 m/rad) and
    the bound 1e-2 m/rad (observed worst 1.9e-3; the rows are 0.01 to 0.3 m/rad: a sign error in
    the normal's convention would give twice that)."""
    c = collision_model(name)
    m = c.kinematics
    rng = np.random.default_rng(5)
    errors: list[float] = []
    while len(errors) < 40:
        q = rng.uniform(m.q_min, m.q_max)
        pairs = [d for d in c.distances(q, 0.0) if -0.02 < d.distance < -1e-3]
        if not pairs:
            continue
        v = rng.normal(size=q.size)
        v /= np.linalg.norm(v)
        fd, _ = finite_differences(c, q, v, STEPS * 10, pairs)
        errors += [abs(f - d.dd_dq @ v) for f, d in zip(fd, pairs, strict=True) if not math.isnan(f)]
    e = np.array(errors)
    summary = f"{name}: {len(e)} penetrating samples, |fd - row| median {np.median(e):.1e}, max {e.max():.1e} m/rad"
    print(summary)
    assert e.max() <= 1e-2, summary


def test_distances_match_pybullet() -> None:
    """coal's distances against pybullet's getClosestPoints on the LWR4 cell's URDF at the same
    configurations (50 random ones inside the limits, every separated pair).

    pybullet rounds every edge of its boxes and cylinders by its 1 mm collision margin (the shape
    shrunk by the margin, then grown by it). The exact comparison is therefore on a copy of the
    URDF loaded with URDF_USE_IMPLICIT_CYLINDER into the cell's client, its joints set like the
    cell's: where both witness points lie on a face or a cylinder's side at least 1 mm from every
    edge, the two shapes are the same and the distances agree to 1e-4 m (observed 5e-7); elsewhere
    pybullet's distance is larger by at most the rounding's reach, m (sqrt 3 - 1) for a box corner
    and m (sqrt 2 - 1) for a cylinder rim, per shape. The cell itself (the simulator) loads
    cylinders as convex hulls, grown by the margin: its distances are within 2.5 mm of coal's
    (observed -2.0 to +1.3 mm), a difference the damper's 3 cm safety distance covers.
    """
    m = kinematics("lwr4_cell")
    c = collision_model("lwr4_cell")
    margin = 1e-3
    rng = np.random.default_rng(0)
    configurations = [rng.uniform(m.q_min, m.q_max) for _ in range(50)]
    exact, bounded, simulator = [], [], []
    with DualArmCell(CellConfig.for_robot(m.description), initial_positions=configurations[0]) as cell:
        cid, cell_body = cell.client_id, cell.body_id
        body = p.loadURDF(str(m.urdf), useFixedBase=True, flags=p.URDF_USE_IMPLICIT_CYLINDER, physicsClientId=cid)
        infos = [p.getJointInfo(body, j, physicsClientId=cid) for j in range(p.getNumJoints(body, physicsClientId=cid))]
        link = {info[12].decode(): j for j, info in enumerate(infos)}
        joint = {info[1].decode(): j for j, info in enumerate(infos)}
        assert [p.getJointInfo(cell_body, j, physicsClientId=cid)[12].decode() for j in range(len(infos))] == list(link)

        def closest(body_id: int, d: PairDistance) -> float:
            points = p.getClosestPoints(body_id, body_id, 10.0, link[d.link_a], link[d.link_b], physicsClientId=cid)
            return float(min(x[8] for x in points))

        for q in configurations:
            cell.reset(q)
            for name, value in zip(m.joint_names, q, strict=True):
                p.resetJointState(body, joint[name], value, physicsClientId=cid)
            for d in c.distances(q):
                if d.distance <= 1e-3:
                    continue
                d_pb = closest(body, d)
                (smooth_a, reach_a), (smooth_b, reach_b) = (
                    _rounding(c, shape, point, margin) for shape, point in
                    ((d.geometry_a, d.point_a), (d.geometry_b, d.point_b)))
                if smooth_a and smooth_b:
                    exact.append(abs(d_pb - d.distance))
                bounded.append((d_pb - d.distance, reach_a + reach_b))
                simulator.append(closest(cell_body, d) - d.distance)
    e = np.array(exact)
    gap = np.array([g for g, _ in bounded])
    reach = np.array([r for _, r in bounded])
    sim = np.array(simulator)
    summary = (f"{len(bounded)} separated pairs, {len(e)} on faces/sides: |d_pb - d| max {e.max():.1e} m; "
               f"rounded edges: d_pb - d in [{gap.min():.1e}, {gap.max():.1e}] m; simulator's cell: "
               f"[{sim.min():.1e}, {sim.max():.1e}] m")
    print(summary)
    assert len(e) >= 20 and e.max() <= 1e-4, summary
    assert np.all(gap >= -1e-6) and np.all(gap <= reach + 1e-6), summary
    assert np.all(np.abs(sim) <= 2.5e-3), summary


def _rounding(c: CollisionModel, shape: str, point: np.ndarray, margin: float) -> tuple[bool, float]:
    """Whether ``point`` (on the shape, world) lies on a face or a cylinder's side at least
    ``margin`` from every edge, and how far pybullet's rounding of the shape's edges reaches."""
    index = [g.name for g in c.geometry.geometryObjects].index(shape)
    geometry = c.geometry.geometryObjects[index].geometry
    x = c.shape_placement(index).actInv(point)  # placements of the last distances() call
    if isinstance(geometry, coal.Box):
        half = np.asarray(geometry.halfSide)
        on = np.abs(np.abs(x) - half) < 1e-7
        smooth = on.sum() == 1 and bool(np.all(on | (np.abs(x) < half - margin)))
        return smooth, margin * (math.sqrt(3) - 1)
    assert isinstance(geometry, coal.Cylinder), type(geometry)
    radial, r, h = math.hypot(x[0], x[1]), geometry.radius, geometry.halfLength
    side, face = abs(radial - r) < 1e-7, abs(abs(x[2]) - h) < 1e-7
    smooth = (side and abs(x[2]) < h - margin) or (face and radial < r - margin)
    return smooth, margin * (math.sqrt(2) - 1)


# ---- the pairs ----------------------------------------------------------------------------------

COUNTS = {  # pairs: (world-arm, same arm, left-right), pruned, shape pairs
    "lwr4_cell": ((58, 52, 116), 3, 226),  # with the peg and hole's 6 bodies (before: (40, 28, 63), 3, 131)
    "baxter": ((230, 138, 320), 8, 816),  # (before: (188, 102, 225), 8, 631)
}


def kinds(c: CollisionModel) -> tuple[int, int, int]:
    sides = [(c.link_side(a), c.link_side(b)) for a, b in c.pairs]
    return (sum(a == WORLD for a, _ in sides), sum(a == b for a, b in sides),
            sum(a == "left" and b == "right" for a, b in sides))


@pytest.mark.parametrize("name", ROBOTS)
def test_pair_counts(name: str) -> None:
    c = collision_model(name)
    (world, same, left_right), pruned, shapes = COUNTS[name]
    got = (kinds(c), len(c.pruned), c.geometry_pairs)
    assert got == COUNTS[name], (
        f"{name}: {len(c.pairs)} link pairs (world-arm, same arm, left-right: {kinds(c)}), {len(c.pruned)} "
        f"pruned ({', '.join(f'{a}-{b} >= {bound:.3f} m' for a, b, bound in c.pruned)}), {c.geometry_pairs} "
        f"shape pairs; expected {world + same + left_right} ({world}, {same}, {left_right}), {pruned}, {shapes}")
    assert len(c.pairs) == sum(kinds(c)) == len(set(c.pairs))


@pytest.mark.parametrize("name", ROBOTS)
def test_no_pair_between_adjacent_links(name: str) -> None:
    """Every pair's links are at least 2 arm joints apart, 3 on the same arm; the world is never
    against itself; left comes before right and the world before an arm."""
    c = collision_model(name)
    order = {WORLD: 0, "left": 1, "right": 2}
    for a, b in c.pairs:
        sa, sb = c.link_side(a), c.link_side(b)
        assert order[sa] <= order[sb] and not sa == sb == WORLD, (a, b)
        assert c.joint_distance(a, b) >= (3 if sa == sb else 2), (a, b, c.joint_distance(a, b))
    if name == "lwr4_cell":
        pairs = set(c.pairs)
        for absent in [("left_link_0", "left_link_1"), ("torso", "left_link_1"), ("left_link_1", "left_link_2"),
                       ("left_link_1", "left_link_3"), ("left_link_7", "left_flange"), ("left_link_5", "left_flange")]:
            assert absent not in pairs and absent[::-1] not in pairs, absent
        for present in [("torso", "left_link_2"), ("left_link_1", "left_link_4"), ("left_link_4", "left_flange"),
                        ("right_link_0", "left_link_3"), ("left_flange", "right_flange")]:
            assert present in pairs, present


@pytest.mark.parametrize("name", ROBOTS)
def test_left_right_pairs_are_all_there_but_the_pruned(name: str) -> None:
    """Every left link with shapes against every right one, unless the broadphase proved the pair
    never comes within the margin; and the pruned pairs are indeed never near (400 random
    configurations: a pruned pair that came within the margin would show in ``distances(q,
    within=margin)`` of a model that keeps every pair)."""
    c = collision_model(name)
    left = [k for k in c.links if c.link_side(k) == "left"]
    right = [k for k in c.links if c.link_side(k) == "right"]
    pruned = {(a, b) for a, b, _ in c.pruned}
    def left_right(pairs: set[tuple[str, str]]) -> set[tuple[str, str]]:
        return {(a, b) for a, b in pairs if c.link_side(a) == "left" and c.link_side(b) == "right"}

    assert set(itertools.product(left, right)) == left_right(set(c.pairs)) | left_right(pruned)
    assert all(bound >= c.margin for _, _, bound in c.pruned)
    everything = CollisionModel(c.kinematics, margin=1e3)
    assert len(everything.pairs) == len(c.pairs) + len(c.pruned) and not everything.pruned
    rng = np.random.default_rng(1)
    m = c.kinematics
    for _ in range(400):
        q = rng.uniform(m.q_min, m.q_max)
        near = {(d.link_a, d.link_b): d.distance for d in everything.distances(q, c.margin)}
        assert not pruned & set(near), {k: near[k] for k in pruned & set(near)}


def test_allowed_pairs_and_self_collision() -> None:
    m = kinematics("lwr4_cell")
    full = collision_model("lwr4_cell")
    c = CollisionModel(m, allowed=[("right_flange", "left_flange"), ("left_tool", "right_tool")])
    assert ("left_flange", "right_flange") in full.pairs
    assert ("left_flange", "right_flange") not in c.pairs and ("right_flange", "left_flange") not in c.pairs
    # the end effectors: the left flange and the hole block's 5 bodies against the right flange and the peg
    assert len(c.pairs) == len(full.pairs) - 6 * 2
    with pytest.raises(ValueError, match="'left_peg' is not a link of"):
        CollisionModel(m, allowed=[("left_peg", "right_flange")])
    alone = CollisionModel(m, self_collision=False)
    assert not any(alone.link_side(a) == alone.link_side(b) for a, b in alone.pairs)
    assert len(alone.pairs) == len(full.pairs) - kinds(full)[1]


@pytest.mark.parametrize("name", ROBOTS)
def test_geometry_is_reduced_like_the_kinematic_model(name: str) -> None:
    """Same joints as DualArmModel (order, nq) and the same frames at a random configuration."""
    m, c = kinematics(name), collision_model(name)
    assert c.model.nq == m.model.nq == m.nq
    assert [c.model.names[i] for i in range(1, c.model.njoints)] == m.joint_names
    q = np.random.default_rng(2).uniform(m.q_min, m.q_max)
    c.distances(q, 0.0)
    for frame, pose in zip(("left_tool", "right_tool"), m.tool_poses(q), strict=True):
        placement = c.data.oMi[c.model.frames[c.model.getFrameId(frame)].parentJoint] * \
            c.model.frames[c.model.getFrameId(frame)].placement
        np.testing.assert_allclose(placement.homogeneous, pose.homogeneous, atol=1e-12)


# ---- the distances ------------------------------------------------------------------------------

@pytest.mark.parametrize("name", ROBOTS)
def test_witness_points_normals_and_rows(name: str) -> None:
    """p_b - p_a = d n with n a unit vector, separated or penetrating; a row has no column of a
    joint that moves neither link (the other arm's joints for a pair with the world)."""
    c = collision_model(name)
    m = c.kinematics
    rng = np.random.default_rng(4)
    signs = set()
    for _ in range(20):
        for d in c.distances(rng.uniform(m.q_min, m.q_max)):
            signs.add(d.distance > 0)
            np.testing.assert_allclose(np.linalg.norm(d.normal), 1.0, atol=1e-12)
            np.testing.assert_allclose(d.point_b - d.point_a, d.distance * d.normal, atol=1e-8)
            moved = {c.link_side(d.link_a), c.link_side(d.link_b)} - {WORLD}
            for side in {"left", "right"} - moved:
                assert not np.any(d.dd_dq[m.arm_columns(side)]), (d.link_a, d.link_b)
    assert signs == {True, False}


def test_distances_are_deterministic_and_within_is_a_subset() -> None:
    """The same q gives the same distances bit for bit whatever came before (no GJK warm start);
    ``within`` returns exactly the pairs closer than it, with the same values; ``closest`` is the
    smallest."""
    c = collision_model("lwr4_cell")
    m = c.kinematics
    rng = np.random.default_rng(6)
    qs = [rng.uniform(m.q_min, m.q_max) for _ in range(20)]
    first = [c.distances(q) for q in qs]
    for i in rng.permutation(len(qs)):
        again = c.distances(qs[i])
        assert [(d.distance, *d.point_a, *d.dd_dq) for d in again] == \
            [(d.distance, *d.point_a, *d.dd_dq) for d in first[i]]
        near = c.distances(qs[i], 0.1)
        assert [(d.link_a, d.link_b, d.distance) for d in near] == \
            [(d.link_a, d.link_b, d.distance) for d in first[i] if d.distance < 0.1]
        assert c.closest(qs[i]).distance == min(d.distance for d in first[i])
    assert len(first[0]) == len(c.pairs)


# ---- the damper ---------------------------------------------------------------------------------

def pair(distance: float, row: list[float]) -> PairDistance:
    zero = np.zeros(3)
    return PairDistance("a", "b", "a_0", "b_0", distance, zero, zero, np.array([1.0, 0.0, 0.0]), np.array(row))


def test_velocity_damper_rows_by_hand() -> None:
    """d_i = 0.1, d_s = 0.03, xi = 0.5: a pair at 0.05 m allows an approach of 0.5 * 0.02 / 0.07 =
    1/7 m/s; one at 0.01 m (inside d_s) must recede at 1/7 m/s; one at 0.2 m gets no row."""
    distances = [pair(0.05, [1.0, -2.0, 0.5]), pair(0.2, [3.0, 3.0, 3.0]), pair(0.01, [0.0, 1.0, 0.0])]
    a, b = velocity_damper_rows(distances, influence=0.1, safety=0.03, gain=0.5)
    np.testing.assert_array_equal(a, [[-1.0, 2.0, -0.5], [0.0, -1.0, 0.0]])
    np.testing.assert_allclose(b, [1 / 7, -1 / 7], rtol=1e-15)
    # a joint velocity on the boundary: d_dot = dd_dq qd = -xi (d - d_s) / (d_i - d_s)
    qd = np.array([-1 / 7, 0.0, 0.0])
    assert a[0] @ qd == pytest.approx(b[0]) and distances[0].dd_dq @ qd == pytest.approx(-1 / 7)
    a, b = velocity_damper_rows(distances[1:2], influence=0.1, safety=0.03, gain=0.5)
    assert a.shape == (0, 3) and b.shape == (0,)
    a, b = velocity_damper_rows([], influence=0.1, safety=0.03, gain=0.5)
    assert a.shape == (0, 0) and b.shape == (0,)


@pytest.mark.parametrize(("kwargs", "key"), [
    ({"influence_distance": 0.03, "safety_distance": 0.03}, "collision.influence_distance"),
    ({"safety_distance": -0.01}, "collision.safety_distance"),
    ({"gain": 0.0}, "collision.gain"),
    ({"gain": math.nan}, "collision.gain"),
    ({"influence_distance": True}, "collision.influence_distance"),
    ({"enabled": 1}, "collision.enabled"),
])
def test_collision_params_name_the_bad_value(kwargs: dict[str, object], key: str) -> None:
    with pytest.raises(ParameterError, match=f"parameter '{key}': got"):
        CollisionParams(**kwargs)  # type: ignore[arg-type]
    with pytest.raises(ParameterError):
        velocity_damper_rows([], influence=0.1, safety=0.2, gain=0.5)


def test_collision_params_defaults() -> None:
    params = CollisionParams()
    assert (params.enabled, params.influence_distance, params.safety_distance, params.gain) == (True, 0.1, 0.03, 0.5)
    assert params.gain * 0.005 / (params.influence_distance - params.safety_distance) < 0.05  # xi T / (d_i - d_s)


def test_damper_keeps_two_arms_driven_into_each_other_apart() -> None:
    """A kinematic loop on the LWR4 cell (T = 5 ms, 3 s): both arms are driven in joint space
    towards a configuration where they interpenetrate (qd_nom = 2 (q_goal - q), within the velocity
    limits). Unconstrained, the arms collide (d < 0). With the damper's rows, qd = argmin ||qd -
    qd_nom||^2 s.t. A qd <= b and the velocity limits (daqp), recomputed every period with d_i =
    0.1 m, d_s = 0.03 m, xi = 0.5 m/s: no pair closer than d_s - 1 mm (the first-order step's error),
    and the arms end near d_s (they were pushed towards each other all along)."""
    m = kinematics("lwr4_cell")
    c = collision_model("lwr4_cell")
    params = CollisionParams()
    start = m.description.ready
    rng = np.random.default_rng(8)
    goal = None
    for _ in range(2000):  # a goal the straight joint path reaches through a left-right collision
        q = rng.uniform(m.q_min, m.q_max) * 0.8
        if c.closest(start).distance > params.influence_distance and any(
                c.link_side(d.link_a) == "left" and c.link_side(d.link_b) == "right" and d.distance < -0.02
                for d in c.distances(q, 0.0)):
            goal = q
            break
    assert goal is not None
    backend = make_backend("daqp")
    period = 0.005

    def run(damped: bool) -> float:
        q, lowest = start.copy(), math.inf
        for _ in range(600):
            qd_nom = np.clip(2.0 * (goal - q), -m.qd_max, m.qd_max)
            distances = c.distances(q, params.influence_distance)
            lowest = min([lowest] + [d.distance for d in distances])
            qd = qd_nom
            if damped and distances:
                a, b = velocity_damper_rows(distances, params.influence_distance, params.safety_distance, params.gain)
                n = q.size
                solution = backend.solve(QPProblem(H=np.eye(n), g=-qd_nom, C=a, l=np.full(len(b), -1e20), u=b,
                                                   lb=-m.qd_max, ub=m.qd_max))
                assert solution.ok, solution.status
                assert solution.x is not None
                qd = solution.x
            q = q + period * qd
        return min(lowest, c.closest(q).distance)

    free, damped = run(False), run(True)
    print(f"closest distance without the damper {free:.4f} m, with it {damped:.4f} m")
    assert free < 0.0, f"without the damper the arms should collide: closest {free:.4f} m"
    assert params.safety_distance - 1e-3 <= damped <= params.safety_distance + 0.01, (
        f"with the damper the closest distance is {damped:.4f} m (d_s {params.safety_distance} m)")


@pytest.mark.parametrize("robot", ["lwr4_cell", "baxter"])
def test_what_is_known_from_earlier_calls_never_changes_the_result(robot: str) -> None:
    """``distances(q, within)`` skips pairs by what earlier calls learnt (temporal coherence); along a
    random walk with small steps and jumps, a model used all along gives bit for bit what a fresh model
    gives at each q, and a pair is skipped only when it is really farther than ``within``."""
    m = kinematics(robot)
    used = CollisionModel(m, allowed=m.description.collision_allowed)
    rng = np.random.default_rng(7)
    q = np.asarray(m.description.ready, dtype=float)
    skipped = 0
    for k in range(30):
        step = rng.normal(0.0, 0.02, m.nq) if k % 10 else rng.uniform(-0.8, 0.8, m.nq)  # every 10th: a jump
        q = np.clip(q + step, m.q_min, m.q_max)
        got = used.distances(q, within=0.10)
        fresh = CollisionModel(m, allowed=m.description.collision_allowed)
        want = fresh.distances(q, within=0.10)
        assert [(d.link_a, d.link_b, d.distance) for d in got] == [(d.link_a, d.link_b, d.distance) for d in want]
        assert all(np.array_equal(a.dd_dq, b.dd_dq) for a, b in zip(got, want, strict=True))
        every = by_pair(fresh.distances(q))
        returned = {(d.link_a, d.link_b) for d in got}
        assert all(d.distance >= 0.10 for pair, d in every.items() if pair not in returned)
        skipped += int((used._slack >= 0.10).sum())  # the known bounds at q after the call
    assert skipped > 0  # the bound does skip pairs


def test_a_non_finite_q_forgets_what_is_known_and_gives_no_pair() -> None:
    """NaN joint positions give no pair (the controller's input check rejects the cycle) and never
    poison the known bounds: the next finite q gives what a fresh model gives, bit for bit."""
    m = kinematics("lwr4_cell")
    used = CollisionModel(m, allowed=m.description.collision_allowed)
    q = np.asarray(m.description.ready, dtype=float)
    used.distances(q, within=0.10)
    bad = q.copy()
    bad[3] = np.nan
    assert used.distances(bad, within=0.10) == []
    near = q + 0.05
    want = CollisionModel(m, allowed=m.description.collision_allowed).distances(near, within=0.5)
    got = used.distances(near, within=0.5)
    assert want and [(d.link_a, d.link_b, d.distance) for d in got] == [(d.link_a, d.link_b, d.distance) for d in want]


@pytest.mark.parametrize("robot", ROBOTS)
def test_speed_bound_holds_for_every_pair_and_velocity(robot: str) -> None:
    """``NearPairs.speed`` C bounds how fast each pair's distance can change: |dd_dq qd| <= C |qd| for
    any qd (the reach of the pair's links about each joint), checked on 20 near-contact configurations
    with 50 random velocities each (uniform in the velocity limits, and single-joint velocities, where
    the bound is tightest). The deferred rows of the collision limit rely on it; the bound must also
    not be vacuous (it must vouch for slow motions: C |qd| < 0.5 m/s for qd = 2 % of the limits)."""
    c = collision_model(robot)
    m = c.kinematics
    rng = np.random.default_rng(11)
    worst, slow_bounds = 0.0, []
    for q in near_contact(c, 20, seed=5):
        near = c.near(q, within=NEAR)
        assert near.rows is not None and near.speed.shape == near.rows.shape
        assert np.all(near.speed >= 0.0)
        velocities = [rng.uniform(-m.qd_max, m.qd_max) for _ in range(40)]
        velocities += [m.qd_max * np.eye(m.nq)[rng.integers(m.nq)] * rng.choice([-1.0, 1.0]) for _ in range(10)]
        for qd in velocities:
            actual, bound = np.abs(near.rows @ qd), near.speed @ np.abs(qd)
            assert np.all(actual <= bound + 1e-12), (actual - bound).max()
            worst = max(worst, float((actual[bound > 0] / bound[bound > 0]).max(initial=0.0)))
        slow_bounds.append(float((near.speed @ (0.02 * m.qd_max)).max()))
    print(f"{robot}: largest |d_dot| / bound {worst:.3f}; bound at 2 % of the limits {max(slow_bounds):.3f} m/s")
    assert max(slow_bounds) < 0.5


@pytest.mark.parametrize("robot", ROBOTS)
def test_deferred_rows_are_the_rows_computed_at_once(robot: str) -> None:
    """``near(q, within, rows=False)`` keeps what the rows need; ``CollisionModel.rows`` builds from it the
    rows ``near(q, within)`` computes at once, bit for bit, even after other calls moved the model on."""
    c = collision_model(robot)
    for q in near_contact(c, 5, seed=6):
        now = c.near(q, within=NEAR)
        later = c.near(q, within=NEAR, rows=False)
        assert later.rows is None
        c.near(np.asarray(c.kinematics.description.ready, dtype=float))  # the model's data move on
        assert now.rows is not None
        assert np.array_equal(c.rows(later), now.rows)
        assert np.array_equal(later.speed, now.speed) and np.array_equal(later.distance, now.distance)
        with pytest.raises(ValueError, match="deferred"):
            later.pair_distances()
        assert later.points is None and later.normals is None  # the witness points deferred too
        assert now.points is not None and now.normals is not None
        points, normals = c.witness(later)
        assert np.array_equal(points, now.points) and np.array_equal(normals, now.normals)
        def fields(near: NearPairs) -> list[tuple[object, ...]]:
            return [(p.link_a, p.link_b, p.geometry_a, p.geometry_b, p.distance, p.point_a.tolist(),
                     p.point_b.tolist(), p.normal.tolist(), p.dd_dq.tolist()) for p in near.pair_distances()]

        assert fields(c.complete(later)) == fields(now)


@pytest.mark.parametrize("robot", ["lwr4_cell", "baxter"])
def test_sphere_bounds_are_the_spheres_gaps_and_below_coals_distances(robot: str) -> None:
    """The broadphase's bound of every shape pair (one matrix product on the joints' frames) equals
    ||c_a - c_b|| - r_a - r_b with each shape's bounding sphere placed by pinocchio's oMg (another path), and is
    below coal's distance of the pair, on random configurations."""
    c = collision_model(robot)
    m = c.kinematics
    objects = c.geometry.geometryObjects
    spheres = [bounding_sphere(obj.geometry) for obj in objects]
    pairs = [(cp.first, cp.second) for cp in c.geometry.collisionPairs]
    all_pairs = np.arange(len(pairs))
    rng = np.random.default_rng(3)
    request, below = coal.DistanceRequest(), 0
    for _ in range(30):
        q = rng.uniform(m.q_min, m.q_max)
        pin.computeJointJacobians(c.model, c.data, q)
        pin.updateGeometryPlacements(c.model, c.data, c.geometry, c.geometry_data)
        bounds = c._spheres.bounds(all_pairs)
        placed = c.geometry_data.oMg
        centres = [placed[k].act(spheres[k][0]) for k in range(len(objects))]
        gaps = np.array([np.linalg.norm(centres[a] - centres[b]) - spheres[a][1] - spheres[b][1] for a, b in pairs])
        np.testing.assert_allclose(bounds, gaps, rtol=0.0, atol=1e-12)
        for k, (a, b) in enumerate(pairs):
            d = coal.distance(objects[a].geometry, coal.Transform3s(placed[a]), objects[b].geometry,
                              coal.Transform3s(placed[b]), request, coal.DistanceResult())
            assert bounds[k] <= d + 1e-9, (c.geometry.geometryObjects[a].name, objects[b].name, bounds[k], d)
            below += 1
    assert below == 30 * len(pairs)
