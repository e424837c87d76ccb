"""Contacts and distances seen by the simulator, independently of the controller's collision code.

Two things, both on pybullet's collision shapes of the robot's resolved URDF as the cell loads them
(:class:`~dualarm_sim.cell.DualArmCell`: meshes and cylinders as convex hulls grown by pybullet's
1 mm collision margin), never on coal:

* :func:`min_distances`: the independent check of a run (issue 27): for recorded joint positions,
  the smallest distance between the given link pairs at every row (``p.getClosestPoints`` per pair)
  and over the run. Only WHICH pairs to check comes from the controller's side: the caller passes
  them, usually :func:`~dualarm_sim.cell_config.robot_collision_pairs` (the pairs of
  :class:`~dualarm_control.collision.CollisionModel`, the robot's ``collision_allowed`` left out).
* :func:`obstacle_min_distances`: the same for the links an arm joint moves against a scenario's
  obstacles (issue 42, docs/obstacles.md), on the obstacles' pybullet bodies.
* :class:`ContactCounter`: the contact-steps per link pair the simulator counted
  (:meth:`~dualarm_sim.cell.DualArmCell.contacts` after each step), the events when a pair comes
  into contact or separates (for a log line), and the values the sim node puts on ``/diagnostics``.

docs/collision.md ("The simulator's contacts", "Independent check with pybullet") has the
measured agreement with coal and the costs.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pybullet as p

from dualarm_control.arrays import FloatArray
from dualarm_control.errors import DimensionError
from dualarm_control.obstacles import Obstacle
from dualarm_control.robot import RobotDescription
from dualarm_control.robot_params import load_robot
from dualarm_sim.cell import DualArmCell
from dualarm_sim.cell_config import CellConfig

IntArray = npt.NDArray[np.intp]
Pair = tuple[str, str]
DEFAULT_CUTOFF = 0.2
"""Query distance of :func:`min_distances` [m]: a pair farther apart than this gives no closest
point from pybullet (its distance is then reported as ``inf``, "> cutoff")."""


@dataclass(frozen=True)
class MinDistances:
    """The smallest link-pair distance of every row of a run and of the whole run (pybullet).

    Attributes:
        pairs: the link pairs checked, in the caller's order.
        distances: per row, the smallest distance over the pairs [m], (k,): > 0 apart, <= 0 in
            contact (minus the penetration depth); ``inf`` when every pair is beyond ``cutoff``.
        closest: per row, the index in ``pairs`` of the pair with that distance, (k,); -1 with ``inf``.
        pair_minimum: per pair, its smallest distance over the rows [m], (len(pairs),); ``inf``
            beyond ``cutoff``.
        cutoff: the query distance [m].
    """

    pairs: tuple[Pair, ...]
    distances: FloatArray
    closest: IntArray
    pair_minimum: FloatArray
    cutoff: float

    @property
    def row(self) -> int:
        """The row with the run's smallest distance (the first such row; 0 when all are ``inf``)."""
        return int(np.argmin(self.distances)) if len(self.distances) else 0

    @property
    def minimum(self) -> float:
        """The run's smallest distance [m] (``inf`` when no pair came within ``cutoff``)."""
        return float(self.distances[self.row]) if len(self.distances) else math.inf

    @property
    def pair(self) -> Pair | None:
        """The pair with the run's smallest distance (None when no pair came within ``cutoff``)."""
        i = int(self.closest[self.row]) if len(self.closest) else -1
        return self.pairs[i] if i >= 0 else None

    def row_pair(self, row: int) -> Pair | None:
        """The closest pair of one row (None when every pair is beyond ``cutoff``)."""
        i = int(self.closest[row])
        return self.pairs[i] if i >= 0 else None


def min_distances(robot: RobotDescription | str, positions: FloatArray, pairs: Sequence[Pair],
                  cutoff: float = DEFAULT_CUTOFF) -> MinDistances:
    """The smallest distance between ``pairs`` at every row of ``positions``, from pybullet.

    The robot's cell is loaded as the simulator loads it (:class:`~dualarm_sim.cell.DualArmCell`
    in its own DIRECT client, the locked joints at their values; its self-collision filters do not
    matter: ``getClosestPoints`` ignores them). Each row sets the arms' joints
    (``resetJointState``, :meth:`~dualarm_sim.cell.DualArmCell.pose`: no limit check, so recorded
    overshoots of a few 1e-5 rad are kept), then ``p.getClosestPoints(body, body, cutoff, link_a,
    link_b)`` per pair gives the pair's smallest signed distance (the base link is -1); pairs whose
    axis-aligned bounding boxes (``p.getAABB``, which hold the shapes) are ``cutoff`` or more apart
    are skipped: their distance is at least that gap.

    Args:
        robot: the robot description or its name.
        positions: recorded joint positions [rad], (k, n), n the robot's arm joints (left then right).
        pairs: link pairs (resolved URDF link names), e.g. ``robot_collision_pairs(robot)``.
        cutoff: query distance [m], > 0: pairs farther apart count as ``inf``.

    Returns:
        :class:`MinDistances`. About 2 us (LWR4) to 16 us (Baxter) per pair and row (docs/collision.md).

    Raises:
        DimensionError: ``positions`` not (k, n). ValueError: a bad cutoff, a non-finite position,
        an empty pair list. KeyError: a link that is not in the URDF.
    """
    r = load_robot(robot)
    q = np.asarray(positions, dtype=float)
    if q.ndim != 2 or q.shape[1] != r.nq:
        raise DimensionError(f"min_distances: positions must be (k, {r.nq}) for robot {r.name!r}, got {q.shape}")
    if not (math.isfinite(cutoff) and cutoff > 0.0):
        raise ValueError(f"min_distances: cutoff={cutoff!r} must be a distance > 0 [m]")
    if not pairs:
        raise ValueError("min_distances: no link pair to check")
    names = tuple((str(a), str(b)) for a, b in pairs)
    distances = np.full(len(q), math.inf)
    closest = np.full(len(q), -1, dtype=np.intp)
    pair_minimum = np.full(len(names), math.inf)
    with DualArmCell(CellConfig.for_robot(r, collisions=False)) as cell:
        cid, body = cell.client_id, cell.body_id
        links = [(cell.link_index(a), cell.link_index(b)) for a, b in names]
        used = sorted({i for pair in links for i in pair})
        slot = {link: k for k, link in enumerate(used)}
        ia = np.array([slot[a] for a, _ in links])
        ib = np.array([slot[b] for _, b in links])
        for k, row in enumerate(q):
            cell.pose(row)
            boxes = np.array([p.getAABB(body, link, physicsClientId=cid) for link in used])  # (links, 2, 3)
            gap = np.maximum(np.maximum(boxes[ia, 0] - boxes[ib, 1], boxes[ib, 0] - boxes[ia, 1]), 0.0)
            near = np.flatnonzero(np.linalg.norm(gap, axis=1) < cutoff).tolist()  # AABB gap: a lower bound
            best, best_i = math.inf, -1
            for i in near:
                la, lb = links[i]
                points = p.getClosestPoints(body, body, cutoff, la, lb, physicsClientId=cid)
                if not points:
                    continue
                d = min(c[8] for c in points)
                pair_minimum[i] = min(pair_minimum[i], d)
                if d < best:
                    best, best_i = d, i
            distances[k], closest[k] = best, best_i
    return MinDistances(names, distances, closest, pair_minimum, float(cutoff))


def moved_links(cell: DualArmCell) -> list[str]:
    """The links of ``cell`` that one of its commanded (arm) joints moves, in pybullet's link order."""
    cid, body = cell.client_id, cell.body_id
    infos = [p.getJointInfo(body, j, physicsClientId=cid) for j in range(p.getNumJoints(body, physicsClientId=cid))]
    arm = set(cell.joint_names)
    moved: set[int] = set()
    for j, info in enumerate(infos):  # a joint's parent link comes before it in pybullet's order
        if info[1].decode() in arm or info[16] in moved:
            moved.add(j)
    return [infos[j][12].decode() for j in sorted(moved)]


def obstacle_min_distances(robot: RobotDescription | str, positions: FloatArray, obstacles: Sequence[Obstacle],
                           cutoff: float = DEFAULT_CUTOFF, paths: Mapping[str, FloatArray] | None = None) -> MinDistances:
    """The smallest distance between the links an arm joint moves and the ``obstacles``, at every row of
    ``positions``, from pybullet (as :func:`min_distances`, on the simulator's own shapes: the
    robot's cell with the obstacles' bodies, :mod:`dualarm_sim.obstacles`): one
    ``p.getClosestPoints(robot, obstacle, cutoff)`` per obstacle and row, every link at once. The
    pairs are (link, ``obstacle:<name>``), every moved link against every obstacle; a pair farther
    than ``cutoff`` [m] counts as ``inf``. ``paths``: a moving obstacle's position [m] at each row, (k, 3), by
    name (its body placed there first). Raises as :func:`min_distances` (ValueError: no obstacle)."""
    r = load_robot(robot)
    q = np.asarray(positions, dtype=float)
    if q.ndim != 2 or q.shape[1] != r.nq:
        raise DimensionError(f"obstacle_min_distances: positions must be (k, {r.nq}) for robot {r.name!r}, "
                             f"got {q.shape}")
    if not (math.isfinite(cutoff) and cutoff > 0.0):
        raise ValueError(f"obstacle_min_distances: cutoff={cutoff!r} must be a distance > 0 [m]")
    if not obstacles:
        raise ValueError("obstacle_min_distances: no obstacle to check")
    with DualArmCell(CellConfig.for_robot(r, collisions=False, obstacles=tuple(obstacles))) as cell:
        cid, body = cell.client_id, cell.body_id
        links = moved_links(cell)
        names = tuple((link, o.label) for o in obstacles for link in links)
        column = {(cell.link_index(link), k): i for i, (link, k) in enumerate(
            (link, k) for k in range(len(obstacles)) for link in links)}
        bodies = [cell.obstacle_bodies[o.name] for o in obstacles]
        distances = np.full(len(q), math.inf)
        closest = np.full(len(q), -1, dtype=np.intp)
        pair_minimum = np.full(len(names), math.inf)
        moved = [(cell.obstacle_bodies[name], np.asarray(path, dtype=float)) for name, path in (paths or {}).items()]
        for k, row in enumerate(q):
            cell.pose(row)
            for other, path in moved:
                p.resetBasePositionAndOrientation(other, path[k].tolist(), (0.0, 0.0, 0.0, 1.0), physicsClientId=cid)
            for o, other in enumerate(bodies):
                for c in p.getClosestPoints(body, other, cutoff, physicsClientId=cid):
                    i = column.get((c[3], o))
                    if i is None:
                        continue
                    d = float(c[8])
                    pair_minimum[i] = min(pair_minimum[i], d)
                    if d < distances[k]:
                        distances[k], closest[k] = d, i
    return MinDistances(names, distances, closest, pair_minimum, float(cutoff))


@dataclass(frozen=True)
class ContactEvent:
    """A link pair coming into contact (``started``) or separating.

    Attributes:
        pair: the two links.
        started: True when the contact begins, False when the pair separates.
        step: the step count at the event [-].
        depth: penetration depth [m], >= 0: at the first contact step when started, the deepest
            of the contact when it ends.
        steps: contact-steps of this contact so far [-] (1 when it starts).
    """

    pair: Pair
    started: bool
    step: int
    depth: float
    steps: int

    def text(self) -> str:
        """The log line, e.g. ``contact left_link_5 - right_flange: 2.1 mm deep``."""
        a, b = self.pair
        if self.started:
            return f"contact {a} - {b}: {self.depth * 1e3:.1f} mm deep (step {self.step})"
        return (f"contact {a} - {b} ended after {self.steps} steps, {self.depth * 1e3:.1f} mm deep at most "
                f"(step {self.step})")


class ContactCounter:
    """Contact-steps per link pair: a pair in contact counts once per step it is in contact.

    Usage, once per step: ``for event in counter.update(cell.contacts()): log(event.text())``.

    Attributes:
        steps: the steps counted [-].
        per_pair: contact-steps per pair, in the order the pairs first touched.
        deepest: the deepest penetration over the run [m], >= 0 (0 without contact).
        current: the pairs in contact at the last step, with their depth [m].
    """

    def __init__(self) -> None:
        self.steps = 0
        self.per_pair: dict[Pair, int] = {}
        self.deepest = 0.0
        self.current: dict[Pair, float] = {}
        self._episode: dict[Pair, tuple[int, float]] = {}  # ongoing contacts: steps, deepest [m]

    @property
    def total(self) -> int:
        """Contact-steps summed over the pairs [-]."""
        return sum(self.per_pair.values())

    def update(self, contacts: Mapping[Pair, float]) -> list[ContactEvent]:
        """Count one step's contacts (pair -> distance [m], <= 0, as
        :meth:`~dualarm_sim.cell.DualArmCell.contacts` gives them); the pairs that started or
        ended, separations first."""
        self.steps += 1
        events = []
        for pair in [q for q in self._episode if q not in contacts]:
            n, deepest = self._episode.pop(pair)
            events.append(ContactEvent(pair, False, self.steps, deepest, n))
        self.current = {}
        for pair, distance in contacts.items():
            depth = max(-float(distance), 0.0)
            self.current[pair] = depth
            self.per_pair[pair] = self.per_pair.get(pair, 0) + 1
            self.deepest = max(self.deepest, depth)
            n, deepest = self._episode.get(pair, (0, 0.0))
            self._episode[pair] = (n + 1, max(deepest, depth))
            if n == 0:
                events.append(ContactEvent(pair, True, self.steps, depth, 1))
        return events

    def pairs_text(self) -> str:
        """``link_a-link_b:steps`` per pair, comma-separated (empty without contact)."""
        return ", ".join(f"{a}-{b}:{n}" for (a, b), n in self.per_pair.items())

    def diagnostics(self) -> dict[str, int | float | str]:
        """The ``/diagnostics`` values: ``contacts`` (contact-steps), ``contact_pairs``
        (:meth:`pairs_text`), ``deepest_contact_m`` [m], ``in_contact`` (pairs at the last step)."""
        return {"contacts": self.total, "contact_pairs": self.pairs_text(),
                "deepest_contact_m": round(self.deepest, 6), "in_contact": len(self.current)}
