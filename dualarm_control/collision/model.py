"""The robot's collision model: its links with collision shapes, the link pairs checked, the
broadphase lower bounds, and the per-call distances (:meth:`CollisionModel.near`; the computation
itself is in :mod:`dualarm_control.collision.distances`).

Pairs (:class:`CollisionModel`), a link being the parent frame of a shape, "the world" every shape
not moved by an arm joint (the torso, the pedestal, the arms' bases, a locked head), and the joint
distance of two links the number of arm joints on the kinematic tree's path between them (links
fixed to each other count as one body; two links at joint distance 1 are adjacent: their shapes
touch or overlap at the joint, by design):

* every link of the left arm (moved by a left joint: the flange, the tool, the fingers too)
  against every link of the right arm;
* every arm link against every shape of the world at joint distance >= 2 (the first link of an
  arm, on its base, is adjacent to the world);
* with ``self_collision``, each arm against its own links at joint distance >= 3 (links i and i+2
  of an arm share link i+1 between them and are not checked: on the LWR4 link i's cylinder reaches
  past joint i+1's origin, and on Baxter the elbow and forearm shapes overlap their neighbours');
* every link moved by an arm joint (the arms' first links too) against every obstacle of the scenario
  (:mod:`dualarm_control.obstacles`: world shapes ``obstacle:<name>``, :mod:`~dualarm_control.collision.obstacles`);
* minus the ``allowed`` link pairs (e.g. a peg and its hole), minus the pairs the broadphase proves
  can never come within ``margin`` of each other (:meth:`CollisionModel.lower_bound`).

No pair is chosen or dropped by looking at a configuration: a pair that overlaps in the robot's
ready configuration is kept (and reported by :meth:`CollisionModel.distances` with d <= 0).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import coal
import numpy as np
import numpy.typing as npt
import pinocchio as pin

from dualarm_control.arrays import FloatArray
from dualarm_control.collision.distances import (
    NearPairs,
    PairDistance,
    ShapePairs,
    closest_pairs,
    read_witness,
    witness_pair_rows,
)
from dualarm_control.collision.obstacles import add_obstacles
from dualarm_control.collision.params import (
    DEFAULT_GJK_TOLERANCE,
    DEFAULT_MARGIN,
    FALLBACK_GJK_TOLERANCES,
    SAME_ARM_JOINT_DISTANCE,
    SPHERE_BROADPHASE_MIN,
    TOOL_FRAMES,
    WORLD,
    WORLD_JOINT_DISTANCE,
    distance_request,
)
from dualarm_control.collision.placements import JointFrames, SphereGaps
from dualarm_control.collision.shapes import (
    bounding_sphere,
    end_effector_links,
    farthest,
    reduced_geometry,
    shape_distance,
    sphere_distance,
    urdf_tree,
)
from dualarm_control.kinematics import DualArmModel
from dualarm_control.obstacles import Obstacle


@dataclass(frozen=True)
class _Body:
    """A link with collision shapes: its joint (0 = the world) and its side ('left', 'right', WORLD);
    an obstacle is a world body checked against every arm link."""

    name: str
    joint: int
    side: str
    geometries: tuple[int, ...]
    obstacle: bool = False



class CollisionModel:
    """The robot's collision shapes and the link pairs checked (module docstring).

    Args:
        model: the arms' kinematic model; the geometry is reduced like ``model.model`` (RobotError
            if the reduced models differ).
        allowed: link pairs never checked, in either order (e.g. ``("left_flange",
            "right_flange")``, the LWR4 cell's hole block and peg); ValueError for an unknown link.
        self_collision: check each arm against its own links (joint distance >= 3).
        margin: broadphase margin [m]: a pair whose distance is proven >= margin at every
            configuration is dropped; must be >= the influence distance it is used with.
        gjk_tolerance: coal's GJK tolerance, on the duality gap [m^2] (:data:`DEFAULT_GJK_TOLERANCE`;
            EPA keeps :data:`EPA_TOLERANCE`).
        obstacles: a scenario's static obstacles (:mod:`dualarm_control.obstacles`): world shapes
            ``obstacle:<name>`` checked against every link an arm joint moves (docs/obstacles.md).

    Attributes:
        pairs: the link pairs checked, (link_a, link_b): left before right, world before an arm, an arm
            link before an obstacle (the obstacles' pairs last, by obstacle).
        pruned: the pairs the broadphase dropped, with their distance lower bound [m].
        geometry_pairs: how many shape pairs the link pairs hold (one link may have several shapes).
    """

    def __init__(self, model: DualArmModel, allowed: Sequence[tuple[str, str]] = (), self_collision: bool = True,
                 margin: float = DEFAULT_MARGIN, gjk_tolerance: float = DEFAULT_GJK_TOLERANCE,
                 obstacles: Sequence[Obstacle] = ()) -> None:
        if not (math.isfinite(margin) and margin > 0.0):
            raise ValueError(f"margin={margin!r} must be a distance > 0 [m]")
        if not (math.isfinite(gjk_tolerance) and gjk_tolerance > 0.0):
            raise ValueError(f"gjk_tolerance={gjk_tolerance!r} must be > 0 [m]")
        self.kinematics = model
        self.margin = float(margin)
        self.self_collision = self_collision
        self.model, self.geometry = reduced_geometry(model)
        self.obstacles: tuple[Obstacle, ...] = tuple(obstacles)
        self._obstacle_names = frozenset(add_obstacles(self.model, self.geometry, self.obstacles))
        self.data = self.model.createData()
        self._bodies = self._find_bodies()
        self._body_index = {b.name: i for i, b in enumerate(self._bodies)}
        links = {f.name for f in self.model.frames if f.type == pin.FrameType.BODY}
        for pair in allowed:
            if len(pair) != 2:
                raise ValueError(f"allowed pair {pair!r}: expected two link names")
            for name in pair:
                if name not in links:
                    raise ValueError(f"allowed pair {tuple(pair)!r}: {name!r} is not a link of {model.urdf.name} "
                                     f"(links with collision shapes: {', '.join(b.name for b in self._bodies)})")
        self.allowed_given: frozenset[frozenset[str]] = frozenset(frozenset(p) for p in allowed)
        """The allowed pairs as given (a tool frame not yet expanded to its end effector)."""
        self.allowed: frozenset[frozenset[str]] = frozenset(
            frozenset((a, b)) for pair in allowed for a in self.end_effector(pair[0]) for b in self.end_effector(pair[1]))
        pin.framesForwardKinematics(self.model, self.data, pin.neutral(self.model))
        pin.updateGeometryPlacements(self.model, self.data, self.geometry, self.geometry.createData())
        candidates = self._candidates()
        self.pairs: list[tuple[str, str]] = []
        self.pruned: list[tuple[str, str, float]] = []
        self._pair_geometries: list[tuple[int, int, list[int]]] = []  # body a, body b, collision pair ids
        for a, b in candidates:
            bound = self.lower_bound(self._bodies[a].name, self._bodies[b].name)
            if bound >= self.margin:
                self.pruned.append((self._bodies[a].name, self._bodies[b].name, bound))
                continue
            ids = []
            for ga in self._bodies[a].geometries:
                for gb in self._bodies[b].geometries:
                    self.geometry.addCollisionPair(pin.CollisionPair(ga, gb))
                    ids.append(len(self.geometry.collisionPairs) - 1)
            self.pairs.append((self._bodies[a].name, self._bodies[b].name))
            self._pair_geometries.append((a, b, ids))
        self.geometry_pairs: int = len(self.geometry.collisionPairs)
        self._frames = JointFrames(self.model, self.data)  # oMi for the sphere bounds
        self.request = distance_request(gjk_tolerance)
        """The request of every shape pair (absolute tolerance, no warm start:
        :mod:`~dualarm_control.collision.distances`)."""
        self.geometry_data = self.geometry.createData()
        """The shapes' placements in the world at the last call that computed a distance (``oMg``,
        ``pin.updateGeometryPlacements``). Its per-pair distance functors are not used: they keep
        GJK's state from call to call (the same q then gives other witness points, measured)."""
        self._index_shape_pairs()
        self._none = NearPairs.empty(self.model.nv)
        self._calls = 0  # placements computed so far (the call of a deferred witness point)
        self._coal = ShapePairs(self._shapes, [g.name for g in self.geometry.geometryObjects], self._hull_points,
                                self.geometry_data.oMg, self._shape_a_list, self._shape_b_list, self._shape_pair_owner,
                                self.pairs, self._pair_motion, self._pair_support, self.request,
                                [distance_request(t) for t in FALLBACK_GJK_TOLERANCES if t > gjk_tolerance])
        """What coal needs of every shape pair (:meth:`near`'s loop)."""
        self._below = np.zeros(len(self._shape_a_list), dtype=bool)  # the known bounds' test, preallocated

    # ---- links and pairs -------------------------------------------------------------------

    @classmethod
    def shared(cls, model: DualArmModel, allowed: Sequence[tuple[str, str]] = (),
               obstacles: Sequence[Obstacle] = ()) -> CollisionModel:
        """``model``'s collision model for the ``allowed`` pairs and ``obstacles`` (default settings), built on first use
        and kept on the model (``model.derived``): the controllers, the task sampler and the reports of
        one robot in one process share it instead of building one each (0.05-0.3 s; a sweep builds a
        controller per run). Sharing changes no result: what a collision model carries from call to
        call (the known bounds of :meth:`near`) only decides what is computed, never what it returns."""
        key = (cls, frozenset(frozenset(p) for p in allowed), tuple(obstacles))
        found = model.derived.get(key)
        if not isinstance(found, cls):
            found = cls(model, allowed=allowed, obstacles=obstacles)
            model.derived[key] = found
        return found

    def _index_shape_pairs(self) -> None:
        """Arrays for the vectorised calls: each shape pair's shapes and link pair, each shape's
        joint and bounding sphere (centre in its joint's frame), each joint's support mask."""
        shapes = self.geometry.collisionPairs
        self._shape_a = np.array([cp.first for cp in shapes], dtype=np.intp)
        self._shape_b = np.array([cp.second for cp in shapes], dtype=np.intp)
        owner = []
        for i, (_, _, ids) in enumerate(self._pair_geometries):
            owner += [i] * len(ids)
        self._shape_pair_owner: list[int] = owner
        self._all_shape_pairs = np.arange(len(shapes), dtype=np.intp)
        objects = self.geometry.geometryObjects
        self._shape_joint = np.array([obj.parentJoint for obj in objects], dtype=np.intp)
        self._shape_a_list: list[int] = self._shape_a.tolist()
        self._shape_b_list: list[int] = self._shape_b.tolist()
        self._place_rotation = np.array([obj.placement.rotation for obj in objects]).reshape(-1, 3, 3)
        self._place_translation = np.array([obj.placement.translation for obj in objects]).reshape(-1, 3)
        spheres = [bounding_sphere(obj.geometry) for obj in objects]
        self._centres = np.array([c for c, _ in spheres])  # in each shape's own frame, (shapes, 3)
        self._centres_joint = (self._place_rotation @ self._centres[:, :, None])[:, :, 0] + self._place_translation
        self._radii = np.array([r for _, r in spheres])
        self._spheres = SphereGaps(self._frames, self._shape_joint, self._centres_joint, self._radii, self._shape_a,
                                   self._shape_b)  # the broadphase's sphere bounds
        self._shapes = [obj.geometry for obj in objects]
        self._hull_points: list[FloatArray | None] = [
            np.asarray(g.points()) if isinstance(g, coal.ConvexBase) else None for g in self._shapes]
        support = np.zeros((self.model.njoints, self.model.nv))
        for joint in range(1, self.model.njoints):
            for j in self._chain(joint):
                support[joint, self.model.idx_vs[j]] = 1.0
        self._support = support
        self._pair_support = np.stack((support[self._shape_joint[self._shape_a]],  # (2, shape pairs, n)
                                       support[self._shape_joint[self._shape_b]]))
        # motion bound (temporal coherence): a point of a body moves by at most sum_j c_j |dq_j| when the
        # joints move by dq, c_j = the reach of the body about joint j (revolute) or 1 (prismatic)
        coefficients = np.zeros((len(self._bodies), self.model.nv))
        for i, body in enumerate(self._bodies):
            for j in self._chain(body.joint):
                prismatic = "P" in self.model.joints[j].shortname().replace("JointModel", "")
                coefficients[i, self.model.idx_vs[j]] = 1.0 if prismatic else self._reach(body, j)
        body_of_shape = {g: i for i, body in enumerate(self._bodies) for g in body.geometries}
        self._pair_motion = (coefficients[[body_of_shape[int(g)] for g in self._shape_a.tolist()]]
                             + coefficients[[body_of_shape[int(g)] for g in self._shape_b.tolist()]])
        self._slack = np.full(len(shapes), -np.inf)  # a lower bound of each shape pair's d [m] at ...
        self._slack_q: FloatArray | None = None  # ... these joint positions (the last call's)

    def _find_bodies(self) -> list[_Body]:
        """The links that carry collision shapes, in the order of their first shape."""
        left = set(self.kinematics.joint_names[:self.kinematics.n_left])
        order: list[str] = []
        shapes: dict[str, list[int]] = {}
        joint_of: dict[str, int] = {}
        for k, obj in enumerate(self.geometry.geometryObjects):
            name = self.model.frames[obj.parentFrame].name
            if name not in shapes:
                order.append(name)
                shapes[name] = []
                joint_of[name] = obj.parentJoint
            shapes[name].append(k)
        bodies = []
        for name in order:
            joint = joint_of[name]
            side = WORLD if joint == 0 else "left" if self.model.names[joint] in left else "right"
            bodies.append(_Body(name, joint, side, tuple(shapes[name]), name in self._obstacle_names))
        return bodies

    def end_effector(self, link: str) -> list[str]:
        """``link`` itself, or for a tool frame (``left_tool``, ``right_tool``: F1, F2) its end effector:
        from the tool up through fixed joints to the first link with collision shapes (the LWR4's
        flange, Baxter's gripper base) and every link fixed below it (Baxter's locked fingers, the
        tool frame, a tool set's bodies: :func:`~dualarm_control.collision.shapes.end_effector_links`),
        as the simulator groups them (``dualarm_sim.cell``). An allowed pair naming a tool
        frame allows the whole end effector (``left_tool right_tool``: the tools meet on purpose)."""
        if link not in TOOL_FRAMES:
            return [link]
        parent_of, rigid = urdf_tree(self.kinematics.urdf, self.kinematics.joint_names)
        return end_effector_links(link, parent_of, rigid, {b.name for b in self._bodies})

    def _body(self, link: str) -> _Body:
        index = self._body_index.get(link)
        if index is None:
            raise KeyError(f"{link!r} is not a link with collision shapes; links: "
                           f"{', '.join(b.name for b in self._bodies)}")
        return self._bodies[index]

    @property
    def links(self) -> list[str]:
        """The links that carry collision shapes, in the URDF's order."""
        return [b.name for b in self._bodies]

    def link_side(self, link: str) -> str:
        """``"left"`` or ``"right"`` (moved by that arm's joints), or :data:`WORLD` (fixed)."""
        return self._body(link).side

    def joint_distance(self, link_a: str, link_b: str) -> int:
        """Number of arm joints on the kinematic tree's path between two links [-] (KeyError for a
        name that is not a link)."""
        for name in (link_a, link_b):
            if not self.model.existFrame(name):
                raise KeyError(f"{name!r} is not a link of {self.kinematics.urdf.name}")
        ja, jb = (self.model.frames[self.model.getFrameId(n)].parentJoint for n in (link_a, link_b))
        chain_a, chain_b = self._chain(ja), self._chain(jb)
        common = len(set(chain_a) & set(chain_b))
        return len(chain_a) + len(chain_b) - 2 * common

    def _chain(self, joint: int) -> list[int]:
        """The joints from the world to ``joint``, inclusive (empty for the world)."""
        out = []
        while joint != 0:
            out.append(joint)
            joint = self.model.parents[joint]
        return out[::-1]

    def _candidates(self) -> list[tuple[int, int]]:
        """Body index pairs by the rules of the module docstring, before the broadphase."""
        out = []
        obstacle_pairs = []  # (arm link, obstacle), after the others
        bodies = self._bodies
        rank = {WORLD: 0, "left": 1, "right": 2}
        for i, a in enumerate(bodies):
            for j, b in enumerate(bodies):
                if j <= i:
                    continue
                if rank[a.side] > rank[b.side]:
                    i2, j2, a2, b2 = j, i, b, a
                else:
                    i2, j2, a2, b2 = i, j, a, b
                if frozenset((a2.name, b2.name)) in self.allowed or a2.side == b2.side == WORLD:
                    continue
                if a2.obstacle:  # an obstacle against every arm link, the first links too
                    obstacle_pairs.append((j2, i2))
                    continue
                jd = self.joint_distance(a2.name, b2.name)
                if a2.side == WORLD:
                    keep = jd >= WORLD_JOINT_DISTANCE
                elif a2.side == b2.side:
                    keep = self.self_collision and jd >= SAME_ARM_JOINT_DISTANCE
                else:
                    keep = True
                if keep:
                    out.append((i2, j2))
        out.sort(key=lambda ij: (rank[bodies[ij[0]].side], rank[bodies[ij[1]].side], ij))
        return out + sorted(obstacle_pairs, key=lambda ij: (ij[1], ij[0]))

    def _reach(self, body: _Body, start: int) -> float:
        """Radius [m] of a sphere about the origin of joint ``start`` (an ancestor of the body's
        joint, or the body's joint itself) that holds the body's shapes at every configuration:
        the joint offsets from ``start`` to the body's joint (triangle inequality: the joints only
        turn the offsets) plus the shapes' extent from the body's joint origin."""
        extent = max(farthest(self.geometry.geometryObjects[k]) for k in body.geometries)
        chain = self._chain(body.joint)
        offsets = chain[chain.index(start) + 1:]
        return extent + sum(float(np.linalg.norm(self.model.jointPlacements[j].translation)) for j in offsets)

    def lower_bound(self, link_a: str, link_b: str) -> float:
        """A lower bound [m] of the two links' distance over all configurations (the broadphase).

        Let A be the link nearer the world. If B is on the other arm (or A is the world), B's
        shapes stay in a sphere about B's arm's first joint origin o_1 (fixed in the world) of
        radius R_B = sum of the joint offsets after o_1 + B's extent; likewise A's when it moves:
        bound = ||o_1A - o_1B|| - R_A - R_B, or the distance of A's shapes to B's sphere when A is
        the world. If B is on A's arm beyond A's joint k, B's sphere is about the origin of joint
        k + 1, which is fixed to A: bound = distance of A's shapes to that sphere (coal, in the
        frame of joint k). Two links on one joint (or both in the world) keep their distance: the
        bound is that distance. Negative when the spheres overlap the shapes (the pair is kept).
        KeyError for a link without collision shapes.
        """
        a, b = self._body(link_a), self._body(link_b)
        if a.joint == b.joint:
            return min(shape_distance(self.geometry.geometryObjects[ka], self.geometry.geometryObjects[kb])
                       for ka in a.geometries for kb in b.geometries)
        if a.side != WORLD and (b.side == WORLD or (a.side == b.side and len(self._chain(a.joint)) >
                                                    len(self._chain(b.joint)))):
            a, b = b, a
        chain_b = self._chain(b.joint)
        if a.side != WORLD and a.side != b.side:
            chain_a = self._chain(a.joint)
            o_a = self.data.oMi[chain_a[0]].translation
            o_b = self.data.oMi[chain_b[0]].translation
            return float(np.linalg.norm(o_a - o_b)) - self._reach(a, chain_a[0]) - self._reach(b, chain_b[0])
        if a.side == WORLD:  # A in the world frame, B's sphere about its arm's first joint (fixed)
            start = chain_b[0]
            centre = self.data.oMi[start].translation
        else:  # A in its joint's frame, B's sphere about the next joint of B's chain (fixed to A)
            start = chain_b[chain_b.index(a.joint) + 1]
            centre = self.model.jointPlacements[start].translation
        return sphere_distance([self.geometry.geometryObjects[k] for k in a.geometries], centre,
                               self._reach(b, start))

    # ---- distances ---------------------------------------------------------------------------

    def distances(self, q: FloatArray, within: float | None = None, polish: bool = False) -> list[PairDistance]:
        """Every pair's distance, witness points, normal and row dd_dq at q
        (:mod:`~dualarm_control.collision.distances`): :meth:`near` as one :class:`PairDistance` per
        pair, in the order of :attr:`pairs`."""
        return self.near(q, within, polish).pair_distances()

    def near(self, q: FloatArray, within: float | None = None, polish: bool = False, rows: bool = True) -> NearPairs:
        """The pairs' distances, witness points, normals and rows dd_dq at q, as arrays
        (:mod:`~dualarm_control.collision.distances`).

        Args:
            q: joint positions [rad], (n,), left then right.
            within: if given [m], only the pairs with d < within. Then only the shape pairs that may
                be closer than ``within`` go to coal, and rows are computed only for the pairs kept:
                the cheap call for the damper, which needs the pairs with d < d_i. Two lower bounds
                decide: what is known of a pair (its distance, or its bounding spheres' gap, at the
                joint positions of an earlier call) minus how far its shapes can have moved since,
                sum_j c_j |dq_j| summed over the calls between (c_j the reach of the shape's body
                about joint j, m per rad: :attr:`_pair_motion`; one matrix-vector product per call,
                no kinematics at all when nothing can be near; a non-finite q forgets it all), then,
                when more than :data:`SPHERE_BROADPHASE_MIN` shape pairs are left, the bounding
                spheres (about each shape's centre, placed at q). The result does not depend on
                earlier calls: a pair with d < within passes both bounds and is computed, from the
                same placements (pinocchio's oMi * the shape's placement) whatever the bounds kept.
            polish: refine the witness points and normals of the pairs returned on the shapes' closest
                features (:func:`~dualarm_control.collision.features.polish_witness`; rows to 1e-6 m/rad
                instead of 1e-5, at up to 100 us per pair): the distances are coal's either way;
                False (the default) gives GJK's points and normals.
            rows: compute the rows dd_dq now; False defers them and, without ``polish``, the witness
                points and normals too (``NearPairs.rows``, ``points`` and ``normals`` None;
                :meth:`rows`, :meth:`witness` and :meth:`complete` give the same later, from coal's
                arrays, which the returned object keeps).

        Returns:
            the pairs (those within), in the order of :attr:`pairs`.
        """
        q = self.kinematics.check_q(q)
        active = self._broadphase(q, within)
        if active is None:
            return self._none
        pin.updateGeometryPlacements(self.model, self.data, self.geometry, self.geometry_data)  # oMg = oMi * placement
        self._calls += 1
        found = closest_pairs(self._coal, active, within, self._slack, self.data.J, self._calls, polish, rows)
        return self._none if found is None else found

    def _broadphase(self, q: FloatArray, within: float | None) -> npt.NDArray[np.intp] | None:
        """The shape pairs that may be closer than ``within`` at q [rad] (n,), ascending (all of them
        when ``within`` is None), None when none may be (:meth:`near` has the two bounds); the
        known bounds moved to q, and the joints' placements and Jacobians computed at q (``data``)
        unless no pair may be near."""
        if not math.isfinite(sum(q.tolist())):  # forget what is known (it would turn NaN); no pair is near
            self._slack.fill(-np.inf)
            self._slack_q = None
            if within is not None:
                return None
        else:
            if self._slack_q is not None:  # what is known, moved to q: d(q) >= d(q') - sum_j c_j |q_j - q'_j|
                self._slack -= self._pair_motion @ np.abs(q - self._slack_q)
            self._slack_q = q.copy()
        candidates = self._all_shape_pairs
        if within is not None:  # pairs whose distance may be < within, from what is known (no kinematics)
            candidates = np.less(self._slack, within, out=self._below).nonzero()[0]
            if not candidates.size:
                return None
        pin.computeJointJacobians(self.model, self.data, q)  # the joints' placements data.oMi too
        if within is None or candidates.size <= SPHERE_BROADPHASE_MIN:
            active = candidates
        else:
            spheres = self._spheres.bounds(candidates)
            self._slack[candidates] = spheres
            active = candidates[spheres < within]
        return active

    def witness(self, near: NearPairs) -> tuple[FloatArray, FloatArray]:
        """The witness points (2, m, 3) [m] and unit normals (m, 3) of ``near``'s pairs: as the call
        kept them or, when it deferred them, made now from coal's arrays it kept (a pair whose GJK
        points are NaN is computed again, its distance in ``near`` kept: CollisionError if another
        :meth:`near` call came between)."""
        if near.points is not None and near.normals is not None:
            return near.points, near.normals
        assert near.raw_witness is not None, "a NearPairs without witness points keeps coal's"
        return read_witness(self._coal, near.raw_witness, near.shape_pairs.tolist(), near.distance.copy(), near.call,
                            self._calls)

    def complete(self, near: NearPairs) -> NearPairs:
        """``near`` with its witness points, normals and rows (those it deferred, built now)."""
        if near.rows is not None and near.points is not None:
            return near
        points, normals = self.witness(near)
        with_points = replace(near, points=points, normals=normals)
        return replace(with_points, rows=self.rows(with_points))

    def rows(self, near: NearPairs) -> FloatArray:
        """The rows dd_dq [m/rad] (m, n) of ``near``'s pairs: ``near.rows``, or, when the call deferred
        them, the same rows built now from the witness points, normals and Jacobians it kept."""
        if near.rows is not None:
            return near.rows
        points, normals = self.witness(near)
        return witness_pair_rows(near.shape_pairs, points, normals, near.jacobian, self._pair_support)

    def shape_placement(self, index: int) -> pin.SE3:
        """Shape ``index``'s placement in the world at the last :meth:`distances` call that computed a
        distance (pinocchio's ``oMg``: oMi * the shape's placement in its joint's frame)."""
        return pin.SE3(self.geometry_data.oMg[index])

    def closest(self, q: FloatArray) -> PairDistance:
        """The pair with the smallest distance at q (ValueError when the model has no pair)."""
        if not self.pairs:
            raise ValueError("the collision model has no pair")
        return min(self.distances(q), key=lambda p: p.distance)

