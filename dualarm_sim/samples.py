"""What a simulated cell gives back: the joint state read from the physics after a step
(:class:`JointSample`) and the outcome of a velocity command (:class:`CommandReport`)."""

from __future__ import annotations

from dataclasses import dataclass

from dualarm_control.arrays import FloatArray


@dataclass(frozen=True)
class JointSample:
    """Joint state read from the physics.

    Attributes:
        time: sim time [s] since the last reset.
        positions: joint positions [rad], (14,), left 1..7 then right 1..7 (read-only array).
        velocities: joint velocities [rad/s], (14,), same order (read-only array).
    """

    time: float
    positions: FloatArray
    velocities: FloatArray


@dataclass(frozen=True)
class CommandReport:
    """Outcome of :meth:`DualArmCell.apply_command`.

    Attributes:
        accepted: False if the command was rejected (the arms are then commanded to rest).
        clipped: number of joints whose velocity was clipped to the URDF limit [-].
        reason: human-readable explanation naming the joints; empty if nothing happened.
    """

    accepted: bool
    clipped: int = 0
    reason: str = ""
