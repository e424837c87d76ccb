"""A depth camera's point cloud as one obstacle: voxelised, then a coal octree (issue 42, part 2).

Points p [m], (k, 3), in the cloud's frame, fall into cubic voxels of side s [m] aligned on the
frame's origin, voxel index i = floor(p / s) (octomap's grid: its cells of side s start at
multiples of s, so the voxel is the octree cell the point falls in). One point per occupied voxel
(its centre (i + 1/2) s) is inserted into a coal ``OcTree`` of resolution s: the octree is then
exactly the union of the occupied voxels, whatever the number of points in each (the dedup is a
bitmap of the cloud's bounding box, or a sort of one int64 key per point, instead of octomap's
per-point insertion).

A surface seen by the camera is inside the union of its points' voxels, and every voxel holds a
point, so the distance of a shape to the octree is within one voxel's diagonal s sqrt(3) below the
distance to the points (and the points are on the surface); docs/obstacles.md has what was measured.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import coal
import numpy as np
import numpy.typing as npt

from dualarm_control.arrays import FloatArray

DEFAULT_VOXEL = 0.02
"""m: the default voxel side (``obstacles.cloud_voxel``)."""
DEFAULT_MAX_POINTS = 200_000
"""The most points a cloud is voxelised from; a larger one is decimated (every k-th point) first."""

BITMAP_CELLS = 1 << 24
"""Clouds whose voxel bounding box has at most this many cells are deduplicated on a bitmap (16 MB),
larger ones by sorting their keys."""


@dataclass(frozen=True)
class Voxels:
    """A cloud's occupied voxels.

    Attributes:
        centres: the occupied voxels' centres [m], (v, 3), in the cloud's frame. side: s [m].
        points: points given. used: points voxelised (after dropping non-finite ones and decimating).
        stride: the decimation step (1: every point).
        low, high: the occupied voxels' bounding box [m], (3,) each (the points' voxels' box).
    """

    centres: FloatArray
    side: float
    points: int
    used: int
    stride: int
    low: FloatArray = field(default_factory=lambda: np.zeros(3))
    high: FloatArray = field(default_factory=lambda: np.zeros(3))

    def note(self) -> str:
        """What was done to the cloud, '' when every point was used."""
        parts = []
        if self.stride > 1:
            parts.append(f"decimated to every {self.stride}th point")
        dropped = self.points // self.stride - self.used if self.stride > 1 else self.points - self.used
        if dropped > 0:
            parts.append(f"{dropped} non-finite points dropped")
        return f"cloud of {self.points} points: " + ", ".join(parts) if parts else ""


def voxelise(points: npt.NDArray[np.floating], side: float, max_points: int = DEFAULT_MAX_POINTS) -> Voxels:
    """The occupied voxels of ``points`` [m], (k, 3), side ``side`` [m] (module docstring): non-finite
    points dropped, a cloud of more than ``max_points`` decimated to every ceil(k / max_points)-th point."""
    if not side > 0.0:
        raise ValueError(f"voxel side {side!r}: expected a length > 0 [m]")
    k = len(points)
    stride = max(1, -(-k // max_points)) if max_points > 0 else 1
    sample = points[::stride] if stride > 1 else points
    if not np.isfinite(sample.sum()):  # the rare bad cloud pays for the row test
        sample = sample[np.isfinite(sample).all(axis=1)]
    if not len(sample):
        return Voxels(np.zeros((0, 3)), side, k, 0, stride)
    # coordinates as rows (3, k), in place on one float32 copy: numpy's reductions along a contiguous row
    # are 5-10x faster than down a column, and int32 indices halve the memory traffic
    scaled = np.array(sample.T, dtype=np.float32, order="C")
    scaled *= np.float32(1.0 / side)
    np.floor(scaled, out=scaled)
    lowest, highest = scaled.min(axis=1), scaled.max(axis=1)  # the voxel box, (3,) each: also the range check
    if not (-(2**30) < lowest.min() and highest.max() < 2**30):
        raise ValueError(f"a point {float(np.abs(sample).max())!r} m from the origin: beyond the voxel grid of "
                         f"side {side} m")
    index = scaled.astype(np.int32)
    low = lowest.astype(np.int32)
    index -= low[:, None]
    span = (highest.astype(np.int64) - low) + 1
    cells_total = int(span[0] * span[1] * span[2])
    if cells_total <= BITMAP_CELLS:  # an occupancy bitmap of the cloud's bounding box: no sort
        key = index[0] * np.int32(span[1] * span[2])
        key += index[1] * np.int32(span[2])
        key += index[2]
        occupied = np.zeros(cells_total, dtype=bool)
        occupied[key] = True
        unique = np.flatnonzero(occupied)
    else:
        unique = np.unique((index[0] * span[1] + index[1]) * span[2] + index[2])  # int64 keys
    cells = np.stack((unique // (span[1] * span[2]), (unique // span[2]) % span[1], unique % span[2]), axis=1)
    origin = low.astype(np.int64)
    centres: FloatArray = (cells + origin + 0.5) * side
    return Voxels(centres, side, k, len(sample), stride, origin * side, (origin + span) * side)


def voxel_sphere(voxels: Voxels) -> tuple[FloatArray, float]:
    """A sphere holding every occupied voxel: its centre [m] (3,) in the cloud's frame and radius [m]
    (the voxels' bounding box's, as voxelised: no pass over the voxels, no octree traversal)."""
    low, high = voxels.low, voxels.high
    return (low + high) / 2.0, float(np.linalg.norm(high - low)) / 2.0


def voxel_octree(voxels: Voxels) -> coal.OcTree:
    """A coal octree of resolution ``voxels.side`` holding exactly the occupied voxels."""
    return coal.makeOctree(np.ascontiguousarray(voxels.centres, dtype=float), voxels.side)
