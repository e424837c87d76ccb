"""The wrenches on an object held by two hands: external and internal (the cooperative task space, issue 41).

Chiacchio, Chiaverini and Siciliano (1996), the kineto-static duality of the cooperative task space: with
h_1, h_2 the wrenches the two hands exert on the object, each about its own tool origin p_i, in world axes,
the **external** wrench (the one that moves the object: it balances the weight and the inertial load) is
their sum, about the object's centre p_o,

    h_E = [f_1 + f_2;  m_1 + m_2 + (p_1 - p_o) x f_1 + (p_2 - p_o) x f_2]     (6,)

and the **internal** wrench, dual to the relative pose (x_r = x_2 - x_1, x_a = (x_1 + x_2)/2 give
h_a = h_1 + h_2, h_r = (h_2 - h_1)/2), the part that produces no object motion (squeeze or pull, twist):

    h_I = (h_1 - h_2) / 2 = -h_r                                              (6,)

(each moment about its own grasp point: a load carried evenly, f_1 = f_2 = W/2 with no moment at the hands,
gives h_I = 0 whatever the lever arms; taking both moments about p_o instead would leave -(r x W)/2 of the
weight in h_I for grasps at p_o -+ r). A wrench is [f; m] = [fx, fy, fz, mx, my, mz] [N, N m]. Moving a
wrench from a point p to p_o: m_o = m + (p - p_o) x f.

Sensors (:mod:`dualarm_sim.held_object`): a wrist reading s_i is the wrench the flange exerts on the tool link,
about the tool origin p_i, in the tool frame R_i; the tool link (mass m_t) passes it on to the object less its
own weight, so the hand's wrench on the object is f_i = R_i (s_f,i - b_f,i) + m_t g, m_i = R_i (s_m,i - b_m,i)
with b_i the sensor's bias (g = (0, 0, -9.81) m/s^2, the tool link's centre of mass at its origin).

Sign convention of the internal wrench: h_I > 0 along the left tool's axis towards the right tool is a squeeze
(the left hand pushes the object towards the right one and the right hand pushes back).
"""

from __future__ import annotations

import numpy as np

from dualarm_control.force import GRAVITY
from dualarm_control.kinematics import FloatArray


def move_wrench(wrench: FloatArray, point: FloatArray, to: FloatArray) -> FloatArray:
    """A wrench [f; m] (6,) about ``point`` (3,) [m] as the same wrench about ``to`` (3,): m + (point - to) x f."""
    w = np.asarray(wrench, float)
    lever = np.asarray(point, float) - np.asarray(to, float)
    return np.concatenate((w[:3], w[3:] + np.cross(lever, w[:3])))


def in_frame(wrench: FloatArray, rotation: FloatArray) -> FloatArray:
    """A wrench (6,) in world axes expressed in the frame of rotation R (3, 3): [R^T f; R^T m]."""
    w, r = np.asarray(wrench, float), np.asarray(rotation, float)
    return np.concatenate((r.T @ w[:3], r.T @ w[3:]))


def hand_wrenches(readings: FloatArray, rotations: FloatArray, bias: FloatArray | None = None,
                  tool_mass: float = 0.0) -> FloatArray:
    """The wrenches h_1, h_2 the hands exert on the object, each about its tool origin, world axes (module
    docstring).

    Args:
        readings: s_1, s_2 [N, N m], (2, 6), each in its tool frame about the tool origin.
        rotations: R_1, R_2, the tool frames in the world, (2, 3, 3).
        bias: b_1, b_2 (2, 6) (None: zero). tool_mass: m_t [kg] of each tool link.
    Returns:
        (2, 6): [h_1; h_2].
    """
    s = np.asarray(readings, float) - (0.0 if bias is None else np.asarray(bias, float))
    out = np.empty((2, 6))
    for i in range(2):
        r = np.asarray(rotations[i], float)
        out[i] = np.concatenate((r @ s[i, :3] + tool_mass * GRAVITY, r @ s[i, 3:]))
    return out


def external_wrench(hands: FloatArray, positions: FloatArray, centre: FloatArray) -> FloatArray:
    """h_E (6,) about the object's centre p_o (3,) [m] of the hands' wrenches (2, 6) about their tool origins
    p_1, p_2 (2, 3) [m] (module docstring)."""
    h = np.asarray(hands, float)
    return move_wrench(h[0], positions[0], centre) + move_wrench(h[1], positions[1], centre)


def internal_wrench(hands: FloatArray) -> FloatArray:
    """h_I = (h_1 - h_2) / 2 (6,) of the hands' wrenches (2, 6) (module docstring)."""
    h = np.asarray(hands, float)
    return 0.5 * (h[0] - h[1])


def static_readings(rotations: FloatArray, tool_mass: float) -> FloatArray:
    """What unbiased sensors read with empty hands at rest, (2, 6): each holds its tool link's weight,
    s_f,i = -m_t R_i^T g, s_m,i = 0 (the tool link's centre of mass at its origin)."""
    return np.array([np.concatenate((-tool_mass * np.asarray(r, float).T @ GRAVITY, np.zeros(3))) for r in rotations])


def identify_bias(mean_readings: FloatArray, rotations: FloatArray, tool_mass: float) -> FloatArray:
    """The sensors' bias b (2, 6) from their mean readings (2, 6) with empty hands at rest:
    b_i = mean s_i - (what an unbiased sensor reads then, :func:`static_readings`)."""
    return np.asarray(mean_readings, float) - static_readings(rotations, tool_mass)


def identify_payload(mean_readings: FloatArray, rotations: FloatArray, bias: FloatArray, tool_mass: float) -> float:
    """The held object's mass [kg] from the mean readings (2, 6) with the object held at rest: the hands carry
    its weight, m = -g_hat . (f_1 + f_2) / |g| with f_i = R_i (s_f,i - b_f,i) + m_t g (module docstring)."""
    s = np.asarray(mean_readings, float) - np.asarray(bias, float)
    total = sum(np.asarray(rotations[i], float) @ s[i, :3] + tool_mass * GRAVITY for i in range(2))
    g = float(np.linalg.norm(GRAVITY))
    return float(-(GRAVITY / g) @ total / g)
