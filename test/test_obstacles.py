"""Static obstacles from the configuration (issue 42, part 1; docs/obstacles.md).

* Parsing (dualarm_control/obstacles.py): every type, and bad input refused naming the key and value.
* The collision model (dualarm_control/collision/obstacles.py): every arm link against every
  obstacle, the first links too; the rows of (link, obstacle) pairs against finite differences of
  coal's distances, for each type (a plane as coal's half-space, a mesh as its convex hull).
* The simulator (dualarm_sim/obstacles.py): a static body per obstacle at the same pose, its
  distances to the links (pybullet's closest points) within pybullet's margins of coal's.
* A scenario's obstacles reach the controller's collision limit, the stall judge and the report
  (Scenario.collision_model, Scenario.controller_params).
"""

from __future__ import annotations

import functools
import math
from pathlib import Path

import numpy as np
import pybullet as p
import pytest

from dualarm_control.collision import CollisionModel
from dualarm_control.controller import ControllerParams, RelativeController
from dualarm_control.errors import ScenarioError
from dualarm_control.kinematics import DualArmModel
from dualarm_control.obstacles import (
    MAX_OBSTACLES,
    Box,
    Cylinder,
    Mesh,
    Obstacle,
    Plane,
    Sphere,
    parse_obstacles,
    table_top,
)
from dualarm_control.params import parse_params_text
from dualarm_control.scenario import load_scenario, scenario_from_parameters
from dualarm_sim.cell import DualArmCell
from dualarm_sim.cell_config import CellConfig

# no ROS node, no wall-clock verdict: make test runs it at idle CPU priority beside the parallel tests (docs/testing.md)
pytestmark = pytest.mark.background

OCTAHEDRON = """\
v 1 0 0
v -1 0 0
v 0 1 0
v 0 -1 0
v 0 0 1
v 0 0 -1
f 1 3 5
f 3 2 5
f 2 4 5
f 4 1 5
f 3 1 6
f 2 3 6
f 4 2 6
f 1 4 6
"""


def flat(text: str) -> dict[str, object]:
    """The flattened parameters of a scenario body (indented under ``scenario:``)."""
    head = "/**:\n  ros__parameters:\n    scenario:\n"
    return parse_params_text(head + "\n".join("      " + line for line in text.strip().splitlines()) + "\n",
                             "trajectory_node")


def mesh_file(tmp: Path) -> Path:
    path = tmp / "octahedron.obj"
    path.write_text(OCTAHEDRON)
    return path


def test_every_type_parses(tmp_path: Path) -> None:
    mesh_file(tmp_path)
    found = parse_obstacles(flat("""
obstacles: [table, fixture, ball, post, floor, wall, part]
table: {type: box, size: [1.2, 1.6, 0.05], position: [0.7, 0.0, 0.375]}
fixture: {type: box, size: [0.1, 0.2, 0.3], position: [0.6, 0, 0.9], rpy: [0, 0, 0.5]}
ball: {type: sphere, radius: 0.05, position: [0.5, 0.2, 1.1]}
post: {type: cylinder, radius: 0.03, length: 0.4, position: [0.5, -0.3, 0.9]}
floor: {type: plane, height: 0.0}
wall: {type: plane, normal: [-2, 0, 0], offset: -2.0}
part: {type: mesh, file: octahedron.obj, scale: 0.05, position: [0.6, 0.3, 1.2]}
"""), tmp_path)
    assert [type(o) for o in found] == [Box, Box, Sphere, Cylinder, Plane, Plane, Mesh]
    table, fixture, _, post, floor, wall, part = found
    assert table.top() == 0.4 and table_top(found) == 0.4
    assert fixture.rpy == (0.0, 0.0, 0.5) and fixture.top() == pytest.approx(1.05)
    assert post.top() == pytest.approx(1.1) and floor.top() == 0.0
    assert isinstance(wall, Plane) and wall.normal == (-1.0, 0.0, 0.0) and wall.offset == -1.0  # normalised
    assert isinstance(part, Mesh) and part.file == (tmp_path / "octahedron.obj").resolve()
    assert part.scale == (0.05, 0.05, 0.05) and part.label == "obstacle:part"
    assert parse_obstacles(flat("name: x"), tmp_path) == ()


@pytest.mark.parametrize(("body", "message"), [
    ("obstacles: [a]\na: {type: box, size: [0.1, .nan, 0.1]}", r"'scenario.a.size': got .*nan.*finite number"),
    ("obstacles: [a]\na: {type: box, size: [0.1, 0.0, 0.1]}", r"'scenario.a.size': got 0.0, expected a size > 0"),
    ("obstacles: [a]\na: {type: sphere, radius: -0.1}", r"'scenario.a.radius': got -0.1, expected a size > 0"),
    ("obstacles: [a]\na: {type: sphere, radius: .inf}", r"'scenario.a.radius': got inf"),
    ("obstacles: [a]\na: {type: sphere, radius: 0.1, position: [0, .inf, 0]}", r"'scenario.a.position': got inf"),
    ("obstacles: [a]\na: {type: sphere, radius: 0.1, rpy: [0, 0]}", r"'scenario.a.rpy': got \[0, 0\], expected a list"),
    ("obstacles: [a]\na: {type: cylinder, radius: 0.1}", r"'scenario.a.length' is missing"),
    ("obstacles: [a]\na: {type: cone, radius: 0.1}",
     r"'scenario.a.type': got 'cone', expected one of: box, sphere, cylinder, plane, mesh"),
    ("obstacles: [a]\na: {radius: 0.1}", r"'scenario.a.type': got None"),
    ("obstacles: [a]\na: {type: sphere, radius: 0.1, size: 2}", r"'scenario.a.size': unknown key of a sphere"),
    ("obstacles: [a]\na: {type: plane, normal: [0, 0, 0], offset: 1}", r"'scenario.a.normal'.*non-zero"),
    ("obstacles: [a]\na: {type: plane, normal: [0, 0, 1]}", r"'scenario.a.offset' is missing"),
    ("obstacles: [a]\na: {type: plane, height: 0.3, offset: 1}", r"'scenario.a.height': a plane has a height or"),
    ("obstacles: [a]\na: {type: plane, height: 0.3, position: [0, 0, 0]}", r"'scenario.a.position': unknown key"),
    ("obstacles: [a]\na: {type: mesh, file: nowhere.obj}", r"'scenario.a.file': got 'nowhere.obj', no such file"),
    ("obstacles: [a]\na: {type: mesh, file: part.dae}", r"'scenario.a.file': got 'part.dae', expected a .obj or .stl"),
    ("obstacles: [a, a]\na: {type: sphere, radius: 0.1}", r"obstacle 'a' is listed twice"),
    ("obstacles: [limits]", r"'limits' is not a valid obstacle name"),
    ("obstacles: [a-b]", r"'a-b' is not a valid obstacle name"),
    ("obstacles: 3", r"'scenario.obstacles': got 3, expected a list of obstacle names"),
    ("tasks: [a]\nobstacles: [a]\na: {type: sphere, radius: 0.1}", r"'a' is also a task's name"),
])
def test_bad_input_is_refused_naming_the_key_and_value(tmp_path: Path, body: str, message: str) -> None:
    with pytest.raises(ScenarioError, match=message):
        parse_obstacles(flat(body), tmp_path)


def test_more_than_the_maximum_is_refused(tmp_path: Path) -> None:
    names = [f"o{i}" for i in range(MAX_OBSTACLES + 1)]
    body = f"obstacles: [{', '.join(names)}]\n" + "\n".join(f"{n}: {{type: sphere, radius: 0.01}}" for n in names)
    with pytest.raises(ScenarioError, match=f"{MAX_OBSTACLES + 1} obstacles, more than the {MAX_OBSTACLES}"):
        parse_obstacles(flat(body), tmp_path)
    assert len(parse_obstacles(flat(body.replace(f", o{MAX_OBSTACLES}]", "]")), tmp_path)) == MAX_OBSTACLES


def test_a_table_needs_a_horizontal_top(tmp_path: Path) -> None:
    with pytest.raises(ScenarioError, match="a table needs a horizontal top"):
        table_top(parse_obstacles(flat("obstacles: [table]\ntable: {type: box, size: [1, 1, 0.1], rpy: [0.1, 0, 0]}"),
                                  tmp_path))


# ---- the collision model ---------------------------------------------------------------------

SCENE: tuple[Obstacle, ...] = (
    Plane("floor", normal=(0.0, 0.0, 1.0), offset=0.55),
    Box("fixture", position=(0.55, 0.0, 0.95), size=(0.12, 0.2, 0.35), rpy=(0.1, -0.2, 0.3)),
    Cylinder("post", position=(0.45, 0.35, 0.9), radius=0.04, length=0.5, rpy=(0.3, 0.2, 0.0)),
    Sphere("ball", position=(0.5, -0.35, 1.15), radius=0.06),
)


@functools.cache
def scene_model(mesh: Path | None = None) -> CollisionModel:
    m = DualArmModel("lwr4_cell")
    extra = (Mesh("part", file=mesh, scale=(0.08, 0.08, 0.08), position=(0.6, 0.0, 1.3), rpy=(0.2, 0.4, 0.1)),) \
        if mesh else ()
    return CollisionModel(m, allowed=m.description.collision_allowed, obstacles=SCENE + extra)


def test_every_arm_link_is_checked_against_every_obstacle() -> None:
    """Every link an arm joint moves (the first links too) against every obstacle, labelled (link,
    obstacle:<name>), after the robot's own pairs (unchanged), but the pruned ones."""
    c = scene_model()
    plain = CollisionModel(c.kinematics, allowed=c.kinematics.description.collision_allowed)
    assert c.pairs[:len(plain.pairs)] == plain.pairs
    arm = [link for link in plain.links if plain.link_side(link) != "world"]
    assert "left_link_1" in arm and "right_flange" in arm
    expected = {(link, o.label) for o in SCENE for link in arm}
    pruned = {(a, b) for a, b, _ in c.pruned if b.startswith("obstacle:")}
    assert set(c.pairs[len(plain.pairs):]) | pruned == expected
    assert not {(a, b) for a, b, _ in plain.pruned} ^ {(a, b) for a, b, _ in c.pruned if not b.startswith("obst")}
    assert not any(a == "torso" for a, b in c.pairs if b.startswith("obstacle:"))  # both world: never
    # a first link too, which the robot's own world shapes (joint distance 1) are not checked against
    near = CollisionModel(c.kinematics, obstacles=(Sphere("s", position=(0.15, 0.31, 1.25), radius=0.05),))
    assert ("left_link_1", "obstacle:s") in near.pairs and ("torso", "left_link_1") not in near.pairs
    assert all(bound >= c.margin for _, _, bound in c.pruned)


def test_a_pruned_obstacle_pair_never_comes_within_the_margin() -> None:
    c = scene_model()
    pruned = {(a, b) for a, b, _ in c.pruned if b.startswith("obstacle:")}
    assert pruned  # the ball and the post are far from some first links
    checker = CollisionModel(c.kinematics, allowed=c.kinematics.description.collision_allowed, obstacles=SCENE,
                             margin=10.0)
    rng = np.random.default_rng(0)
    m = c.kinematics
    for _ in range(200):
        q = rng.uniform(m.q_min, m.q_max)
        close = {(d.link_a, d.link_b) for d in checker.distances(q, c.margin)}
        assert not close & pruned


def near_obstacle(c: CollisionModel, rng: np.random.Generator, low: float, high: float) -> tuple[np.ndarray, list]:
    """A random configuration with (arm link, obstacle) pairs at low < d < high, and those pairs."""
    m = c.kinematics
    while True:
        q = rng.uniform(m.q_min, m.q_max)
        pairs = [d for d in c.distances(q, high) if d.link_b.startswith("obstacle:") and d.distance > low]
        if pairs:
            return q, pairs


def central_differences(c: CollisionModel, q: np.ndarray, v: np.ndarray, steps: np.ndarray,
                        pairs: list) -> list[float]:
    """The median over ``steps`` of (d(q + s v) - d(q - s v)) / 2s per pair; NaN when its closest
    shapes or witness points jump (no derivative there)."""
    plus = [{(d.link_a, d.link_b): d for d in c.distances(q + s * v)} for s in steps]
    minus = [{(d.link_a, d.link_b): d for d in c.distances(q - s * v)} for s in steps]
    out = []
    for d in pairs:
        key = (d.link_a, d.link_b)
        ends = [(a[key], b[key], s) for a, b, s in zip(plus, minus, steps, strict=True)]
        jump = any(max(np.linalg.norm(a.point_a - b.point_a), np.linalg.norm(a.point_b - b.point_b)) > 100 * s
                   or (a.geometry_a, a.geometry_b) != (d.geometry_a, d.geometry_b) for a, b, s in ends)
        out.append(math.nan if jump else float(np.median([(a.distance - b.distance) / (2 * s) for a, b, s in ends])))
    return out


def test_rows_of_obstacle_pairs_are_the_derivative_of_the_distance(tmp_path_factory: pytest.TempPathFactory) -> None:
    """As test_collision's rows test, for (arm link, obstacle) pairs of every type: near contact
    (1 mm < d < 0.15 m), a random unit joint direction v, d_dot = dd_dq v against the median of five
    central differences at h = 0.5 to 2 x 1e-4 rad. Bounds as the robot's pairs' (median <= 2e-7,
    99 % <= 5e-6, max <= 1e-4 m/rad; a wrong point, column or sign gives 1e-2 to 1e-1)."""
    c = scene_model(mesh_file(tmp_path_factory.mktemp("mesh")))
    rng = np.random.default_rng(7)
    steps = 1e-4 * np.array([0.5, 0.7, 1.0, 1.4, 2.0])
    errors: dict[str, list[float]] = {}
    while min((len(errors.get(o, [])) for o in ("floor", "fixture", "post", "ball", "part")), default=0) < 8:
        q, pairs = near_obstacle(c, rng, 1e-3, 0.15)
        v = rng.normal(size=q.size)
        v /= np.linalg.norm(v)
        for d, fd in zip(pairs, central_differences(c, q, v, steps, pairs), strict=True):
            if not math.isnan(fd):
                errors.setdefault(d.link_b.removeprefix("obstacle:"), []).append(abs(fd - float(d.dd_dq @ v)))
    e = np.concatenate([np.array(x) for x in errors.values()])
    summary = (f"{len(e)} samples ({', '.join(f'{k} {len(x)}' for k, x in errors.items())}): median "
               f"{np.median(e):.1e}, 99 % {np.percentile(e, 99):.1e}, max {e.max():.1e} m/rad")
    print(summary)
    assert np.median(e) <= 2e-7 and np.percentile(e, 99) <= 5e-6 and e.max() <= 1e-4, summary


def test_rows_of_links_inside_an_obstacle() -> None:
    """Penetrating (arm link, obstacle) pairs (-2 cm < d < -1 mm: EPA, or coal's half-space depth):
    steps 10 times larger, bound 1e-2 m/rad (a sign error gives twice the row, 0.01 to 0.3)."""
    c = scene_model()
    rng = np.random.default_rng(3)
    steps = 1e-3 * np.array([0.5, 0.7, 1.0, 1.4, 2.0])
    errors: list[float] = []
    while len(errors) < 30:
        q, pairs = near_obstacle(c, rng, -0.02, 0.0)
        pairs = [d for d in pairs if d.distance < -1e-3]
        v = rng.normal(size=q.size)
        v /= np.linalg.norm(v)
        fd = central_differences(c, q, v, steps, pairs)
        errors += [abs(f - float(d.dd_dq @ v)) for f, d in zip(fd, pairs, strict=True) if not math.isnan(f)]
    assert max(errors) <= 1e-2, max(errors)


def test_a_plane_is_the_same_as_a_large_box_below_it() -> None:
    """coal's half-space against the arm links gives the distances (and rows) of a 20 x 20 x 1 m box
    whose top is the plane, where the witness point is inside the box's top face (the rows to the box
    witness points' accuracy, GJK's: up to 1e-5 m/rad; the half-space's are exact)."""
    m = DualArmModel("lwr4_cell")
    plane = CollisionModel(m, obstacles=(Plane("t", offset=0.6),))
    box = CollisionModel(m, obstacles=(Box("t", size=(20.0, 20.0, 1.0), position=(0.0, 0.0, 0.1)),))
    rng = np.random.default_rng(1)
    compared = 0
    while compared < 40:
        q = rng.uniform(m.q_min, m.q_max)
        a = {(d.link_a, d.link_b): d for d in plane.distances(q, 0.15) if d.link_b == "obstacle:t"}
        b = {(d.link_a, d.link_b): d for d in box.distances(q, 0.15) if d.link_b == "obstacle:t"}
        assert set(a) == set(b)
        for key, d in a.items():
            if d.distance > 0:
                assert d.distance == pytest.approx(b[key].distance, abs=1e-9)
                np.testing.assert_allclose(d.dd_dq, b[key].dd_dq, atol=2e-5)  # GJK's points on the box
                compared += 1


def test_obstacles_in_the_simulator_match_coal(tmp_path: Path) -> None:
    """The cell's obstacle bodies at random configurations: pybullet's closest points from each arm
    link to each obstacle against coal's distance of the same pair, where within 0.1 m. pybullet's
    link shapes are convex hulls grown by its 1 mm margin, its boxes' and cylinders' edges rounded
    by it: -2.5 to +1.5 mm (the robot's own pairs: -2.0 to +1.3 mm, docs/collision.md)."""
    c = scene_model(mesh_file(tmp_path))
    with DualArmCell(CellConfig.for_robot("lwr4_cell", collisions=False, obstacles=c.obstacles)) as cell:
        assert set(cell.obstacle_bodies) == {o.name for o in c.obstacles}
        rng = np.random.default_rng(2)
        diffs: list[float] = []
        while len(diffs) < 60:
            q, pairs = near_obstacle(c, rng, 1e-3, 0.1)
            cell.pose(q)
            for d in pairs:
                body = cell.obstacle_bodies[d.link_b.removeprefix("obstacle:")]
                points = p.getClosestPoints(cell.body_id, body, 0.2, cell.link_index(d.link_a), -1,
                                            physicsClientId=cell.client_id)
                diffs.append(min(pt[8] for pt in points) - d.distance)
    print(f"pybullet - coal: {min(diffs) * 1e3:.2f} to {max(diffs) * 1e3:.2f} mm over {len(diffs)} pairs")
    assert -2.5e-3 <= min(diffs) and max(diffs) <= 1.5e-3


# ---- a scenario's obstacles everywhere its collision model is used ----------------------------------

SCENARIO = """\
/**:
  ros__parameters:
    scenario:
      name: with_a_post
      obstacles: [post]
      post: {type: cylinder, radius: 0.03, length: 0.4, position: [0.55, 0.0, 0.9]}
      goals:
        - {t: 0.0, xyz: [0.0, 0.0, 0.15], rpy: [3.14159265, 0.0, 0.0]}
"""


def test_a_scenarios_obstacles_reach_the_controller_judge_and_report(tmp_path: Path) -> None:
    path = tmp_path / "s.yaml"
    path.write_text(SCENARIO)
    scenario = load_scenario(str(path))
    assert [o.label for o in scenario.obstacles] == ["obstacle:post"]
    model = DualArmModel(scenario.robot)
    judged = scenario.collision_model(model)  # the stall judge's and the report's
    assert judged.obstacles == scenario.obstacles and ("right_link_6", "obstacle:post") in judged.pairs
    controller = RelativeController(model, scenario.controller_params(ControllerParams()))
    assert controller.collision_model is judged  # the same shared model
    limit = controller.limit("collision")
    assert limit is not None and "right_link_6 – obstacle:post" in limit._labels  # type: ignore[attr-defined]
    plain = scenario_from_parameters({k: v for k, v in parse_params_text(SCENARIO, "x").items()
                                      if not k.startswith(("scenario.obstacles", "scenario.post"))}, path)
    assert plain.obstacles == () and not any("obstacle:" in b for _, b in plain.collision_model(model).pairs)


def test_pan_cleaning_declares_its_table_once() -> None:
    """f6's plane is the top of the obstacle 'table'; the cell has it as an obstacle body, not twice."""
    scenario = load_scenario("pan_cleaning")
    tasks = scenario.tasks
    assert tasks is not None and [o.name for o in scenario.obstacles] == ["table"]
    assert tasks.table_height == 0.4 == table_top(scenario.obstacles) and tasks.table_obstacle
    assert tasks.cell_table is None
    collision = scenario.collision_model(DualArmModel(scenario.robot))
    assert ("left_link_3", "obstacle:table") in collision.pairs
