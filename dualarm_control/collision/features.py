"""Witness points refined on the shapes' closest features (``polish=True`` of
:meth:`~dualarm_control.collision.CollisionModel.near`): the feature of a shape that holds a GJK
witness point (a point, a segment, a circle or a face), the features' supports and closest points
(segments in closed form, circles by Newton's method), and :func:`polish_witness`, which puts them
together. Hand-written geometry on coal's primitives (spheres, cylinders, boxes, convex hulls);
docs/collision.md ("Polished rows") has the accuracy it buys."""

from __future__ import annotations

import math

import coal
import numpy as np
import pinocchio as pin

from dualarm_control.arrays import FloatArray
from dualarm_control.collision.params import (
    WITNESS_FEATURE_TOLERANCE,
    WITNESS_POLISH_LIMIT,
)

Feature = tuple  # ("point", P, rad) | ("segment", P, Q, rad) | ("circle", C, u, v, r, theta, 0.0) | ("face", N)


def polish_witness(shape_a: coal.CollisionGeometry, placed_a: pin.SE3, hull_a: FloatArray | None,
                   shape_b: coal.CollisionGeometry, placed_b: pin.SE3, hull_b: FloatArray | None, d: float,
                   pa: FloatArray, pb: FloatArray, n: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Witness points and normal of the shapes A and B, placed in the world at ``placed_a`` and
    ``placed_b``, refined on their closest features.

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

    Args:
        shape_a, shape_b: the shapes. placed_a, placed_b: their placements in the world (pinocchio's
            ``oMg``). hull_a, hull_b: a convex hull's vertices in its own frame [m], (k, 3), else None.
        d: coal's distance [m]. pa, pb: GJK's witness points [m], (3,). n: its unit normal, (3,).

    Returns:
        p_a, p_b [m], (3,), and n, (3,): refined, or the given ones.
    """
    fa = _feature(shape_a, placed_a.rotation, placed_a.translation, pa, hull_a)
    fb = _feature(shape_b, placed_b.rotation, placed_b.translation, pb, hull_b)
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
    if isinstance(shape, coal.Halfspace):  # an obstacle plane: its normal, out of the obstacle
        return ("face", rotation @ np.asarray(shape.n, dtype=float))
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
