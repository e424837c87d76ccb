"""The controller's ROS parameter schema: :data:`CONTROLLER_PARAMETERS` and :func:`controller_params`.

One list of :class:`~dualarm_control.params.ParamSpec` (name, default, description, check) is the
only source of validation of the controller's parameters, whether they come from a file, from
``-p`` or from the controller node; :func:`controller_params` turns the values into
:class:`~dualarm_control.controller.ControllerParams`.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from dualarm_control.collision import CollisionParams
from dualarm_control.controller import (
    DEFAULT_ACCELERATION_LIMIT,
    ControllerParams,
    acceleration_limit_problem,
)
from dualarm_control.errors import ParameterError
from dualarm_control.params import (
    ParamSpec,
    link_pairs,
    non_negative,
    open_unit_interval,
    positive,
    resolve,
    unit_interval,
)
from dualarm_control.qp import DEFAULT_BACKEND, DEFAULT_MAX_ITER, QPSettings
from dualarm_control.solvers import SolverParams


def _solver_choices() -> list[str]:
    from dualarm_control.solvers import solver_names

    return solver_names()


def _backend_check(value: Any) -> str:
    """daqp, proxsuite or a qpsolvers solver installed here (dualarm_control.qp.available_backends)"""
    from dualarm_control.qp import available_backends, is_backend

    return "" if is_backend(value) else "one of: " + ", ".join(available_backends())


def _acceleration_check(value: Any) -> str:
    """[0.0] means no bound; otherwise every value must be > 0."""
    return "" if value == [0.0] else acceleration_limit_problem(value)


def _allowed(value: Any) -> tuple[tuple[str, str], ...]:
    """``collision.allowed`` as link pairs (validated by :func:`_pairs_check`)."""
    return link_pairs(value, "collision.allowed")


def _pairs_check(value: Any) -> str:
    """[''] or 'link_a link_b' strings"""
    try:
        link_pairs(value, "collision.allowed")
    except ParameterError as exc:
        return exc.expected
    return ""


def _names_check(value: Any) -> str:
    """a list of strings ([''] = none)"""
    return "" if isinstance(value, list) and all(isinstance(v, str) for v in value) else "a list of strings"


def _names(value: list[str]) -> tuple[str, ...]:
    """A string-array parameter's entries, ROS's [''] for none skipped."""
    return tuple(v for v in value if v)


CONTROLLER_PARAMETERS: tuple[ParamSpec, ...] = (
    ParamSpec("solver", "hierarchical_sparse_qp", "kinematic solver (registry name)", choices=_solver_choices),
    ParamSpec("gain", 10.0, "closed-loop gain K of eq (13) [1/s]", check=positive),
    ParamSpec("control_period", 0.005, "control period T [s] (200 Hz)", check=positive, read_only=True),
    ParamSpec("alpha", 0.1, "repulsive activation share alpha of eq (24)", check=unit_interval,
              bounds=(0.0, 1.0)),
    ParamSpec("velocity_scale", 1.0, "factor on the nominal joint velocity limits", check=open_unit_interval),
    ParamSpec("l1_weight", 1e-6, "lambda of eq (17)/(26)", check=positive),
    ParamSpec("regularization", 1e-6, "standard QP minimum-norm tie-break eps", check=non_negative),
    ParamSpec("proximal_weight", 1e-6, "sparse QPs' proximal term mu around the previous solution (0 = exact lasso)",
              check=non_negative),
    ParamSpec("secondary_l1_weight", 0.1, "hierarchical_sparse_l1_qp: price lambda_2 [rad/s] of moving a joint "
              "outside the repulsive zone (docs/hierarchy.md)", check=positive),
    ParamSpec("acceleration_limit", [0.0],
              "joint acceleration bound [rad/s^2]: [0.0] = none, one value for all joints or one per joint "
              f"(documented choice: [{DEFAULT_ACCELERATION_LIMIT}])", check=_acceleration_check),
    ParamSpec("qp_backend", DEFAULT_BACKEND, "QP back-end", check=_backend_check),
    ParamSpec("collision.enabled", True, "collision limit on (velocity damper rows, hard in every solver)"),
    ParamSpec("collision.influence_distance", 0.10, "collision limit: influence distance d_i [m] (> safety_distance)",
              check=positive),
    ParamSpec("collision.safety_distance", 0.03, "collision limit: safety distance d_s [m] kept between links",
              check=non_negative),
    ParamSpec("collision.gain", 0.5, "collision limit: approach speed xi [m/s] allowed at d_i", check=positive),
    ParamSpec("collision.shape_margin", 0.001, "collision limit: the shapes grown by this [m] each (pybullet's "
              "collision margin): d_s is kept between them", check=non_negative),
    ParamSpec("collision.stall_acceleration", 10.0, "collision limit: joint acceleration bound [rad/s^2] while a "
              "collision or obstacle row holds the command and 0.1 s after (0 = none; docs/collision.md)",
              check=non_negative),
    ParamSpec("collision.live_obstacles", 0, "collision limit: the most live obstacles at once (markers on "
              "/collision_objects, a point cloud, a moving hand; 0 = none; docs/obstacles.md)", check=non_negative,
              read_only=True),
    ParamSpec("collision.allowed", [""], "link pairs never checked besides the robot's collision_allowed: "
              "'link_a link_b' strings ([''] = none)", check=_pairs_check, read_only=True),
    ParamSpec("limits", [""], "registered limits added to the default ones, by name ([''] = none; docs/limits.md)",
              check=_names_check, read_only=True),
    ParamSpec("plugins", [""], "Python files or module names imported first: a user's own limits and tasks "
              "register there ([''] = none; docs/limits.md)", check=_names_check, read_only=True),
    ParamSpec("qp_eps_abs", 1e-9, "QP absolute tolerance", check=positive),
    ParamSpec("qp_max_iter", DEFAULT_MAX_ITER, "QP iteration cap (a solve that reaches it falls back)", check=positive),
)


def controller_params(values: Mapping[str, Any], node: str = "controller_node") -> ControllerParams:
    """Build validated ControllerParams from raw parameter values (file, ``-p``, or node)."""
    v = resolve(CONTROLLER_PARAMETERS, values, node)
    return ControllerParams(
        solver=v["solver"],
        gain=v["gain"],
        period=v["control_period"],
        alpha=v["alpha"],
        velocity_scale=v["velocity_scale"],
        acceleration_limit=() if v["acceleration_limit"] == [0.0] else tuple(v["acceleration_limit"]),
        solver_params=SolverParams(
            l1_weight=v["l1_weight"],
            regularization=v["regularization"],
            proximal_weight=v["proximal_weight"],
            secondary_l1_weight=v["secondary_l1_weight"],
            qp_backend=v["qp_backend"],
            qp=QPSettings(eps_abs=v["qp_eps_abs"], max_iter=v["qp_max_iter"]),
        ),
        collision=CollisionParams(
            enabled=v["collision.enabled"], influence_distance=v["collision.influence_distance"],
            safety_distance=v["collision.safety_distance"], gain=v["collision.gain"],
            shape_margin=v["collision.shape_margin"], live_obstacles=v["collision.live_obstacles"],
            stall_acceleration=v["collision.stall_acceleration"], allowed=_allowed(v["collision.allowed"])),
        limits=_names(v["limits"]),
        plugins=_names(v["plugins"]),
    )
