"""The corner path of paper 003 (Sect. IV-B, Fig. 3), sampled, in the left tool frame F1.

A corner with sides ``l`` in a plane ``z = height`` of F1, with a fillet of radius ``r``:
``h1`` points on the first side (x = l, y from 0 to l - r, tangent +y), ``h2`` points on the
fillet (centre (l - r, l - r), strictly inside the quarter circle), ``h3`` points on the second
side (y = l, x from l - r to 0, tangent -x). Constant relative orientation R_d. Paper values:
l = 0.15 m, r = 0.01 m, height 0.3 m, (h1, h2, h3) = (13, 5, 13), R_d = diag(1, -1, -1).

Placement in our cell: the path is relative (F2 in F1), so only its pose in F1 is chosen;
the arms' world poses are the optimiser's (redundancy) choice. We keep the paper's numbers:
the peg frame F2 faces the hole frame F1 (R_d = rpy(180, 0, 0) deg, as in the assembly
scenario) 0.3 m in front of it along F1's z, and moves in the plane parallel to the hole
face. Both LWR4 arms (shoulders 0.52 m apart, reach about 1.2 m to the tool) reach every
point of it with many postures.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dualarm_control.kinematics import FloatArray


@dataclass(frozen=True)
class SampledPath:
    """A relative path given by h samples, all in F1.

    Attributes:
        positions: p_d,i [m], (h, 3).
        tangents: unit tangents t_i, (h, 3).
        rotation: constant relative orientation R_d, (3, 3).
    """

    positions: FloatArray
    tangents: FloatArray
    rotation: FloatArray

    def __len__(self) -> int:
        return int(self.positions.shape[0])


@dataclass(frozen=True)
class CornerPath:
    """Geometry of the corner path (lengths in m, orientation as roll-pitch-yaw in rad)."""

    side: float = 0.15
    fillet_radius: float = 0.01
    height: float = 0.3
    samples: tuple[int, int, int] = (13, 5, 13)
    rpy: tuple[float, float, float] = (math.pi, 0.0, 0.0)

    def __post_init__(self) -> None:
        if not 0.0 < self.fillet_radius < self.side:
            raise ValueError(f"fillet_radius must be in (0, side={self.side}), got {self.fillet_radius}")
        h1, h2, h3 = self.samples
        if h1 < 2 or h2 < 0 or h3 < 2:
            raise ValueError(f"samples (h1, h2, h3) need h1 >= 2, h2 >= 0, h3 >= 2; got {self.samples}")

    @property
    def rotation(self) -> FloatArray:
        """R_d = Rz(yaw) Ry(pitch) Rx(roll), (3, 3)."""
        roll, pitch, yaw = self.rpy
        cr, sr, cp, sp, cy, sy = (math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch),
                                  math.cos(yaw), math.sin(yaw))
        rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
        ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
        rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
        return rz @ ry @ rx

    def sample(self) -> SampledPath:
        """Positions and tangents of Sect. IV-B (the paper's 1-based index i), h = h1 + h2 + h3."""
        l, r = self.side, self.fillet_radius
        h1, h2, h3 = self.samples
        pos, tan = [], []
        for i in range(1, h1 + 1):
            pos.append((l, (l - r) * (i - 1) / (h1 - 1)))
            tan.append((0.0, 1.0))
        for i in range(h1 + 1, h1 + h2 + 1):
            theta = 0.5 * math.pi * (i - h1) / (h2 + 1)
            pos.append(((l - r) + r * math.cos(theta), (l - r) + r * math.sin(theta)))
            tan.append((-math.sin(theta), math.cos(theta)))
        for i in range(h1 + h2 + 1, h1 + h2 + h3 + 1):
            pos.append(((l - r) * (1.0 - (i - (h1 + h2 + 1)) / (h3 - 1)), l))
            tan.append((-1.0, 0.0))
        xy, txy = np.array(pos), np.array(tan)
        h = xy.shape[0]
        positions = np.column_stack((xy, np.full(h, self.height)))
        tangents = np.column_stack((txy, np.zeros(h)))
        return SampledPath(positions=positions, tangents=tangents, rotation=self.rotation)

    @property
    def length(self) -> float:
        """Arc length of the continuous path [m]: two straight sides of l - r and a quarter circle."""
        return 2.0 * (self.side - self.fillet_radius) + 0.5 * math.pi * self.fillet_radius

    def distance(self, point: FloatArray) -> float:
        """Distance [m] from a point in F1 (3,) to the continuous path (line, arc, line)."""
        l, r = self.side, self.fillet_radius
        p = np.asarray(point, dtype=float)
        dz = p[2] - self.height
        x, y = p[0], p[1]
        # side 1: x = l, y in [0, l - r]
        d1 = math.hypot(x - l, y - min(max(y, 0.0), l - r))
        # side 2: y = l, x in [0, l - r]
        d2 = math.hypot(y - l, x - min(max(x, 0.0), l - r))
        # fillet: quarter circle centred at (l - r, l - r), angles [0, pi/2]
        cx, cy = x - (l - r), y - (l - r)
        angle = math.atan2(cy, cx)
        if 0.0 <= angle <= 0.5 * math.pi:
            d3 = abs(math.hypot(cx, cy) - r)
        else:
            d3 = math.inf
        return math.hypot(min(d1, d2, d3), dz)
