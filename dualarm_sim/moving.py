"""A scenario's moving obstacles (:mod:`dualarm_control.moving_obstacles`) as pybullet bodies of the
cell: one static-mass body each (as :mod:`dualarm_sim.obstacles`), teleported to its path's position
every step (``resetBasePositionAndOrientation``: a kinematic body, its motion not changed by contacts)."""

from __future__ import annotations

from collections.abc import Sequence

import pybullet as p

from dualarm_control.moving_obstacles import MovingObstacle
from dualarm_sim.obstacles import add_obstacle_bodies


class MovingBodies:
    """The moving obstacles' bodies in the cell's pybullet ``client``, placed at time t by :meth:`place`."""

    def __init__(self, moving: Sequence[MovingObstacle], client: int) -> None:
        self.moving = tuple(moving)
        self.client = client
        self.bodies = add_obstacle_bodies([m.shape for m in self.moving], client)

    def place(self, t: float) -> None:
        """Every body at its path's position at time t [s]."""
        for m in self.moving:
            position, _ = m.state(t)
            p.resetBasePositionAndOrientation(self.bodies[m.name], position.tolist(), (0.0, 0.0, 0.0, 1.0),
                                              physicsClientId=self.client)
