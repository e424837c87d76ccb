"""The rotation coordinates of the online generator: equations (1)-(4) of
:mod:`dualarm_control.online_trajectory`.

Angular velocity and acceleration of the rotation coordinates ``s`` (:func:`angular_velocity` (1),
:func:`angular_acceleration` (2)), and the per-coordinate box ``(Q, b)`` inside the ball of the
angular limits (3) that holds the current state (4) (:func:`least_shares`, :func:`rotation_box`).
Units: rad, s.
"""

from __future__ import annotations

import math

import numpy as np

from dualarm_control.trajectory import FloatArray

_SERIES_ANGLE = 1e-2  # rad: below it the Jacobian coefficients use their Taylor series
_PARALLEL = 1e-9  # relative cross-product norm under which a hint counts as parallel
_MIN_SHARE = 1e-3  # smallest box share b_i given to ruckig (it refuses zero or tiny limits)
_ROUNDING = 1e-9  # relative excess of a limit counted as rounding
_SIDE_SHARE = 0.3  # least box share of a sideways coordinate that moves (its braking room)
_SIDE_STATE = 1e-3  # sideways state share below which the least share (1e-3) is room enough
_IDLE = 1e-9  # sideways state share below which a coordinate is at rest (it moves by rounding only)


def _cross(a: FloatArray, b: FloatArray) -> FloatArray:
    """a x b for 3-vectors (numpy's general ``cross`` costs ~10x more per call on (3,) arrays)."""
    a0, a1, a2 = float(a[0]), float(a[1]), float(a[2])
    b0, b1, b2 = float(b[0]), float(b[1]), float(b[2])
    return np.array((a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0))


def _jacobian_coefficients(theta: float) -> tuple[float, float, float, float]:
    """``A, B, A'/th, B'/th`` of ``J_l = I + A [s]x + B [s]x^2`` at ``th = ||s||`` [rad]."""
    if theta < _SERIES_ANGLE:
        t2 = theta * theta
        return (0.5 - t2 / 24.0 + t2 * t2 / 720.0, 1.0 / 6.0 - t2 / 120.0 + t2 * t2 / 5040.0,
                -1.0 / 12.0 + t2 / 180.0, -1.0 / 60.0 + t2 / 1260.0)
    s, c = math.sin(theta), math.cos(theta)
    a = (1.0 - c) / theta**2
    b = (theta - s) / theta**3
    da = (theta * s - 2.0 * (1.0 - c)) / theta**4
    db = (1.0 - c) / theta**4 - 3.0 * (theta - s) / theta**5
    return a, b, da, db


def angular_velocity(s: FloatArray, ds: FloatArray) -> FloatArray:
    """``w = J_l(s) s'`` (1) [rad/s], (3,), for rotation coordinates ``s`` [rad] and rates ``s'``."""
    a, b, _, _ = _jacobian_coefficients(float(np.linalg.norm(s)))
    sxd = _cross(s, ds)
    return ds + a * sxd + b * _cross(s, sxd)


def angular_acceleration(s: FloatArray, ds: FloatArray, dds: FloatArray) -> FloatArray:
    """``alpha = J_l(s) s'' + (dJ_l/dt) s'`` (2) [rad/s^2], (3,).

    ``(dJ_l/dt) s' = (A'/th)(s.s')(s x s') + (B'/th)(s.s')(s x (s x s')) + B s' x (s x s')``.
    """
    a, b, da, db = _jacobian_coefficients(float(np.linalg.norm(s)))
    sxd = _cross(s, ds)
    sdd = _cross(s, dds)
    dot = float(s @ ds)
    return (dds + a * sdd + b * _cross(s, sdd)
            + da * dot * sxd + db * dot * _cross(s, sxd) + b * _cross(ds, sxd))


def _unit(v: FloatArray) -> FloatArray | None:
    n = float(np.linalg.norm(v))
    return v / n if n > 0.0 else None


def _basis(first: FloatArray, hint: FloatArray | None) -> FloatArray:
    """Orthonormal basis (3, 3) (columns) with first column ``first`` (unit) and the second
    in the plane of ``first`` and ``hint`` when they are not parallel."""
    e2 = None
    if hint is not None:
        e2 = _unit(hint - (hint @ first) * first)
        if e2 is not None and float(np.linalg.norm(hint - (hint @ first) * first)) < _PARALLEL * float(
                np.linalg.norm(hint)):
            e2 = None
    if e2 is None:
        other = np.eye(3)[int(np.argmin(np.abs(first)))]
        e2 = _unit(other - (other @ first) * first)
        assert e2 is not None
    # a second Gram-Schmidt pass ("twice is enough"): a hint nearly parallel to ``first`` leaves e2 off
    # orthogonal by the cancellation's rounding (1e-9 for a hint 1e-9 rad from ``first``, hypothesis found it)
    again = _unit(e2 - (e2 @ first) * first)
    e2 = again if again is not None else e2
    return np.column_stack((first, e2, _cross(first, e2)))


def least_shares(x: FloatArray, y: FloatArray, braking: float) -> FloatArray:
    """Per coordinate, the least box share ``b_i`` in which the state ``(x_i, y_i)`` stays (4).

    A coordinate with velocity share ``x_i = v_i / vmax`` and acceleration share
    ``y_i = a_i / amax`` needs ``b_i >= |y_i|`` and, when its acceleration still raises its speed
    (``x_i y_i > 0``), the speed it reaches while that acceleration falls to zero at the jerk
    limit ``b_i jmax``: ``|x_i| + braking y_i^2 / b_i <= b_i``, ``braking = amax^2 / (2 jmax vmax)``:

        (4)  b_i >= max(|y_i|, (|x_i| + sqrt(x_i^2 + 4 braking y_i^2)) / 2)     (rising)
             b_i >= max(|y_i|, |x_i|)                                           (otherwise)

    Ruckig started from such a state keeps ``|v_i| <= b_i vmax``; from a state beyond it, it
    overshoots (the speed rises while the acceleration is brought down). Shapes (3,), [-].
    """
    ax = np.abs(x)
    rising = x * y > 0.0
    speed = np.where(rising, 0.5 * (ax + np.sqrt(ax * ax + 4.0 * braking * y * y)), ax)
    return np.maximum(speed, np.abs(y))


def _fits(b: FloatArray, need: FloatArray) -> bool:
    """The state whose least shares are ``need`` stays in the box ``b`` (up to rounding)."""
    return bool(np.all(need <= b * (1.0 + _ROUNDING)))


def _at_the_limit(velocity: FloatArray, acceleration: FloatArray, vmax: FloatArray,
                  amax: float) -> tuple[FloatArray, FloatArray]:
    """Rounding at a velocity limit removed: a coordinate at its limit ``vmax`` (3,) [rad/s] up to
    a relative 1e-9 is put on it, and an acceleration [rad/s^2] below ``1e-9 amax`` that pushes it
    further is set to 0 (ruckig brakes for one cycle on ``v = vmax``, ``a = 3e-26``: measured
    6e-5 rad/s dips while cruising, 0.03 cycle lost per goal)."""
    speed = np.abs(velocity)
    at = (speed >= vmax * (1.0 - _ROUNDING)) & (speed <= vmax * (1.0 + _ROUNDING))
    velocity = np.where(at, np.sign(velocity) * vmax, velocity)
    pushing = at & (velocity * acceleration > 0.0) & (np.abs(acceleration) <= _ROUNDING * amax)
    return velocity, np.where(pushing, 0.0, acceleration)


def rotation_box(direction: FloatArray, x: FloatArray, y: FloatArray, braking: float = 0.0,
                 previous: tuple[FloatArray, FloatArray] | None = None) -> tuple[FloatArray, FloatArray]:
    """Basis ``Q`` (3, 3) and box shares ``b`` (3,) for the rotation coordinates (see (3), (4)).

    Args:
        direction: the motion's direction (goal rotation vector, commanded angular velocity),
            (3,), any norm (zero: none).
        x: current ``w / vmax`` (3,).
        y: current ``alpha / amax`` (3,).
        braking: ``amax^2 / (2 jmax vmax)`` [-] of (4).
        previous: the box ``(Q, b)`` of the last cycle: the state, ruckig's output in it, stays in it.

    Returns:
        ``Q`` with first column along ``direction`` (else along ``x``, ``y``) and ``b >= 0`` with
        ``||max(b, 1e-3 on moving coordinates)|| <= 1`` that holds the state (4): a sideways
        coordinate (2, 3) that moves gets at least a 0.3 share to brake in when it fits (without
        a floor its box would shrink with its state and it would never stop), a sideways
        coordinate at rest (state below 1e-9) gets none (ruckig's least share 1e-3 moves it by
        rounding only), the rest of the ball goes to ``b_1``: from rest ``b = (1, 0, 0)``, the
        full scalar limits about the goal axis, as a rest-to-rest segment. When no box along
        ``direction`` holds the state (fast and accelerating sideways), the ``previous`` box is
        kept (it holds it: ruckig put it there) until one does; without one (a state beyond the
        limits, after a limit change) the largest box ``need / ||need||``: ruckig brakes the excess.
    """
    first = _unit(direction)
    if first is None:
        first = _unit(x) if _unit(x) is not None else _unit(y)
    if first is None:
        return np.eye(3), np.array([1.0, 0.0, 0.0])
    hint = x if float(np.linalg.norm(_cross(first, x))) > float(np.linalg.norm(_cross(first, y))) else y
    q = _basis(first, hint)
    need = least_shares(q.T @ x, q.T @ y, braking)
    need = np.where(need <= 1.0 + _ROUNDING, np.minimum(need, 1.0), need)  # at the limit up to rounding: at it
    moving = need[1:] > _IDLE
    counted = np.where(moving, np.maximum(need[1:], _MIN_SHARE), 0.0)
    roomy = np.where(need[1:] > _SIDE_STATE, np.maximum(counted, _SIDE_SHARE), counted)
    for sides in (roomy, counted):
        rest = float(sides @ sides)
        if rest < 1.0:
            b = np.array([math.sqrt(1.0 - rest), *np.where(moving, sides, need[1:])])
            if b[0] >= _MIN_SHARE and _fits(b, need):
                return q, b
    if previous is not None:
        return previous
    need = np.maximum(need, _MIN_SHARE)
    return q, need / float(np.linalg.norm(need))
