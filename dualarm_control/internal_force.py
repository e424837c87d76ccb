"""Internal-force control of an object held by two hands (issue 41, item 3): a relative-frame admittance and
the identification of the sensors' bias and the payload.

Paper 001's eq (9) adds a force-feedback offset f_F(f_c^0 - f_c) to one task along one direction (the pan
normal). Here the same feedback acts on the six components of the relative frame F1 (the left tool's): the
offset delta = [delta_p; delta_w] (m, rad; F1 axes) of the held relative pose follows the internal wrench
h_I (:mod:`dualarm_control.cooperative_wrench`, expressed in F1) away from its setpoint h_I*, as eq (9)'s PI:

    I_k = clip(I_{k-1} + T K_I (h_I - h_I*)),   delta_k = clip(K_P (h_I - h_I*) + I_k)
    K_I = diag(k_f I_3, k_m I_3),  K_P = diag(p_f I_3, p_m I_3)

(k_f [m/(N s)], k_m [rad/(N m s)], p_f [m/N], p_m [rad/(N m)]; clipped to ``max_offset`` [m] and
``max_rotation`` [rad], anti-windup). The proportional part damps the loop: the grasp is stiff (K_s, N/m), the
internal force grows as K_s k times the relative pose task's error (k its gain), so the integral alone makes
an undamped oscillator (f'' = -K_s k k_f f); p_f adds the damping K_s k p_f. A squeeze (h_I > 0 along the left tool's axis
towards the right tool) moves the tools apart; a pull brings them together; a twist turns the right tool
back. The relative target becomes p* + delta_p, exp(delta_w) R* (the right tool in F1).

Identification (two still steps, :class:`WrenchIdentification`): with empty hands before the grasp, the
sensors' bias (their mean reading less the tool links' weight); with the object held, still, after the
grasp, its mass (the hands carry its weight, :func:`~dualarm_control.cooperative_wrench.identify_payload`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from dualarm_control.cooperative_wrench import identify_bias, identify_payload
from dualarm_control.kinematics import FloatArray
from dualarm_control.robot import TOOL_MASS


def _number(name: str, value: object, low: float = 0.0, strict: bool = False) -> None:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ValueError(f"{name} must be a finite number, got {value!r}")
    if value < low or (strict and value <= low):
        raise ValueError(f"{name} must be {'>' if strict else '>='} {low:g}, got {value!r}")


@dataclass(frozen=True)
class InternalForceParams:
    """Internal-force control (scenario keys ``internal_force.*``; the live ones marked live).

    Attributes:
        task: the relative_pose task whose target the admittance moves.
        setpoint: h_I* [N, N N, N m x3] in F1, (6,) (live).
        force_gain: k_f [m/(N s)], >= 0 (live). torque_gain: k_m [rad/(N m s)], >= 0 (live).
        force_p_gain: p_f [m/N], >= 0 (live). torque_p_gain: p_m [rad/(N m)], >= 0 (live).
        max_offset: |delta_p| bound per axis [m], > 0. max_rotation: |delta_w| bound per axis [rad], > 0.
        grasp_time: when the hands close [s] (the simulator's ``held_object.grasp_time``), >= 0.
        still_time: length of each identification step [s], >= 0: the bias in [grasp - still, grasp), the
            payload in [grasp + still, grasp + 2 still); the absolute tasks hold the start pose until then.
        start_ramp: after the still steps the absolute tasks' targets blend from the start pose to theirs over
            this time [s] (smoothstep; a step would jolt the stiff grasp), >= 0.
        wrench_limit: a hand's force on the object beyond this [N] stops the motion safely, > 0.
        payload_time: the payload's still step starts here [s] (lasting ``still_time``); None: at grasp + still
            (a carry lifts the box off its support first and identifies it while it hangs still, set down above
            the support: :mod:`~dualarm_control.references.carry`).
        tool_mass: each tool link's mass [kg] (the sensors carry it), >= 0.
    """

    task: str = "hold"
    setpoint: tuple[float, ...] = (0.0,) * 6
    force_gain: float = 1.0e-2
    torque_gain: float = 0.25
    force_p_gain: float = 0.0
    torque_p_gain: float = 0.0
    max_offset: float = 0.02
    max_rotation: float = 0.1
    grasp_time: float = 0.0
    still_time: float = 0.2
    start_ramp: float = 1.0
    wrench_limit: float = 200.0
    tool_mass: float = TOOL_MASS
    payload_time: float | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.task, str) or not self.task:
            raise ValueError(f"task must be a relative_pose task's name, got {self.task!r}")
        if len(self.setpoint) != 6:
            raise ValueError(f"setpoint must be 6 numbers [N, N m], got {self.setpoint!r}")
        for i, v in enumerate(self.setpoint):
            _number(f"setpoint[{i}]", v, -math.inf)
        for name in ("force_gain", "torque_gain", "force_p_gain", "torque_p_gain", "grasp_time", "still_time", "start_ramp",
                     "tool_mass"):
            _number(name, getattr(self, name))
        for name in ("max_offset", "max_rotation", "wrench_limit"):
            _number(name, getattr(self, name), strict=True)
        if self.payload_time is not None:
            _number("payload_time", self.payload_time, self.grasp_time)

    @property
    def payload_start(self) -> float:
        """When the payload's still step starts [s]."""
        return self.grasp_time + self.still_time if self.payload_time is None else self.payload_time

    @property
    def motion_start(self) -> float:
        """When the identification is over and the absolute tasks may move [s]."""
        return self.grasp_time + 2.0 * self.still_time


@dataclass
class RelativeAdmittance:
    """The offset delta (6,) of the held relative pose (module docstring), one step per control period."""

    params: InternalForceParams
    offset: FloatArray = field(default_factory=lambda: np.zeros(6))
    integral: FloatArray = field(default_factory=lambda: np.zeros(6))

    def step(self, internal: FloatArray, period: float) -> FloatArray:
        """delta after one period T [s] with the measured internal wrench h_I (6,) [N, N m] in F1."""
        p = self.params
        k_i = np.array([p.force_gain] * 3 + [p.torque_gain] * 3)
        k_p = np.array([p.force_p_gain] * 3 + [p.torque_p_gain] * 3)
        bound = np.array([p.max_offset] * 3 + [p.max_rotation] * 3)
        error = np.asarray(internal, float) - np.asarray(p.setpoint, float)
        self.integral = np.clip(self.integral + period * k_i * error, -bound, bound)
        self.offset = np.clip(k_p * error + self.integral, -bound, bound)
        return self.offset.copy()


def ramp_fraction(t: float, start: float, duration: float) -> float:
    """s(t) in [0, 1]: 0 before ``start`` [s], the smoothstep 3 u^2 - 2 u^3 of u = (t - start) / duration, 1 after."""
    if t <= start:
        return 0.0
    if duration <= 0.0 or t >= start + duration:
        return 1.0
    u = (t - start) / duration
    return u * u * (3.0 - 2.0 * u)


def blend_pose(start: tuple[FloatArray, FloatArray], end: tuple[FloatArray, FloatArray], s: float
               ) -> tuple[FloatArray, FloatArray]:
    """The pose a fraction s of the way: (p_0 + s (p_1 - p_0) [m], R_0 exp(s log(R_0^T R_1)))."""
    (p0, r0), (p1, r1) = start, end
    return p0 + s * (p1 - p0), r0 @ pin.exp3(s * pin.log3(r0.T @ r1))


def offset_target(position: FloatArray, rotation: FloatArray, offset: FloatArray) -> tuple[FloatArray, FloatArray]:
    """The relative target moved by delta (6,): (p* + delta_p (3,) [m], exp(delta_w) R* (3, 3)), F1 axes."""
    d = np.asarray(offset, float)
    return np.asarray(position, float) + d[:3], pin.exp3(d[3:]) @ np.asarray(rotation, float)


@dataclass
class WrenchIdentification:
    """The two still steps of :class:`InternalForceParams` (module docstring): readings (2, 6) and the tool
    rotations (2, 3, 3) are added while t is in a window; the bias is known once the first window is over,
    the payload once the second is. Before: zero bias, NaN mass."""

    params: InternalForceParams
    bias: FloatArray = field(default_factory=lambda: np.zeros((2, 6)))
    mass: float = math.nan
    _sums: dict[str, list[FloatArray]] = field(default_factory=lambda: {"bias": [], "payload": []})
    _rotations: FloatArray | None = None
    _bias_known: bool = False

    def add(self, t: float, readings: FloatArray, rotations: FloatArray) -> None:
        """One cycle's readings at time t [s]."""
        p = self.params
        grasp, still = p.grasp_time, p.still_time
        if grasp - still <= t < grasp:
            self._sums["bias"].append(np.asarray(readings, float))
            self._rotations = np.asarray(rotations, float)
        elif t >= grasp and self._sums["bias"] and not self._bias_known:
            assert self._rotations is not None
            self._bias_known = True
            self.bias = identify_bias(np.mean(self._sums["bias"], axis=0), self._rotations, p.tool_mass)
        payload = p.payload_start
        if payload <= t < payload + still:
            self._sums["payload"].append(np.asarray(readings, float))
            self._rotations = np.asarray(rotations, float)
        elif t >= payload + still and self._sums["payload"] and math.isnan(self.mass):
            assert self._rotations is not None
            self.mass = identify_payload(np.mean(self._sums["payload"], axis=0), self._rotations, self.bias,
                                         p.tool_mass)
