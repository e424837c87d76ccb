"""The collision package's settings: its constants (tolerances, margins), :class:`CollisionParams`
(the velocity damper's settings, validated), :class:`CollisionError`, and the coal request every
distance is computed with (:func:`distance_request`)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import coal
import numpy as np

from dualarm_control.errors import DualArmError, ParameterError
from dualarm_control.obstacles import Obstacle

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
"""A refined witness point farther than this [m] from GJK's is not used
(:func:`~dualarm_control.collision.features.polish_witness`)."""
SPHERE_BROADPHASE_MIN = 16
"""Shape pairs left after the known bounds (:meth:`~dualarm_control.collision.CollisionModel.near`)
beyond which their bounding spheres are checked before coal: below it the spheres' fixed cost (every
joint's placement) is more than the few coal calls they could save (a cylinder pair costs coal about
3 us)."""
KNOWN_MARGIN = 1e-9
"""Subtracted from a computed distance before it is kept as a known lower bound [m] (round-off)."""
MAX_LIVE_OBSTACLES = 256
"""The most live obstacle slots (``collision.live_obstacles``): each may add a coal call per arm link
and cycle when near."""
_FAILED = 1e6
"""A distance [m] beyond this is coal's failure value (-DBL_MAX or inf), not a distance."""


class CollisionError(DualArmError, RuntimeError):
    """coal could not compute a distance (the message names the shapes)."""


@dataclass(frozen=True)
class CollisionParams:
    """Settings of the velocity damper (:mod:`dualarm_control.collision.damper`), validated.

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
    obstacles: tuple[Obstacle, ...] = ()
    """The scenario's static obstacles (``scenario.obstacles``, :mod:`dualarm_control.obstacles`): world
    shapes the collision model checks against every arm link (docs/obstacles.md)."""
    live_obstacles: int = 0
    """The most live obstacles at once (markers on a topic, a point cloud, a moving hand; slots, >= 0;
    0: no live obstacle limit): :mod:`dualarm_control.limits.live`."""
    stall_acceleration: float = 10.0
    """rad/s^2, >= 0: the joint acceleration bound the row limits add while their rows hold the command and
    0.1 s after (:mod:`dualarm_control.limits.stall`: the period-2 limit cycle at a stall); 0: none. Default:
    the documented acceleration bound (``config/acceleration_limit.yaml``)."""

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
        if isinstance(self.stall_acceleration, bool) or not isinstance(self.stall_acceleration, int | float) \
                or not math.isfinite(self.stall_acceleration) or self.stall_acceleration < 0.0:
            raise ParameterError("collision.stall_acceleration", self.stall_acceleration,
                                 "an acceleration >= 0 [rad/s^2] (0: no brake at a stall)")
        if isinstance(self.live_obstacles, bool) or not isinstance(self.live_obstacles, int) \
                or not 0 <= self.live_obstacles <= MAX_LIVE_OBSTACLES:
            raise ParameterError("collision.live_obstacles", self.live_obstacles,
                                 f"an integer from 0 to {MAX_LIVE_OBSTACLES}")

    @property
    def kept_distances(self) -> tuple[float, float]:
        """(d_i, d_s) in coal's distance of the URDF's shapes [m]: both plus 2 ``shape_margin``."""
        grow = 2.0 * self.shape_margin
        return self.influence_distance + grow, self.safety_distance + grow


def distance_request(gjk_tolerance: float) -> coal.DistanceRequest:
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


def _oblique() -> np.ndarray:
    """Rz(0.7) Ry(0.5) Rx(0.3): a rotation with no zero entry (no axis turns into a direction with a zero component)."""
    (cx, sx), (cy, sy), (cz, sz) = ((math.cos(a), math.sin(a)) for a in (0.3, 0.5, 0.7))
    return np.array([[cz * cy, cz * sy * sx - sz * cx, cz * sy * cx + sz * sx],
                     [sz * cy, sz * sy * sx + cz * cx, sz * sy * cx - cz * sx],
                     [-sy, cy * sx, cy * cx]])


def settle_box_support() -> bool:
    """Make coal's box support exact in this process, once: whether it is.

    coal 3.0's support function of a box (``getShapeSupport(const Box*, ...)``) keeps its inflation of the
    box's negative sides in a function-local ``static const``, set by the process's first box support query:
    1 + 1e-10 when that query's direction had a zero component (GJK's first direction is its default guess
    (1, 0, 0), so any query with a box as the first shape), else 1. Every later box distance in the process
    then depends on which query came first: the same tool box and link gave 0.10179354994222353 m in one
    process and 0.10179354994207389 m in another (1.5e-13 m), and a stall amplified that to 0.05 rad/s
    (docs/collision.md, "At a stall"). One query with the box second at an oblique rotation sets it to 1 (the
    exact box); this module makes it when it is imported, before any distance of this package. A process that
    queried a box through coal before (its own code, pinocchio's collision functions) keeps what that query
    set: False then (:func:`box_support_exact`)."""
    coal.distance(coal.Cylinder(0.1, 0.2), coal.Transform3s(), coal.Box(1.0, 1.0, 1.0),
                  coal.Transform3s(_oblique(), np.array([1.3, 1.1, 0.9])), distance_request(DEFAULT_GJK_TOLERANCE),
                  coal.DistanceResult())
    return box_support_exact()


def box_support_exact() -> bool:
    """Whether coal's box support is exact in this process (:func:`settle_box_support`): a unit box and a
    cylinder 2 m from its centre along -x are 1.4 m apart, 1.39999999994 m with the box inflated (and the
    cylinder's own inflation, 1e-11 m, either way)."""
    d = coal.distance(coal.Box(1.0, 1.0, 1.0), coal.Transform3s(), coal.Cylinder(0.1, 0.2),
                      coal.Transform3s(np.eye(3), np.array([-2.0, 0.0, 0.0])), distance_request(DEFAULT_GJK_TOLERANCE),
                      coal.DistanceResult())
    return bool(d > 1.4 - 3e-11)


settle_box_support()
