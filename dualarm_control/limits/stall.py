"""A brake at a stall: the joint acceleration bound while a row limit holds the command (docs/collision.md,
"At a stall").

At a stall the task pulls with K e against an active velocity-damper row whose normal turns with q, and the
QP's minimiser jumps from one side of the row to the other from one cycle to the next: a period-2 limit cycle
(measured without a joint acceleration bound: collision_demo 139-260 rad/s^2 between two cycles, busy_cell's
two tools pressed on one plate 930-1285 rad/s^2). A row limit (collision, live obstacles) with a
:class:`StallBrake` adds, from the cycle after one of its rows held the command (A qd >= b - 1e-6 m/s: the
report's ``active``) until :data:`HOLD_S` has passed without one, the box of the joint acceleration bound
(:func:`~dualarm_control.limits.acceleration.acceleration_box`):

    qd_{k-1} - a T <= qd_k <= qd_{k-1} + a T,   capped by the stopping speeds toward the position limits,

a = ``collision.stall_acceleration`` [rad/s^2] (0: no brake), T the control period [s]. It is narrowed after
eq (23) and the controller's own acceleration bound (the row limits' priority). A run whose rows never hold
the command (the assembly: Table I) is not changed by a bit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dualarm_control.limits.acceleration import acceleration_box
from dualarm_control.limits.base import Constraint, FloatArray, JointLimits, Limit
from dualarm_control.limits.registry import LimitContext

HOLD_S = 0.1
"""s: how long the brake holds after the last cycle with an active row (a stall's rows can let go for a cycle
or two while the limit cycle dies out)."""


@dataclass(slots=True)
class StallBrake:
    """The acceleration box a row limit adds while its rows hold the command (module docstring).

    Attributes:
        limits: the joint limits (the stopping speeds). acceleration: a [rad/s^2], (n,), > 0.
        period: T [s]. hold: cycles the brake holds after the last active row (>= 1).
        left: cycles it still holds (0: released).
    """

    limits: JointLimits
    acceleration: FloatArray
    period: float
    hold: int
    left: int = 0

    @classmethod
    def of(cls, context: LimitContext) -> StallBrake | None:
        """The brake of a controller's row limits: ``collision.stall_acceleration`` on every joint; None when 0."""
        value = float(context.params.collision.stall_acceleration)
        if value <= 0.0:
            return None
        return cls(context.joint_limits, np.full(context.model.nq, value), context.period,
                   max(1, math.ceil(HOLD_S / context.period - 1e-9)))

    def box(self, q: FloatArray, previous: FloatArray) -> tuple[FloatArray, FloatArray] | None:
        """This cycle's box (lower, upper) [rad/s], (n,) each, at q [rad] after the command ``previous``
        [rad/s]; None while released. Counts the cycle."""
        if self.left <= 0:
            return None
        self.left -= 1
        return acceleration_box(q, self.limits, previous, self.acceleration, self.period)

    def narrow(self, constraint: Constraint, q: FloatArray, previous: FloatArray) -> Constraint:
        """``constraint`` (a row limit's, once per cycle) with this cycle's box (:meth:`box`) while the brake
        holds; ``constraint`` itself while released."""
        box = self.box(q, previous)
        return constraint if box is None else Constraint(*box, constraint.rows, constraint.labels)

    def saw(self, active: int) -> None:
        """The row limit's count of active rows in the cycle just ended: any holds the brake for ``hold`` cycles."""
        if active:
            self.left = self.hold

    def reset(self) -> None:
        """Released (a new run)."""
        self.left = 0


class BrakedLimit(Limit):
    """A row limit with a :class:`StallBrake` (``brake``; None: none): released for a new run, and holding
    on across a live parameter change as it held before (a change during a stall keeps the stall braked)."""

    brake: StallBrake | None = None

    def reset(self) -> None:
        if self.brake is not None:
            self.brake.reset()

    def continue_from(self, old: Limit) -> None:
        brake = getattr(old, "brake", None)
        if self.brake is not None and isinstance(brake, StallBrake):
            self.brake.left = min(brake.left, self.brake.hold)
