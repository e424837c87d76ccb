"""Collision distances between the robot's links and the velocity damper that keeps them apart.

The ROS-free core of collision avoidance (issue 27; docs/collision.md): :func:`velocity_damper` gives
the rows ``A qd <= b`` that :class:`~dualarm_control.limits.collision.CollisionLimit` adds to every solver's QP.

Geometry: the robot's COLLISION shapes from its resolved URDF (``pin.buildGeomFromUrdf``), reduced
like :class:`~dualarm_control.kinematics.DualArmModel`'s model (``pin.buildReducedModel``, the same
locked joints at the same values, the same joint order). Meshes are replaced by their convex hulls
(as pybullet does for the links of a multibody): coal then returns a signed distance for every pair
and the witness points are unique for strictly separated convex shapes, except on degenerate
configurations (parallel faces or edges: the tests detect them).

Distances (``coal.distance`` on the shapes placed by ``pin.updateGeometryPlacements``), for a pair
of shapes A (on link a) and B (on link b) at the joint configuration q [rad], (n,):

    d = n^T (p_b - p_a)                                   [m]

with p_a, p_b [m], (3,), the witness points in the world (the nearest points of A and B) and n,
(3,), the unit normal from A to B. When A and B are separate, d = ||p_b - p_a|| > 0 and n = (p_b -
p_a) / d; when they touch d = 0; when they penetrate coal's EPA returns d < 0, minus the
penetration depth (the shortest translation of B that separates them), p_b - p_a = d n then points
against n (B's deepest point lies inside A). A link with several shapes (Baxter's fingers) keeps
the pair of shapes with the smallest d. Accuracy (measured, docs/collision.md): d to about
1e-12 / d m apart (certified by GJK's duality gap, :data:`DEFAULT_GJK_TOLERANCE`), to 1e-6 m in
penetration (EPA); the rows to 3e-6 m/rad for 99 % of the pairs near contact (worst seen 5e-5:
witness points sliding along a rim or an edge).
Every call starts GJK afresh (no warm start): the same q gives the same distances bit for bit,
whatever was computed before.

Distance velocity: the witness points move with their links, so (for unique witness points)

    d_dot = n^T (v(p_b) - v(p_a)) = dd_dq qd,   dd_dq = n^T (J_pb - J_pa)   (1, n)

where J_p = J_v - S(p - o) J_w, (3, n), is the Jacobian of the point of the link at p [m/s per
rad/s]: [J_v; J_w] the link's parent joint's Jacobian (pinocchio LOCAL_WORLD_ALIGNED: velocity of
the joint origin o and angular velocity, world axes), S the cross-product matrix. A fixed part's
J_p is zero. (The motion of the witness points over the surfaces and of n do not contribute: n
is normal to both surfaces at the witness points and n^T dn = 0.)

Velocity damper (Faverjon and Tournassoud 1987; Kanoun et al. 2011): for every pair closer than
the influence distance d_i, the approach speed is bounded so that d decays at most exponentially
towards the safety distance d_s:

    d_dot >= -xi (d - d_s) / (d_i - d_s)        i.e.   -dd_dq qd <= xi (d - d_s) / (d_i - d_s)

xi [m/s] is the approach speed allowed at d = d_i (it falls linearly to 0 at d = d_s, and d_dot
must be positive below d_s: the pair is pushed back out). Along the boundary d(t) - d_s = (d_0 -
d_s) exp(-t xi / (d_i - d_s)): d_s is never crossed in continuous time.

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

from dualarm_control.errors import DimensionError, DualArmError, ParameterError
from dualarm_control.kinematics import DualArmModel
from dualarm_control.robot import RobotError

FloatArray = npt.NDArray[np.float64]
TOOL_FRAMES = ("left_tool", "right_tool")
"""The tool frames F1, F2 every resolved URDF has (``dualarm_control.robot``)."""
WORLD = "world"
"""The side of the shapes no arm joint moves (the torso, the pedestal, the arms' bases)."""
SAME_ARM_JOINT_DISTANCE = 3
"""Smallest joint distance of two links of one arm that are checked against each other."""
WORLD_JOINT_DISTANCE = 2
"""Smallest joint distance of an arm link and a world shape that are checked."""
DEFAULT_MARGIN = 0.15
"""Broadphase margin [m]: pairs that can never come closer than this are not checked (1.5 times
the default influence distance: a larger d_i up to 0.15 m needs no new model)."""
DEFAULT_GJK_TOLERANCE = 1e-12
"""coal's GJK tolerance: a bound on the duality gap ||x||^2 - x.w [m^2] (absolute), which
certifies the distance (to about 1e-12 / d). Not coal's default criterion (relative, 1e-6): on
cylinder rims it can stop with witness points up to 1e-8 m outside the shapes (a distance that
much too small), and so can the duality gap at 1e-13 (seen on Baxter's forearms), where GJK
cannot progress further.
The rows' accuracy follows the tolerance: a witness point may slide by e along a rim for a change
of d of order e^2 / r, so on the LWR4 cell the rows' median error is 2e-6 m/rad at 1e-9 and 6e-8
at 1e-12 (99 % within 2e-6). GJK may fail instead (coal returns -DBL_MAX: 3 of 131 000 shape
pairs at 1e-12, 21 at 1e-13, over 1000 random LWR4 configurations, mostly the large torso box
against a link 0.3 m away): then the pair is tried again at :data:`FALLBACK_GJK_TOLERANCES`."""
FALLBACK_GJK_TOLERANCES = (1e-11, 1e-10, 1e-9)
"""The tolerances of the next tries when GJK or EPA fails (a non-finite distance or witness point)."""
EPA_TOLERANCE = 1e-6
"""coal's EPA tolerance [m] (its default): the penetration depths' accuracy. Tighter (1e-9), EPA
fails on some cylinder pairs (an infinite distance) instead of converging."""
GJK_MAX_ITERATIONS = 256
"""coal's GJK and EPA iteration limits (coal's defaults: 128 and 64)."""
WITNESS_FEATURE_TOLERANCE = 1e-7
"""A witness point within this [m] of a shape's rim, edge or vertex is on it (GJK's points lie on
the surfaces to about 1e-9 m: a chord of rim points sags by e^2 / 2r)."""
WITNESS_POLISH_LIMIT = 1e-3
"""A refined witness point farther than this [m] from GJK's is not used (:meth:`CollisionModel._polish`)."""
SPHERE_BROADPHASE_MIN = 16
"""Shape pairs left after the known bounds (:meth:`CollisionModel.near`) beyond which their bounding
spheres are checked before coal: below it the spheres' fixed cost (every joint's placement) is more
than the few coal calls they could save (a cylinder pair costs coal about 3 us)."""
KNOWN_MARGIN = 1e-9
"""Subtracted from a computed distance before it is kept as a known lower bound [m] (round-off)."""
_FAILED = 1e6
"""A distance [m] beyond this is coal's failure value (-DBL_MAX or inf), not a distance."""


class CollisionError(DualArmError, RuntimeError):
    """coal could not compute a distance (the message names the shapes)."""


@dataclass(frozen=True)
class CollisionParams:
    """Settings of the velocity damper (module docstring), validated.

    Attributes:
        enabled: whether the damper's rows are added (a switch for the solvers, later).
        influence_distance: d_i [m]: pairs closer than this get a row. Default 0.10 m: an arm
            approaching at 1 m/s (a point 0.5-1 m from a joint turning at 1-2 rad/s) needs 5 cm
            to brake to rest at 10 m/s^2, which fits in d_i - d_s = 7 cm.
        safety_distance: d_s [m]: the distance the damper keeps, >= 0. Default 0.03 m: it
            covers what the model does not see: the LWR4's collision cylinders are 6 mm thinner
            than its visual ones (r 0.054 vs 0.060 m: 12 mm between two arms), pybullet's shapes
            differ from coal's by up to 2 mm (docs/collision.md), one control period
            of motion at 1 m/s (5 mm at T = 5 ms) between two measurements, and the first-order
            prediction d(t + T) ~ d + d_dot T, whose error is O(T^2) (0.1 mm here).
        gain: xi [m/s]: the approach speed allowed at d = d_i (0 at d_s), > 0. Default 0.5 m/s:
            below the 1 m/s a fast arm reaches (so crossing d_i asks for braking, not a stop), and
            the decay rate xi / (d_i - d_s) = 7.1 1/s gives xi T / (d_i - d_s) = 0.036 per period
            at T = 5 ms, far below 1 (the discrete step d_{k+1} - d_s = (1 - xi T / (d_i - d_s))
            (d_k - d_s) stays monotone; it would oscillate above 1 and diverge above 2).
    """

    enabled: bool = True
    influence_distance: float = 0.10
    safety_distance: float = 0.03
    gain: float = 0.5
    allowed: tuple[tuple[str, str], ...] = ()
    """Link pairs never checked besides the robot's own ``collision_allowed`` (resolved URDF names)."""
    shape_margin: float = 0.001
    """m, >= 0: the limit keeps d_s between the shapes grown by this much each (d >= d_s + 2 margin in
    coal's distance of the URDF's shapes): pybullet's collision margin, 1 mm, by which the simulator's
    shapes are larger (its distances are 0.5-2 mm shorter than coal's, docs/collision.md)."""

    def __post_init__(self) -> None:
        if not isinstance(self.enabled, bool):
            raise ParameterError("collision.enabled", self.enabled, "true or false")
        for key in ("influence_distance", "safety_distance", "gain"):
            value = getattr(self, key)
            if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
                raise ParameterError(f"collision.{key}", value, "a finite number")
        if self.safety_distance < 0.0:
            raise ParameterError("collision.safety_distance", self.safety_distance, "a distance >= 0 [m]")
        if self.influence_distance <= self.safety_distance:
            raise ParameterError("collision.influence_distance", self.influence_distance,
                                 f"a distance [m] > collision.safety_distance = {self.safety_distance}")
        if self.gain <= 0.0:
            raise ParameterError("collision.gain", self.gain, "a speed > 0 [m/s]")
        if not (isinstance(self.shape_margin, int | float) and math.isfinite(self.shape_margin)
                and self.shape_margin >= 0.0):
            raise ParameterError("collision.shape_margin", self.shape_margin, "a distance >= 0 [m]")

    @property
    def kept_distances(self) -> tuple[float, float]:
        """(d_i, d_s) in coal's distance of the URDF's shapes [m]: both plus 2 ``shape_margin``."""
        grow = 2.0 * self.shape_margin
        return self.influence_distance + grow, self.safety_distance + grow


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


@dataclass(frozen=True)
class _Body:
    """A link with collision shapes: its joint (0 = the world) and its side ('left', 'right', WORLD)."""

    name: str
    joint: int
    side: str
    geometries: tuple[int, ...]


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

    Attributes:
        pairs: the link pairs checked, (link_a, link_b): left before right, world before an arm.
        pruned: the pairs the broadphase dropped, with their distance lower bound [m].
        geometry_pairs: how many shape pairs the link pairs hold (one link may have several shapes).
    """

    def __init__(self, model: DualArmModel, allowed: Sequence[tuple[str, str]] = (), self_collision: bool = True,
                 margin: float = DEFAULT_MARGIN, gjk_tolerance: float = DEFAULT_GJK_TOLERANCE) -> None:
        if not (math.isfinite(margin) and margin > 0.0):
            raise ValueError(f"margin={margin!r} must be a distance > 0 [m]")
        if not (math.isfinite(gjk_tolerance) and gjk_tolerance > 0.0):
            raise ValueError(f"gjk_tolerance={gjk_tolerance!r} must be > 0 [m]")
        self.kinematics = model
        self.margin = float(margin)
        self.self_collision = self_collision
        self.model, self.geometry = _reduced_geometry(model)
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
        self._joints = np.tile(np.eye(4), (self.model.njoints, 1, 1))  # oMi for the sphere bounds, (joints, 4, 4)
        self.request = _request(gjk_tolerance)
        """The request of every shape pair (absolute tolerance, no warm start: module docstring)."""
        self._fallbacks = [_request(t) for t in FALLBACK_GJK_TOLERANCES if t > gjk_tolerance]
        self.geometry_data = self.geometry.createData()
        """The shapes' placements in the world at the last call that computed a distance (``oMg``,
        ``pin.updateGeometryPlacements``). Its per-pair distance functors are not used: they keep
        GJK's state from call to call (the same q then gives other witness points, measured)."""
        self._results = [coal.DistanceResult() for _ in self.geometry.collisionPairs]
        self._names = [g.name for g in self.geometry.geometryObjects]
        self._index_shape_pairs()
        self._shape_pair_names = [(self._names[a], self._names[b]) for a, b in
                                  zip(self._shape_a.tolist(), self._shape_b.tolist(), strict=True)]
        self._none = NearPairs.empty(self.model.nv)
        self._calls = 0  # placements computed so far (the call of a deferred witness point)
        placed = self.geometry_data.oMg  # references into geometry_data: they follow updateGeometryPlacements
        self._distance_calls = [(self._shapes[a], placed[a], self._shapes[b], placed[b], self._results[k], owner)
                                for k, (a, b, owner) in enumerate(zip(self._shape_a_list, self._shape_b_list,
                                                                      self._shape_pair_owner, strict=True))]
        """Per shape pair, coal.distance's arguments but the request, and its link pair (the loop of :meth:`near`)."""
        self._below = np.zeros(len(self._results), dtype=bool)  # the known bounds' test, preallocated

    # ---- links and pairs -------------------------------------------------------------------

    @classmethod
    def shared(cls, model: DualArmModel, allowed: Sequence[tuple[str, str]] = ()) -> CollisionModel:
        """``model``'s collision model for the ``allowed`` pairs (default settings), built on first use
        and kept on the model (``model.derived``): the controllers, the task sampler and the reports of
        one robot in one process share it instead of building one each (0.05-0.3 s; a sweep builds a
        controller per run). Sharing changes no result: what a collision model carries from call to
        call (the known bounds of :meth:`near`) only decides what is computed, never what it returns."""
        key = (cls, frozenset(frozenset(p) for p in allowed))
        found = model.derived.get(key)
        if not isinstance(found, cls):
            found = cls(model, allowed=allowed)
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
        spheres = [_bounding_sphere(obj.geometry) for obj in objects]
        self._centres = np.array([c for c, _ in spheres])  # in each shape's own frame, (shapes, 3)
        self._centres_joint = (self._place_rotation @ self._centres[:, :, None])[:, :, 0] + self._place_translation
        self._radii = np.array([r for _, r in spheres])
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
            bodies.append(_Body(name, joint, side, tuple(shapes[name])))
        return bodies

    def end_effector(self, link: str) -> list[str]:
        """``link`` itself, or for a tool frame (``left_tool``, ``right_tool``: F1, F2) its end effector:
        from the tool up through fixed joints to the first link with collision shapes (the LWR4's
        flange, Baxter's gripper base) and every link fixed below it (Baxter's locked fingers, the
        tool), as the simulator groups them (``dualarm_sim.cell``). An allowed pair naming a tool
        frame allows the whole end effector (``left_tool right_tool``: the tools meet on purpose)."""
        if link not in TOOL_FRAMES:
            return [link]
        shaped = {b.name for b in self._bodies}
        parent_of, rigid = self._urdf_tree()
        top: str | None = link
        while top is not None and top not in shaped:
            top = parent_of[top] if top in rigid else None  # up through fixed (or locked) joints only
        if top is None:
            return [link]
        group = [top]
        grown = True
        while grown:  # the links hanging from the group by fixed or locked joints, recursively
            below = sorted(child for child in rigid if parent_of.get(child) in group and child not in group)
            group += below
            grown = bool(below)
        return group

    def _urdf_tree(self) -> tuple[dict[str, str], set[str]]:
        """The resolved URDF's tree: each link's parent link, and the links whose joint to it does not
        move in the model (fixed, or an arm's locked joint)."""
        import xml.etree.ElementTree as ET

        moving = set(self.kinematics.joint_names)
        parent_of: dict[str, str] = {}
        rigid: set[str] = set()
        for joint in ET.parse(self.kinematics.urdf).getroot().iter("joint"):
            child, parent = joint.find("child"), joint.find("parent")
            if child is None or parent is None:
                continue
            parent_of[child.get("link", "")] = parent.get("link", "")
            if joint.get("name") not in moving:
                rigid.add(child.get("link", ""))
        return parent_of, rigid

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
        return out

    def _reach(self, body: _Body, start: int) -> float:
        """Radius [m] of a sphere about the origin of joint ``start`` (an ancestor of the body's
        joint, or the body's joint itself) that holds the body's shapes at every configuration:
        the joint offsets from ``start`` to the body's joint (triangle inequality: the joints only
        turn the offsets) plus the shapes' extent from the body's joint origin."""
        extent = max(_farthest(self.geometry.geometryObjects[k]) for k in body.geometries)
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
            return min(_shape_distance(self.geometry.geometryObjects[ka], self.geometry.geometryObjects[kb])
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
        sphere = coal.Sphere(max(self._reach(b, start), 1e-9))
        place = coal.Transform3s(np.eye(3), np.asarray(centre, dtype=float))
        bound = math.inf
        for k in a.geometries:
            obj = self.geometry.geometryObjects[k]
            result = coal.DistanceResult()
            coal.distance(obj.geometry, coal.Transform3s(obj.placement.rotation, obj.placement.translation),
                          sphere, place, coal.DistanceRequest(), result)
            bound = min(bound, float(result.min_distance))
        return bound

    # ---- distances ---------------------------------------------------------------------------

    def distances(self, q: FloatArray, within: float | None = None, polish: bool = False) -> list[PairDistance]:
        """Every pair's distance, witness points, normal and row dd_dq at q (module docstring):
        :meth:`near` as one :class:`PairDistance` per pair, in the order of :attr:`pairs`."""
        return self.near(q, within, polish).pair_distances()

    def near(self, q: FloatArray, within: float | None = None, polish: bool = False, rows: bool = True) -> NearPairs:
        """The pairs' distances, witness points, normals and rows dd_dq at q, as arrays (module docstring).

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
                features (:meth:`_polish`; rows to 1e-6 m/rad instead of 1e-5, at up to 100 us per pair): the
                distances are coal's either way; False (the default) gives GJK's points and normals.
            rows: compute the rows dd_dq now; False defers them and, without ``polish``, the witness
                points and normals too (``NearPairs.rows``, ``points`` and ``normals`` None;
                :meth:`rows`, :meth:`witness` and :meth:`complete` give the same later, from coal's
                arrays, which the returned object keeps).

        Returns:
            the pairs (those within), in the order of :attr:`pairs`.
        """
        q = self.kinematics.check_q(q)
        if not math.isfinite(sum(q.tolist())):  # forget what is known (it would turn NaN); no pair is near
            self._slack.fill(-np.inf)
            self._slack_q = None
            if within is not None:
                return self._none
        else:
            if self._slack_q is not None:  # what is known, moved to q: d(q) >= d(q') - sum_j c_j |q_j - q'_j|
                self._slack -= self._pair_motion @ np.abs(q - self._slack_q)
            self._slack_q = q.copy()
        candidates = self._all_shape_pairs
        if within is not None:  # pairs whose distance may be < within, from what is known (no kinematics)
            candidates = np.less(self._slack, within, out=self._below).nonzero()[0]
            if not candidates.size:
                return self._none
        pin.computeJointJacobians(self.model, self.data, q)  # the joints' placements data.oMi too
        if within is None or candidates.size <= SPHERE_BROADPHASE_MIN:
            active = candidates
        else:
            self._joints = np.array([placement.homogeneous for placement in self.data.oMi])
            spheres = self._sphere_bounds(candidates)
            self._slack[candidates] = spheres
            active = candidates[spheres < within]
        pin.updateGeometryPlacements(self.model, self.data, self.geometry, self.geometry_data)  # oMg = oMi * placement
        self._calls += 1
        request, calls, slack = self.request, self._distance_calls, self._slack
        best: dict[int, tuple[float, int]] = {}  # link pair -> (d, shape pair)
        for k in active.tolist():
            shape_a, placed_a, shape_b, placed_b, res, i = calls[k]
            res.clear()
            d = coal.distance(shape_a, placed_a, shape_b, placed_b, request, res)
            if not -_FAILED < d < _FAILED:  # also NaN
                d = self._retry(k)
            slack[k] = d - KNOWN_MARGIN
            if i not in best or d < best[i][0]:
                best[i] = (d, k)
        # the link pairs within, in the order of self.pairs: active is ascending and each link pair's
        # shape pairs are consecutive (_index_shape_pairs), so best's first insertions are in that order
        pairs, shape_pairs, found = [], [], []
        for i, (d, k) in best.items():
            if within is None or d < within:
                pairs.append(i)
                shape_pairs.append(k)
                found.append(d)
        if not pairs:
            return self._none
        dist = np.array(found)  # coal.distance returns the result's min_distance
        index = np.array(shape_pairs, dtype=np.intp)
        jacobian = self.data.J.copy()
        links = tuple([self.pairs[i] for i in pairs])
        names = tuple([self._shape_pair_names[k] for k in shape_pairs])
        results = self._results
        # coal's witness points and normals as it gives them, (m, 3, 3) (a copy: its arrays are views of
        # the results, which the next call overwrites); checked and normalised now for rows or polish,
        # else when first needed (witness())
        raw = np.array([(res.getNearestPoint1(), res.getNearestPoint2(), res.normal) for res in map(results.__getitem__,
                                                                                                       shape_pairs)])
        if not rows and not polish:
            return NearPairs(tuple(pairs), links, names, dist, None, None, None,
                             self._pair_motion.take(shape_pairs, axis=0), index, jacobian, raw, self._calls)
        points, normals = self._read_witness(raw, shape_pairs, dist, self._calls)
        if polish:
            for r, k in enumerate(shape_pairs):
                points[0, r], points[1, r], normals[r] = self._polish(k, dist[r], points[0, r], points[1, r], normals[r])
        return NearPairs(tuple(pairs), links, names, dist, points, normals,
                         _witness_pair_rows(index, points, normals, jacobian, self._pair_support) if rows else None,
                         self._pair_motion[index], index, jacobian, None, self._calls)

    def _read_witness(self, raw: FloatArray, shape_pairs: Sequence[int], dist: FloatArray,
                      call: int) -> tuple[FloatArray, FloatArray]:
        """The witness points p_a, p_b (2, m, 3) and unit normals (m, 3) from coal's (p_a, p_b, n) of
        ``shape_pairs`` (``raw``, (m, 3, 3), not modified). A finite distance with NaN points (GJK
        failed) is computed again (:meth:`_retry`, into ``dist``) at the placements of the call that
        gave them: CollisionError when ``call`` is not the last one (its placements are gone)."""
        witness = raw.copy()
        points, normals = witness[:, :2].transpose(1, 0, 2), witness[:, 2]  # (2, m, 3) and (m, 3), views
        squares = (normals * normals).sum(axis=1)
        if not math.isfinite(float(points.sum() + squares.sum())):  # a finite distance with NaN points: GJK failed
            bad = ~(np.isfinite(points).all(axis=(0, 2)) & np.isfinite(normals).all(axis=1))
            for r in np.flatnonzero(bad).tolist():
                if call != self._calls:
                    raise CollisionError(f"coal's witness points of {self._shape_pair_names[shape_pairs[r]]} "
                                         "are not finite and the placements they were computed at are gone")
                res = self._results[shape_pairs[r]]
                dist[r] = self._retry(shape_pairs[r])
                points[0, r], points[1, r], normals[r] = res.getNearestPoint1(), res.getNearestPoint2(), res.normal
            squares = (normals * normals).sum(axis=1)
        normals /= np.sqrt(squares)[:, None]  # np.linalg.norm(normals, axis=1), as it computes it
        return points, normals

    def witness(self, near: NearPairs) -> tuple[FloatArray, FloatArray]:
        """The witness points (2, m, 3) [m] and unit normals (m, 3) of ``near``'s pairs: as the call
        kept them or, when it deferred them, made now from coal's arrays it kept (a pair whose GJK
        points are NaN is computed again, its distance in ``near`` kept: CollisionError if another
        :meth:`near` call came between)."""
        if near.points is not None and near.normals is not None:
            return near.points, near.normals
        assert near.raw_witness is not None, "a NearPairs without witness points keeps coal's"
        return self._read_witness(near.raw_witness, near.shape_pairs.tolist(), near.distance.copy(), near.call)

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
        return _witness_pair_rows(near.shape_pairs, points, normals, near.jacobian, self._pair_support)

    def _retry(self, k: int) -> float:
        """Shape pair k again, at the shapes' placements of the call (``geometry_data.oMg``), with the
        fallback requests, tightest first (GJK or EPA failed: coal then returns -DBL_MAX or an infinite
        distance and NaN points); CollisionError if all fail."""
        res = self._results[k]
        ga, gb = int(self._shape_a[k]), int(self._shape_b[k])
        tf_a, tf_b = self.geometry_data.oMg[ga], self.geometry_data.oMg[gb]
        d = math.nan
        for request in self._fallbacks:
            res.clear()
            d = coal.distance(self._shapes[ga], tf_a, self._shapes[gb], tf_b, request, res)
            if -_FAILED < d < _FAILED and all(np.isfinite(x).all() for x in (
                    res.getNearestPoint1(), res.getNearestPoint2(), res.normal)):
                return float(d)
        raise CollisionError(f"coal failed on the shapes {self._names[ga]!r} and {self._names[gb]!r} (distance "
                             f"{d!r}) at GJK tolerances {self.request.gjk_tolerance:g} to "
                             f"{max(FALLBACK_GJK_TOLERANCES + (self.request.gjk_tolerance,)):g}")

    def _polish(self, k: int, d: float, pa: FloatArray, pb: FloatArray,
                n: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Witness points and normal of shape pair k's shapes A and B, at their placements of the call
        (``geometry_data.oMg``), refined on their closest features.

        GJK certifies d (its duality gap, 1e-12 m^2) but not where the witness points lie along the
        surfaces: there d changes only to second order, so each point may be off by about
        sqrt(1e-12 / d * r) (1e-7 m), and the normal n = (p_b - p_a) / d by that over d (1e-5 at
        d = 1 cm): the rows' errors reached 1e-5 m/rad. Here each shape's closest feature is read
        from GJK's point (:func:`_feature`, within :data:`WITNESS_FEATURE_TOLERANCE`): a point, a
        segment or a circle (a sphere's centre, a cylinder's axis, with a radius; a box's vertex or
        edge, a cylinder's rim, a hull's vertex) or a face (a box's or a cap's plane: its normal is
        n). Two non-face features: their closest points (segments in closed form, a circle's angle
        by Newton's method on the squared distance, to 1e-15 m), n along them; a face: n is its
        normal and the other shape's point its support in -n. Then p_b - p_a = d n with coal's d
        (the distances are coal's, unchanged). GJK's points and n are kept for two faces, a hull's
        edge or facet, a segment parallel to a face, or a result more than
        :data:`WITNESS_POLISH_LIMIT` from GJK's.
        """
        ga, gb = self._shape_a_list[k], self._shape_b_list[k]
        placed_a, placed_b = self.geometry_data.oMg[ga], self.geometry_data.oMg[gb]
        fa = _feature(self._shapes[ga], placed_a.rotation, placed_a.translation, pa, self._hull_points[ga])
        fb = _feature(self._shapes[gb], placed_b.rotation, placed_b.translation, pb, self._hull_points[gb])
        if fa is None or fb is None or (fa[0] == "face" and fb[0] == "face"):
            return pa, pb, n
        if fa[0] == "face" or fb[0] == "face":
            if fa[0] == "face":
                new_n = fa[1]
                xb = _support(fb, -new_n)
                if xb is None:
                    return pa, pb, n
                new_b, new_a = xb, xb - d * new_n
            else:
                new_n = -fb[1]
                xa = _support(fa, new_n)
                if xa is None:
                    return pa, pb, n
                new_a, new_b = xa, xa + d * new_n
        else:
            ca, cb = _closest_cores(fa, fb, pa, pb)
            gap = cb - ca
            norm = float(np.linalg.norm(gap))
            if norm < 1e-9:
                return pa, pb, n
            new_n = gap / norm if norm - fa[-1] - fb[-1] > 0.0 else -gap / norm
            mid = 0.5 * (ca + fa[-1] * new_n + cb - fb[-1] * new_n)
            new_a, new_b = mid - 0.5 * d * new_n, mid + 0.5 * d * new_n
        if (max(float(np.max(np.abs(new_a - pa))), float(np.max(np.abs(new_b - pb)))) > WITNESS_POLISH_LIMIT
                or float(np.max(np.abs(new_n - n))) > 0.01):
            return pa, pb, n
        return new_a, new_b, new_n

    def shape_placement(self, index: int) -> pin.SE3:
        """Shape ``index``'s placement in the world at the last :meth:`distances` call that computed a
        distance (pinocchio's ``oMg``: oMi * the shape's placement in its joint's frame)."""
        return pin.SE3(self.geometry_data.oMg[index])

    def _sphere_bounds(self, shape_pairs: npt.NDArray[np.intp]) -> FloatArray:
        """Lower bounds [m] of the distance of ``shape_pairs`` at the last call's joint placements,
        (k,): ||c_a - c_b|| - r_a - r_b with c, r each shape's bounding sphere (centre in the world,
        from its centre in its joint's frame)."""
        joints = self._joints[self._shape_joint]
        centres = (joints[:, :3, :3] @ self._centres_joint[:, :, None])[:, :, 0] + joints[:, :3, 3]
        a, b = self._shape_a[shape_pairs], self._shape_b[shape_pairs]
        return np.linalg.norm(centres[a] - centres[b], axis=1) - self._radii[a] - self._radii[b]

    def closest(self, q: FloatArray) -> PairDistance:
        """The pair with the smallest distance at q (ValueError when the model has no pair)."""
        if not self.pairs:
            raise ValueError("the collision model has no pair")
        return min(self.distances(q), key=lambda p: p.distance)


def _witness_pair_rows(shape_pairs: npt.NDArray[np.intp], points: FloatArray, normals: FloatArray,
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
    request = _request(DEFAULT_GJK_TOLERANCE)
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


def velocity_damper(dd_dq: FloatArray, distance: FloatArray, influence: float, safety: float,
                    gain: float) -> tuple[FloatArray, FloatArray]:
    """The velocity damper's rows A qd <= b of m pairs, all closer than ``influence`` (module docstring):

        -dd_dq qd <= xi (d - d_s) / (d_i - d_s)

    Args:
        dd_dq: the pairs' rows [m/rad], (m, n). distance: their d [m], (m,).
        influence: d_i [m]. safety: d_s [m], 0 <= d_s < d_i. gain: xi [m/s], > 0.

    Returns:
        A = -dd_dq [m/rad], (m, n), and b [m/s], (m,).
    """
    if dd_dq.ndim != 2 or distance.shape != (dd_dq.shape[0],):
        raise DimensionError(f"velocity_damper: rows {dd_dq.shape} and distances {distance.shape} do not match")
    return -dd_dq, velocity_damper_bound(distance, influence, safety, gain)


def velocity_damper_bound(distance: FloatArray, influence: float, safety: float, gain: float) -> FloatArray:
    """b = xi (d - d_s) / (d_i - d_s) [m/s], (m,), of :func:`velocity_damper`'s rows, for m distances d [m]."""
    if not (0.0 <= safety < influence and gain > 0.0 and math.isfinite(influence + gain)):
        CollisionParams(influence_distance=influence, safety_distance=safety, gain=gain)  # raises, naming the key
    span = influence - safety  # the pairs one by one: m is small, and each b is the same IEEE operations
    return np.array([gain * (d - safety) / span for d in distance.tolist()], dtype=float)


def velocity_damper_rows(distances: Sequence[PairDistance], influence: float, safety: float,
                         gain: float) -> tuple[FloatArray, FloatArray]:
    """:func:`velocity_damper` of the pairs of ``distances`` closer than ``influence`` (any subset of
    :meth:`CollisionModel.distances`), in their order; (0, n) and (0,) when none (n = 0 when
    ``distances`` is empty too)."""
    near = [p for p in distances if p.distance < influence]
    n = distances[0].dd_dq.shape[0] if distances else 0
    if any(p.dd_dq.shape != (n,) for p in near):
        raise DimensionError(f"velocity_damper_rows: rows of different lengths {sorted({p.dd_dq.shape for p in near})}")
    rows = np.stack([p.dd_dq for p in near]) if near else np.zeros((0, n))
    return velocity_damper(rows, np.array([p.distance for p in near]), influence, safety, gain)


Feature = tuple  # ("point", P, rad) | ("segment", P, Q, rad) | ("circle", C, u, v, r, theta, 0.0) | ("face", N)


def _feature(shape: coal.CollisionGeometry, rotation: FloatArray, translation: FloatArray, point: FloatArray,
             hull: FloatArray | None) -> Feature | None:
    """The feature of a shape that holds its witness point (world): ("point", P, radius), ("segment",
    P, Q, radius), ("circle", centre, u, v, r, angle of the point, 0.0) or ("face", outward normal);
    None for another shape or feature (a hull's edge or facet). On a feature: within
    :data:`WITNESS_FEATURE_TOLERANCE`."""
    tol = WITNESS_FEATURE_TOLERANCE
    x = rotation.T @ (point - translation)
    if isinstance(shape, coal.Sphere):
        return ("point", translation.copy(), float(shape.radius))
    if isinstance(shape, coal.Cylinder):
        r, h = float(shape.radius), float(shape.halfLength)
        side = abs(math.hypot(x[0], x[1]) - r) <= tol
        cap = abs(abs(x[2]) - h) <= tol
        z = math.copysign(h, x[2])
        if side and cap:
            return ("circle", rotation[:, 2] * z + translation, rotation[:, 0], rotation[:, 1], r,
                    math.atan2(x[1], x[0]), 0.0)
        if side:
            return ("segment", translation - h * rotation[:, 2], translation + h * rotation[:, 2], r)
        if cap:
            return ("face", math.copysign(1.0, x[2]) * rotation[:, 2])
        return None
    if isinstance(shape, coal.Box):
        half = np.asarray(shape.halfSide)
        on = np.abs(np.abs(x) - half) <= tol
        corner = np.where(x < 0.0, -half, half)
        count = int(on.sum())
        if count == 3:
            return ("point", rotation @ corner + translation, 0.0)
        if count == 2:
            free = int(np.flatnonzero(~on)[0])
            end_a, end_b = corner.copy(), corner.copy()
            end_a[free], end_b[free] = -half[free], half[free]
            return ("segment", rotation @ end_a + translation, rotation @ end_b + translation, 0.0)
        if count == 1:
            axis = int(np.flatnonzero(on)[0])
            return ("face", rotation[:, axis] * math.copysign(1.0, x[axis]))
        return None
    if hull is not None:
        k = int(np.argmin(np.sum((hull - x) ** 2, axis=1)))
        if float(np.linalg.norm(hull[k] - x)) <= tol:
            return ("point", rotation @ hull[k] + translation, 0.0)
    return None


def _support(f: Feature, direction: FloatArray) -> FloatArray | None:
    """The point of a (non-face) feature farthest along ``direction`` (unit), None when not unique
    (a segment nearly perpendicular to it)."""
    kind = f[0]
    if kind == "point":
        return f[1] + f[2] * direction
    if kind == "segment":
        p, q, rad = f[1], f[2], f[3]
        along = float((q - p) @ direction)
        if abs(along) < 1e-9:
            return None
        return (q if along > 0.0 else p) + rad * direction
    _, centre, u, v, r, _, _ = f
    a, b = float(u @ direction), float(v @ direction)
    norm = math.hypot(a, b)
    if norm < 1e-9:
        return None
    return centre + r * (a * u + b * v) / norm


def _circle_point(f: Feature, theta: float) -> FloatArray:
    return f[1] + f[4] * (math.cos(theta) * f[2] + math.sin(theta) * f[3])


def _closest_static(a: Feature, b: Feature) -> tuple[FloatArray, FloatArray]:
    """Closest points of two points or segments (a point is a segment of length 0)."""
    p1, q1 = (a[1], a[1]) if a[0] == "point" else (a[1], a[2])
    p2, q2 = (b[1], b[1]) if b[0] == "point" else (b[1], b[2])
    return _segment_closest(p1, q1, p2, q2)


def _closest_cores(a: Feature, b: Feature, pa: FloatArray, pb: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Closest points of two features' cores (points, segments, circles: the radii aside), from the
    witness points' angles on circles by Newton's method on the squared distance (central
    differences of step 1e-4 rad, at most 8 steps, until the step is below 1e-13 rad)."""
    circles = [f for f in (a, b) if f[0] == "circle"]
    if not circles:
        return _closest_static(a, b)

    def points(angles: list[float]) -> tuple[FloatArray, FloatArray]:
        k = 0
        fixed = []
        for f in (a, b):
            if f[0] == "circle":
                fixed.append(("point", _circle_point(f, angles[k]), 0.0))
                k += 1
            else:
                fixed.append(f)
        return _closest_static(fixed[0], fixed[1])

    def value(angles: list[float]) -> float:
        x, y = points(angles)
        return float((y - x) @ (y - x))

    angles = [float(f[5]) for f in circles]
    step = 1e-4
    for _ in range(8):
        m = len(angles)
        f0 = value(angles)
        grad = np.zeros(m)
        hess = np.zeros((m, m))
        for i in range(m):
            e = [step if j == i else 0.0 for j in range(m)]
            fp = value([t + s for t, s in zip(angles, e, strict=True)])
            fm = value([t - s for t, s in zip(angles, e, strict=True)])
            grad[i] = (fp - fm) / (2 * step)
            hess[i, i] = (fp - 2 * f0 + fm) / step ** 2
        if m == 2:
            fpp = value([angles[0] + step, angles[1] + step])
            fmm = value([angles[0] - step, angles[1] - step])
            hess[0, 1] = hess[1, 0] = ((fpp + fmm - 2 * f0) / step ** 2 - hess[0, 0] - hess[1, 1]) / 2
        try:
            delta = -np.linalg.solve(hess, grad)
        except np.linalg.LinAlgError:
            break
        if not np.all(np.isfinite(delta)) or float(np.max(np.abs(delta))) > 0.1:
            break
        angles = [t + float(s) for t, s in zip(angles, delta, strict=True)]
        if float(np.max(np.abs(delta))) < 1e-13:
            break
    return points(angles)


def _segment_closest(p1: FloatArray, q1: FloatArray, p2: FloatArray, q2: FloatArray) -> tuple[FloatArray, FloatArray]:
    """The closest points of the segments [p1, q1] and [p2, q2], either possibly a point (Ericson,
    Real-Time Collision Detection, 5.1.9; parallel segments: the first segment's start)."""
    d1, d2, r = q1 - p1, q2 - p2, p1 - p2
    a, e, f = float(d1 @ d1), float(d2 @ d2), float(d2 @ r)
    if a <= 1e-24 and e <= 1e-24:
        return p1, p2
    if a <= 1e-24:
        return p1, p2 + min(max(f / e, 0.0), 1.0) * d2
    c = float(d1 @ r)
    if e <= 1e-24:
        return p1 + min(max(-c / a, 0.0), 1.0) * d1, p2
    b = float(d1 @ d2)
    denom = a * e - b * b
    s = min(max((b * f - c * e) / denom, 0.0), 1.0) if denom > 1e-14 * a * e else 0.0
    t = (b * s + f) / e
    if t < 0.0:
        t, s = 0.0, min(max(-c / a, 0.0), 1.0)
    elif t > 1.0:
        t, s = 1.0, min(max((b - c) / a, 0.0), 1.0)
    return p1 + s * d1, p2 + t * d2


def _shape_distance(a: pin.GeometryObject, b: pin.GeometryObject) -> float:
    """The distance [m] of two shapes placed in one frame (their ``placement``s)."""
    result = coal.DistanceResult()
    return float(coal.distance(a.geometry, coal.Transform3s(a.placement.rotation, a.placement.translation),
                               b.geometry, coal.Transform3s(b.placement.rotation, b.placement.translation),
                               coal.DistanceRequest(), result))


def _request(gjk_tolerance: float) -> coal.DistanceRequest:
    """A coal distance request: signed distances and witness points, the duality-gap criterion on
    an absolute tolerance, no warm start, 256 iterations for GJK and EPA."""
    request = coal.DistanceRequest()
    request.gjk_tolerance = gjk_tolerance
    request.epa_tolerance = EPA_TOLERANCE
    request.gjk_convergence_criterion = coal.GJKConvergenceCriterion.DualityGap
    request.gjk_convergence_criterion_type = coal.GJKConvergenceCriterionType.Absolute
    request.gjk_initial_guess = coal.GJKInitialGuess.DefaultGuess
    request.gjk_max_iterations = GJK_MAX_ITERATIONS
    request.epa_max_iterations = GJK_MAX_ITERATIONS
    request.enable_signed_distance = True
    return request


def _farthest(obj: pin.GeometryObject) -> float:
    """max ||x|| [m] over the points x of a shape, in its parent joint's frame."""
    return _farthest_from(obj.geometry, obj.placement.actInv(np.zeros(3)))


def _farthest_from(shape: coal.CollisionGeometry, origin: FloatArray) -> float:
    """max ||x - origin|| [m] over the points x of a shape, all in the shape's frame (exact for
    spheres, capsules, cylinders, boxes and convex hulls; a bounding sphere of the local AABB
    otherwise)."""
    origin = np.asarray(origin, dtype=float)
    if isinstance(shape, coal.Sphere):
        return float(np.linalg.norm(origin)) + float(shape.radius)
    if isinstance(shape, coal.Capsule):
        h = float(shape.halfLength)
        return max(float(np.linalg.norm(origin - [0.0, 0.0, z])) for z in (-h, h)) + float(shape.radius)
    if isinstance(shape, coal.Cylinder):  # the farthest point lies on a rim circle
        h, radial = float(shape.halfLength), float(np.hypot(origin[0], origin[1]))
        return max(math.hypot(radial + float(shape.radius), z - float(origin[2])) for z in (-h, h))
    if isinstance(shape, coal.Box):
        corners = np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).reshape(3, -1).T * np.asarray(shape.halfSide)
        return float(np.max(np.linalg.norm(corners - origin, axis=1)))
    if isinstance(shape, coal.ConvexBase):
        return float(np.max(np.linalg.norm(np.asarray(shape.points()) - origin, axis=1)))
    shape.computeLocalAABB()
    return float(np.linalg.norm(np.asarray(shape.aabb_center) - origin)) + float(shape.aabb_radius)


def _bounding_sphere(shape: coal.CollisionGeometry) -> tuple[FloatArray, float]:
    """A sphere holding a shape: the centre of its local AABB (shape frame) [m], (3,), and the
    farthest point's distance from it [m]."""
    shape.computeLocalAABB()
    centre = np.array(shape.aabb_center, dtype=float)
    return centre, _farthest_from(shape, centre)


def _reduced_geometry(model: DualArmModel) -> tuple[pin.Model, pin.GeometryModel]:
    """The collision geometry of ``model``'s robot, reduced to its arms' joints like its model.

    Meshes become their convex hulls. RobotError if the reduced model differs from ``model.model``
    (joint names, nq, joint placements).
    """
    robot = model.description
    urdf = str(model.urdf)
    full = pin.buildModelFromUrdf(urdf)
    geometry = pin.buildGeomFromUrdf(full, urdf, pin.GeometryType.COLLISION)
    for obj in geometry.geometryObjects:
        shape = obj.geometry
        if isinstance(shape, coal.BVHModelBase):
            shape.buildConvexHull(True, "Qt")
            obj.geometry = shape.convex
    locked = robot.locked_positions()
    if locked:
        q_ref = pin.neutral(full)
        for name, value in locked.items():
            joint = full.getJointId(name)
            q_ref[full.idx_qs[joint]] = value
        reduced, geometry = pin.buildReducedModel(full, geometry, [full.getJointId(n) for n in locked], q_ref)
    else:
        reduced = full
    names = [reduced.names[i] for i in range(1, reduced.njoints)]
    same = reduced.nq == model.model.nq and names == model.joint_names and all(
        reduced.jointPlacements[i].isApprox(model.model.jointPlacements[i], 1e-12) for i in range(reduced.njoints))
    if not same:
        raise RobotError(f"robot {robot.name!r}: the collision model's joints {names} (nq {reduced.nq}) differ "
                         f"from the kinematic model's {model.joint_names} (nq {model.model.nq})")
    return reduced, geometry
