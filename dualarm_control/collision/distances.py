"""The distances of the robot's link pairs, their witness points, normals and rows dd_dq.

Distances (``coal.distance`` on the shapes placed by ``pin.updateGeometryPlacements``), for a pair
of shapes A (on link a) and B (on link b) at the joint configuration q [rad], (n,):

    d = n^T (p_b - p_a)                                   [m]

with p_a, p_b [m], (3,), the witness points in the world (the nearest points of A and B) and n,
(3,), the unit normal from A to B. When A and B are separate, d = ||p_b - p_a|| > 0 and n = (p_b -
p_a) / d; when they touch d = 0; when they penetrate coal's EPA returns d < 0, minus the
penetration depth (the shortest translation of B that separates them), p_b - p_a = d n then points
against n (B's deepest point lies inside A). A link with several shapes (Baxter's fingers) keeps
the pair of shapes with the smallest d. Accuracy (measured, docs/collision.md): d to about
1e-12 / d m apart (certified by GJK's duality gap,
:data:`~dualarm_control.collision.params.DEFAULT_GJK_TOLERANCE`), to 1e-6 m in penetration (EPA); the
rows to 3e-6 m/rad for 99 % of the pairs near contact (worst seen 5e-5: witness points sliding along a
rim or an edge).
Every call starts GJK afresh (no warm start): the same q gives the same distances bit for bit,
whatever was computed before.

Distance velocity: the witness points move with their links, so (for unique witness points)

    d_dot = n^T (v(p_b) - v(p_a)) = dd_dq qd,   dd_dq = n^T (J_pb - J_pa)   (1, n)

where J_p = J_v - S(p - o) J_w, (3, n), is the Jacobian of the point of the link at p [m/s per
rad/s]: [J_v; J_w] the link's parent joint's Jacobian (pinocchio LOCAL_WORLD_ALIGNED: velocity of
the joint origin o and angular velocity, world axes), S the cross-product matrix. A fixed part's
J_p is zero. (The motion of the witness points over the surfaces and of n do not contribute: n
is normal to both surfaces at the witness points and n^T dn = 0.)

The per-call part of :meth:`CollisionModel.near <dualarm_control.collision.CollisionModel.near>`
is here (:func:`closest_pairs`: coal on the shape pairs the model's broadphase left, the closest
shape pair of each link pair, the witness points and rows), on the model's :class:`ShapePairs`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import coal
import numpy as np
import numpy.typing as npt

from dualarm_control.arrays import FloatArray
from dualarm_control.collision.features import polish_witness
from dualarm_control.collision.params import (
    _FAILED,
    DEFAULT_GJK_TOLERANCE,
    FALLBACK_GJK_TOLERANCES,
    KNOWN_MARGIN,
    CollisionError,
    distance_request,
)


@dataclass(frozen=True, slots=True)
class PairDistance:
    """The distance of one link pair at one configuration (module docstring).

    Attributes:
        link_a, link_b: the links (parent frames of the shapes), as in :attr:`CollisionModel.pairs`.
        geometry_a, geometry_b: the shapes that are closest (pinocchio geometry names).
        distance: d [m]: > 0 apart, 0 touching, < 0 penetrating (minus the depth).
        point_a, point_b: witness points p_a on A and p_b on B in the world [m], (3,).
        normal: n, unit, from A to B, (3,): p_b - p_a = d n.
        dd_dq: the row with d_dot = dd_dq @ qd, (n,) [m/rad].
    """

    link_a: str
    link_b: str
    geometry_a: str
    geometry_b: str
    distance: float
    point_a: FloatArray
    point_b: FloatArray
    normal: FloatArray
    dd_dq: FloatArray


@dataclass(slots=True)
class NearPairs:
    """The pairs of one :meth:`CollisionModel.near` call, as arrays (m pairs, in the order of
    :attr:`CollisionModel.pairs`): what the collision limit needs each cycle, without one object
    per pair (:meth:`pair_distances` gives those). A per-cycle record: slotted, not frozen
    (cheaper to build); not modified once returned (:meth:`CollisionModel.complete` makes a new one).

    Attributes:
        index: each pair's index in :attr:`CollisionModel.pairs`, (m,).
        links: each pair's links (link_a, link_b). geometries: its closest shapes.
        distance: d [m], (m,). points: p_a, p_b [m], (2, m, 3). normals: n, (m, 3). Both None
            when the call deferred them (:meth:`CollisionModel.witness` makes them from ``raw_witness``).
        rows: dd_dq [m/rad], (m, n); None when the call deferred them (:meth:`CollisionModel.rows`
            builds them from the witness points, ``shape_pairs`` and ``jacobian``).
        speed: how fast each pair's distance can change, C [m/rad] (m, n): |dd_dq qd| <= C |qd| for
            every qd (the reach of the pair's two links about each joint, :attr:`CollisionModel._pair_motion`).
        shape_pairs: each pair's closest shape pair (its index in the geometry's collision pairs), (m,).
        jacobian: pinocchio's joint Jacobians ``data.J`` at the call's q, (6, n) (for deferred rows).
        raw_witness: coal's (p_a, p_b, n) of each pair as it gave them, (m, 3, 3), when the witness
            points were deferred (else None). call: the model's placements count at this call (a deferred
            witness point whose GJK failed is computed again only at that call's placements).
    """

    index: tuple[int, ...]
    links: tuple[tuple[str, str], ...]
    geometries: tuple[tuple[str, str], ...]
    distance: FloatArray
    points: FloatArray | None
    normals: FloatArray | None
    rows: FloatArray | None
    speed: FloatArray
    shape_pairs: npt.NDArray[np.intp]
    jacobian: FloatArray
    raw_witness: FloatArray | None = None
    call: int = 0

    def __len__(self) -> int:
        return len(self.index)

    @classmethod
    def empty(cls, n: int) -> NearPairs:
        """No pair, for n joints."""
        return cls((), (), (), np.zeros(0), np.zeros((2, 0, 3)), np.zeros((0, 3)), np.zeros((0, n)),
                   np.zeros((0, n)), np.zeros(0, dtype=np.intp), np.zeros((6, n)))

    def pair_distances(self) -> list[PairDistance]:
        """One :class:`PairDistance` per pair (ValueError when the rows were deferred:
        :meth:`CollisionModel.complete` gives them)."""
        rows, points, normals = self.rows, self.points, self.normals
        if rows is None or points is None or normals is None:
            raise ValueError("pair_distances: the rows were deferred (CollisionModel.complete builds them)")
        return [PairDistance(*self.links[r], *self.geometries[r], d, points[0, r], points[1, r],
                             normals[r], rows[r]) for r, d in enumerate(self.distance.tolist())]



@dataclass
class ShapePairs:
    """What coal needs of a collision model's shape pairs, indexed by shape pair k (the model's
    geometry's collision pairs; ``first[k]``, ``second[k]`` index the shapes), by reference: the
    placements follow the model's ``pin.updateGeometryPlacements``.

    Attributes:
        shapes: the shapes (coal geometries). names: their pinocchio names. hulls: a convex hull's
            vertices in its own frame [m], (v, 3), else None. placed: the shapes' placements in the
            world (pinocchio's ``geometry_data.oMg``).
        first, second: each shape pair's shapes. owner: each shape pair's link pair (its index in ``links``).
        links: the link pairs (:attr:`CollisionModel.pairs <dualarm_control.collision.CollisionModel.pairs>`).
        motion: each shape pair's motion bound C [m/rad], (shape pairs, n) (:attr:`NearPairs.speed`).
        support: each shape pair's two joint support masks, (2, shape pairs, n).
        request: coal's request. fallbacks: the requests of the next tries (:func:`retry`).
        results: each shape pair's coal result (the last call's). pair_names: each shape pair's shape names.
        calls: per shape pair, coal.distance's arguments but the request, and its link pair (the loop of
            :func:`closest_pairs`).
    """

    shapes: list[coal.CollisionGeometry]
    names: list[str]
    hulls: list[FloatArray | None]
    placed: Any
    first: list[int]
    second: list[int]
    owner: list[int]
    links: list[tuple[str, str]]
    motion: FloatArray
    support: FloatArray
    request: coal.DistanceRequest
    fallbacks: list[coal.DistanceRequest]
    results: list[coal.DistanceResult] = field(init=False)
    pair_names: list[tuple[str, str]] = field(init=False)
    calls: list[tuple[Any, ...]] = field(init=False)

    def __post_init__(self) -> None:
        self.results = [coal.DistanceResult() for _ in self.first]
        self.pair_names = [(self.names[a], self.names[b]) for a, b in zip(self.first, self.second, strict=True)]
        shapes, placed = self.shapes, self.placed  # references into geometry_data: they follow its placements
        self.calls = [(shapes[a], placed[a], shapes[b], placed[b], self.results[k], i)
                      for k, (a, b, i) in enumerate(zip(self.first, self.second, self.owner, strict=True))]


def closest_pairs(table: ShapePairs, active: npt.NDArray[np.intp], within: float | None, slack: FloatArray,
                  jacobian: FloatArray, call: int, polish: bool, rows: bool) -> NearPairs | None:
    """The link pairs' distances (those within, if given; None when none) from coal on the shape pairs
    ``active``, ascending, at the shapes' placements of this call: each link pair's closest shape
    pair, its witness points, normal and row (:meth:`CollisionModel.near
    <dualarm_control.collision.CollisionModel.near>` has the arguments).

    Args:
        table: the model's shape pairs. active: the shape pairs to compute, ascending, (k,).
        within: [m] or None. slack: each shape pair's known lower bound [m], (shape pairs,): every
            computed distance less :data:`~dualarm_control.collision.params.KNOWN_MARGIN` is kept there.
        jacobian: pinocchio's joint Jacobians ``data.J`` at this call's q, (6, n) (copied).
        call: this call's number (:attr:`NearPairs.call`). polish, rows: as :meth:`CollisionModel.near
            <dualarm_control.collision.CollisionModel.near>`'s.
    """
    request, calls = table.request, table.calls
    best: dict[int, tuple[float, int]] = {}  # link pair -> (d, shape pair)
    for k in active.tolist():
        shape_a, placed_a, shape_b, placed_b, res, i = calls[k]
        res.clear()
        d = coal.distance(shape_a, placed_a, shape_b, placed_b, request, res)
        if not -_FAILED < d < _FAILED:  # also NaN
            d = retry(table, k)
        slack[k] = d - KNOWN_MARGIN
        if i not in best or d < best[i][0]:
            best[i] = (d, k)
    # the link pairs within, in the order of table.links: active is ascending and each link pair's
    # shape pairs are consecutive (_index_shape_pairs), so best's first insertions are in that order
    pairs, shape_pairs, found = [], [], []
    for i, (d, k) in best.items():
        if within is None or d < within:
            pairs.append(i)
            shape_pairs.append(k)
            found.append(d)
    if not pairs:
        return None
    dist = np.array(found)  # coal.distance returns the result's min_distance
    index = np.array(shape_pairs, dtype=np.intp)
    jacobian = jacobian.copy()
    links = tuple([table.links[i] for i in pairs])
    names = tuple([table.pair_names[k] for k in shape_pairs])
    results = table.results
    # coal's witness points and normals as it gives them, (m, 3, 3) (a copy: its arrays are views of
    # the results, which the next call overwrites); checked and normalised now for rows or polish,
    # else when first needed (witness())
    raw = np.array([(res.getNearestPoint1(), res.getNearestPoint2(), res.normal)
                    for res in map(results.__getitem__, shape_pairs)])
    if not rows and not polish:
        return NearPairs(tuple(pairs), links, names, dist, None, None, None,
                         table.motion.take(shape_pairs, axis=0), index, jacobian, raw, call)
    points, normals = read_witness(table, raw, shape_pairs, dist, call, call)
    if polish:
        for r, k in enumerate(shape_pairs):
            points[0, r], points[1, r], normals[r] = _polish(table, k, dist[r], points[0, r], points[1, r], normals[r])
    return NearPairs(tuple(pairs), links, names, dist, points, normals,
                     witness_pair_rows(index, points, normals, jacobian, table.support) if rows else None,
                     table.motion[index], index, jacobian, None, call)


def read_witness(table: ShapePairs, raw: FloatArray, shape_pairs: Sequence[int], dist: FloatArray, call: int,
                 last: int) -> tuple[FloatArray, FloatArray]:
    """The witness points p_a, p_b (2, m, 3) and unit normals (m, 3) from coal's (p_a, p_b, n) of
    ``shape_pairs`` (``raw``, (m, 3, 3), not modified). A finite distance with NaN points (GJK
    failed) is computed again (:func:`retry`, into ``dist``) at the placements of the call that
    gave them: CollisionError when ``call`` is not the ``last`` one (its placements are gone)."""
    witness = raw.copy()
    points, normals = witness[:, :2].transpose(1, 0, 2), witness[:, 2]  # (2, m, 3) and (m, 3), views
    squares = (normals * normals).sum(axis=1)
    if not math.isfinite(float(points.sum() + squares.sum())):  # a finite distance with NaN points: GJK failed
        bad = ~(np.isfinite(points).all(axis=(0, 2)) & np.isfinite(normals).all(axis=1))
        for r in np.flatnonzero(bad).tolist():
            if call != last:
                raise CollisionError(f"coal's witness points of {table.pair_names[shape_pairs[r]]} "
                                     "are not finite and the placements they were computed at are gone")
            res = table.results[shape_pairs[r]]
            dist[r] = retry(table, shape_pairs[r])
            points[0, r], points[1, r], normals[r] = res.getNearestPoint1(), res.getNearestPoint2(), res.normal
        squares = (normals * normals).sum(axis=1)
    normals /= np.sqrt(squares)[:, None]  # np.linalg.norm(normals, axis=1), as it computes it
    return points, normals


def retry(table: ShapePairs, k: int) -> float:
    """Shape pair k again, at the shapes' placements of the call (``geometry_data.oMg``), with the
    fallback requests, tightest first (GJK or EPA failed: coal then returns -DBL_MAX or an infinite
    distance and NaN points); CollisionError if all fail."""
    res = table.results[k]
    ga, gb = table.first[k], table.second[k]
    tf_a, tf_b = table.placed[ga], table.placed[gb]
    d = math.nan
    for request in table.fallbacks:
        res.clear()
        d = coal.distance(table.shapes[ga], tf_a, table.shapes[gb], tf_b, request, res)
        if -_FAILED < d < _FAILED and all(np.isfinite(x).all() for x in (
                res.getNearestPoint1(), res.getNearestPoint2(), res.normal)):
            return float(d)
    raise CollisionError(f"coal failed on the shapes {table.names[ga]!r} and {table.names[gb]!r} (distance "
                         f"{d!r}) at GJK tolerances {table.request.gjk_tolerance:g} to "
                         f"{max(FALLBACK_GJK_TOLERANCES + (table.request.gjk_tolerance,)):g}")


def _polish(table: ShapePairs, k: int, d: float, pa: FloatArray, pb: FloatArray,
            n: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """:func:`~dualarm_control.collision.features.polish_witness` of shape pair k, at its shapes'
    placements of the call (``geometry_data.oMg``)."""
    ga, gb = table.first[k], table.second[k]
    placed = table.placed
    return polish_witness(table.shapes[ga], placed[ga], table.hulls[ga], table.shapes[gb], placed[gb],
                          table.hulls[gb], d, pa, pb, n)


def witness_pair_rows(shape_pairs: npt.NDArray[np.intp], points: FloatArray, normals: FloatArray,
                      jacobian: FloatArray, support: FloatArray) -> FloatArray:
    """dd_dq = n^T (J_pb - J_pa) for m shape pairs, (m, n), from the WORLD joint Jacobians.

    pinocchio's ``data.J`` (6, n) holds every joint's motion [v_0; w] in the world, v_0 the
    velocity of the point at the world origin: the point p of a link moves at v_0 + w x p, so
    J_p = (J_lin - S(p) J_ang) restricted to the joints that move the link, and
    n^T J_p = (n^T J_lin + (p x n)^T J_ang) masked by that link's joint support.

    Args:
        shape_pairs: (m,) shape pair indices. points: p_a, p_b [m], (2, m, 3). normals: n (m, 3).
        jacobian: ``data.J`` (6, n). support: each shape pair's joint support masks, (2, pairs, n).
    """
    m = len(shape_pairs)
    n = np.concatenate((normals, normals))  # n at both points: dd_dq = n^T J_pb - n^T J_pa
    contribution = witness_rows(n, points.reshape(2 * m, 3), jacobian).reshape(2, m, -1)
    contribution *= support[:, shape_pairs]
    result: FloatArray = contribution[1] - contribution[0]
    return result



_NEXT, _PREV = np.array([1, 2, 0]), np.array([2, 0, 1])
"""The cyclic index shifts of a cross product."""


def witness_rows(normals: FloatArray, offsets: FloatArray, jacobian: FloatArray) -> FloatArray:
    """How fast witness points move along their normals (module docstring, "Distance velocity"):

        n^T J_p qd,   J_p = J_v - S(p - o) J_w,   so   n^T J_p = n^T J_v + ((p - o) x n)^T J_w

    the part of a pair's row dd_dq = n^T (J_pb - J_pa) that one point gives (its normal signed: -n
    for the point on A, +n for the point on B).

    Args:
        normals: the signed normals, (m, 3). offsets: p - o [m], (m, 3), from the point o whose
            motion ``jacobian`` gives to each witness point p.
        jacobian: [J_v; J_w], (6, n): the velocity of o and the angular velocity [m/s; rad/s per
            rad/s] (world axes), one for all m points (o the world origin: pinocchio's ``data.J``;
            or a frame's origin: LOCAL_WORLD_ALIGNED).

    Returns:
        (m, n) [m/rad].
    """
    p, n = offsets, normals
    # (p - o) x n componentwise, [p1 n2 - p2 n1, p2 n0 - p0 n2, p0 n1 - p1 n0] (np.cross costs 10x more on (m, 3))
    cross = p[:, _NEXT] * n[:, _PREV] - p[:, _PREV] * n[:, _NEXT]
    result: FloatArray = n @ jacobian[:3] + cross @ jacobian[3:]
    return result


def sphere_plane_distances(centres: FloatArray, radii: FloatArray, normal: FloatArray,
                           offset: float) -> tuple[FloatArray, FloatArray, FloatArray]:
    """coal's distances of spheres (A) to the half-space {x : normal . x <= offset} (B), as for
    every shape pair (module docstring; paper 001's f_6 table plane, eq (11)):

        d = normal . c - r - offset   [m]   (< 0: the sphere dips into the half-space)

    Args:
        centres: c [m], (m, 3), world. radii: r [m], (m,), >= 0. normal: the half-space's outward
            unit normal, (3,). offset: [m].

    Returns:
        d (m,), the witness points on the spheres (m, 3) (c - r normal) and the normals n from A
        to B (m, 3) (-normal): a sphere's row is :func:`witness_rows` of -n at p - c = -r normal.
    """
    request = distance_request(DEFAULT_GJK_TOLERANCE)
    plane = coal.Halfspace(np.asarray(normal, dtype=float), float(offset))
    identity = coal.Transform3s()
    m = len(radii)
    d, points, normals = np.empty(m), np.empty((m, 3)), np.empty((m, 3))
    for j in range(m):
        result = coal.DistanceResult()
        d[j] = coal.distance(coal.Sphere(float(radii[j])), coal.Transform3s(np.eye(3), centres[j]), plane, identity,
                             request, result)
        points[j], normals[j] = result.getNearestPoint1(), result.normal
    return d, points, normals
