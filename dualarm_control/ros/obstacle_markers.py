"""The cell's obstacles as visualization_msgs/MarkerArray (issue 42; docs/obstacles.md).

* :data:`OBSTACLES_TOPIC` ``/dualarm/obstacles``, latched (keep-last 1, transient local, as
  ``/robot_description``): the scenario's static obstacles and its moving ones where they wait, so
  that a bag carries its scene and every viewer (Rerun, Foxglove, the video) draws it;
* ``/collision_objects``: a moving obstacle's marker at each simulation step (stamped with the
  step's time), which the controller takes in as a live obstacle (velocity from successive stamps)
  and the recorder keeps.

Markers are in the frame ``world`` (the cell's), namespace = the obstacle's name, id 0; a plane is a
4 x 4 m tile (CUBE) 1 mm thick under its surface, a mesh a MESH_RESOURCE ``file://`` marker.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Final

import numpy as np

from dualarm_control.moving_obstacles import MovingObstacle
from dualarm_control.obstacles import Box, Cylinder, Mesh, Obstacle, Plane, Sphere
from dualarm_control.ros import convert
from dualarm_control.ros.marker_kinds import (
    CUBE,
    CYLINDER,
    LIVE_TOPIC,
    MESH_RESOURCE,
    OBSTACLES_TOPIC,
    SPHERE,
)

FRAME: Final = "world"
COLOUR: Final = (0.55, 0.55, 0.6, 0.8)
MOVING_COLOUR: Final = (0.9, 0.6, 0.45, 0.9)
TILE: Final = 4.0
"""m: the side of the square tile that draws a plane."""


def _z_to(normal: Sequence[float]) -> np.ndarray:
    """The rotation (3, 3) turning z onto the unit vector ``normal`` (Rodrigues)."""
    n = np.asarray(normal, dtype=float)
    v, c = np.cross((0.0, 0.0, 1.0), n), float(n[2])
    if np.linalg.norm(v) < 1e-12:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    k = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    result: np.ndarray = np.eye(3) + k + k @ k / (1.0 + c)
    return result


def obstacle_marker(obstacle: Obstacle, stamp_ns: int, colour: tuple[float, float, float, float] = COLOUR,
                    position: Sequence[float] | np.ndarray | None = None) -> Any:
    """A visualization_msgs/Marker of ``obstacle`` (at ``position`` [m] instead of its own when given)."""
    from visualization_msgs.msg import Marker

    m = Marker()
    m.header = convert.header(stamp_ns, FRAME)
    m.ns, m.id, m.action = obstacle.name, 0, Marker.ADD
    rotation, origin = obstacle.rotation, np.array(obstacle.position if position is None else position, dtype=float)
    if isinstance(obstacle, Box):
        m.type, scale = CUBE, obstacle.size
    elif isinstance(obstacle, Sphere):
        m.type, scale = SPHERE, (2 * obstacle.radius,) * 3
    elif isinstance(obstacle, Cylinder):
        m.type, scale = CYLINDER, (2 * obstacle.radius, 2 * obstacle.radius, obstacle.length)
    elif isinstance(obstacle, Plane):
        rotation = _z_to(obstacle.normal)
        origin = np.asarray(obstacle.normal) * (obstacle.offset - 0.0005)
        m.type, scale = CUBE, (TILE, TILE, 0.001)
    elif isinstance(obstacle, Mesh):
        m.type, scale = MESH_RESOURCE, obstacle.scale
        m.mesh_resource = "file://" + str(obstacle.file)
    else:
        raise TypeError(f"obstacle {obstacle.name!r}: unknown type {type(obstacle).__name__}")
    m.pose.position.x, m.pose.position.y, m.pose.position.z = (float(v) for v in origin)
    (m.pose.orientation.x, m.pose.orientation.y, m.pose.orientation.z,
     m.pose.orientation.w) = convert.quaternion_xyzw(rotation)
    m.scale.x, m.scale.y, m.scale.z = (float(v) for v in scale)
    m.color.r, m.color.g, m.color.b, m.color.a = colour
    return m


def scene_markers(obstacles: Sequence[Obstacle], moving: Sequence[MovingObstacle], stamp_ns: int = 0) -> Any:
    """The MarkerArray of :data:`OBSTACLES_TOPIC`: every static obstacle, every moving one where it waits."""
    from visualization_msgs.msg import MarkerArray

    msg = MarkerArray()
    msg.markers = ([obstacle_marker(o, stamp_ns) for o in obstacles]
                   + [obstacle_marker(m.shape, stamp_ns, MOVING_COLOUR) for m in moving])
    return msg


class ObstacleTopics:
    """A node's obstacle publishers: with ``scene``, the latched scene now (when there is one: the
    controller's); with ``live``, :meth:`publish_moving` (the simulator's: each step's moving obstacles on
    ``/collision_objects``)."""

    def __init__(self, node: Any, obstacles: Sequence[Obstacle], moving: Sequence[MovingObstacle] = (),
                 scene: bool = True, live: bool = False) -> None:
        from visualization_msgs.msg import MarkerArray

        from dualarm_control.ros.qos import latched_qos

        self.moving = tuple(moving)
        self.scene = None
        if scene and (obstacles or moving):
            self.scene = node.create_publisher(MarkerArray, OBSTACLES_TOPIC, latched_qos())
            self.scene.publish(scene_markers(obstacles, moving))
        self.live = node.create_publisher(MarkerArray, LIVE_TOPIC, 100) if live and self.moving else None
        self._array = MarkerArray

    def publish_moving(self, t: float, stamp_ns: int) -> None:
        """Every moving obstacle at its path's position at time t [s], stamped ``stamp_ns``."""
        if self.live is None:
            return
        msg = self._array()
        msg.markers = [obstacle_marker(m.shape, stamp_ns, MOVING_COLOUR, m.state(t)[0]) for m in self.moving]
        self.live.publish(msg)
