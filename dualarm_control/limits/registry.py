"""The limits' registry: a limit is built by name from the controller's parameters (docs/limits.md).

A controller's limits are the default ones (:data:`DEFAULT_LIMITS`, each built when its parameters turn it
on) and those its ``limits`` parameter names: registered by the package or by a user's own file loaded
through the ``plugins`` parameter (:mod:`dualarm_control.plugins`). Registering is one line::

    @register_limit("keep_out")
    def keep_out(context: LimitContext) -> Limit | None: ...
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from dualarm_control.errors import ParameterError
from dualarm_control.limits.base import FloatArray, JointLimits, Limit
from dualarm_control.registry import Registry

if TYPE_CHECKING:
    from dualarm_control.collision import CollisionModel
    from dualarm_control.kinematics import DualArmModel


@dataclass(frozen=True)
class LimitContext:
    """What a limit's factory may read to build the limit for one controller.

    Attributes:
        model: the robot (joint order, frames, ``nq``).
        joint_limits: its joint limits with the controller's velocity scale applied.
        period: the control period T [s].
        acceleration: a_max [rad/s^2], (n,), or None (no ``acceleration_limit``).
        collision: the controller's collision model, or None (``collision.enabled`` false).
        params: the controller's :class:`~dualarm_control.controller.ControllerParams`.
    """

    model: DualArmModel
    joint_limits: JointLimits
    period: float
    acceleration: FloatArray | None
    collision: CollisionModel | None
    params: Any


LimitFactory = Callable[[LimitContext], "Limit | None"]
"""Builds a limit from a context; None: the parameters leave it off."""

LIMITS: Registry[LimitFactory] = Registry("limit", lambda name, known: ParameterError(
    "limits", name, "a registered limit: " + ", ".join(known)))

DEFAULT_LIMITS = ("joint_velocity", "joint_acceleration", "collision", "live_obstacles")
"""The limits every controller has when their parameters turn them on (the joint limits always)."""


def register_limit(name: str) -> Callable[[LimitFactory], LimitFactory]:
    """Decorator registering a limit factory under ``name`` (ValueError if the name is taken)."""

    return LIMITS.decorator(name)


def limit_names() -> list[str]:
    """Every registered limit name, sorted."""
    return LIMITS.names()


def make_limits(names: tuple[str, ...], context: LimitContext, key: str = "limits") -> list[Limit]:
    """The limits named (those a factory leaves off omitted); ParameterError naming ``key``, the unknown
    name and the registered ones."""
    out = []
    for name in names:
        if name not in LIMITS:
            raise ParameterError(key, name, "a registered limit: " + ", ".join(limit_names()))
        limit = LIMITS.get(name)(context)
        if limit is not None:
            out.append(limit)
    return out
