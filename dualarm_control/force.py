"""Force feedback of paper 001, eq (9): a force/torque sensor model and a PI contact force controller.

The sensor (a wrist F/T sensor between the right flange and the brush) reads the wrench the
flange exerts on the brush, in the brush frame. A real sensor adds noise and is low-pass
filtered before use; :class:`ForceSensorModel` does both (seeded). :func:`contact_normal_force`
turns the reading into f_c = N^T F, the contact force on the brush along the pan normal N,
after removing the brush's weight (a calibrated tool mass, as on a real sensor). The PI
controller :class:`ForcePI` gives f_F(delta f_c), the offset [m] along the pan normal that
eq (9) adds to the circle task (``CircleTask.normal_offset``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from dualarm_control.kinematics import FloatArray

GRAVITY = np.array((0.0, 0.0, -9.81))
"""World gravity [m/s^2] (the cell's)."""


@dataclass(frozen=True)
class ForceParams:
    """Parameters of the force variant (``scenario.force.*``).

    Attributes:
        set_point: nominal contact force f_c^0 [N], > 0; paper: "e.g. 5 N".
        kp: proportional gain of f_F [m/N], >= 0.
        ki: integral gain of f_F [m/(N s)], >= 0 (the offset grows at ki * delta f_c m/s).
        max_offset: |f_F| bound [m] (anti-windup), > 0.
        gain: task gain k [1/s] of the force runs (paper's force run: k = 2).
        noise_std: white noise on each force axis of the sensor [N], >= 0 (documented level:
            0.3 N, a 6-axis F/T sensor on an arm at 200 Hz; the paper's sensor: about 1 N).
        torque_noise_std: white noise on each torque axis [N m], >= 0.
        cutoff_hz: first-order low-pass cut-off of the reading [Hz], > 0.
        seed: noise seed.
        model_error: pan position modelling error along its normal [m]: the controller's
            pan surface is this far above the real one (paper 6.3: the offset d includes
            modelling errors that force feedback absorbs).
        tool_mass: brush mass [kg] for the reading's gravity compensation, >= 0.
        contact_threshold: a contact force above this counts as contact [N], > 0.
    """

    set_point: float = 5.0
    kp: float = 0.0
    ki: float = 0.002
    max_offset: float = 0.03
    gain: float = 2.0
    noise_std: float = 0.3
    torque_noise_std: float = 0.01
    cutoff_hz: float = 15.0
    seed: int = 0
    model_error: float = 0.01
    tool_mass: float = 0.1
    contact_threshold: float = 0.5

    def __post_init__(self) -> None:
        positive = ("set_point", "max_offset", "gain", "cutoff_hz", "contact_threshold")
        non_negative = ("kp", "ki", "noise_std", "torque_noise_std", "tool_mass")
        for key in (*positive, *non_negative, "model_error"):
            value = getattr(self, key)
            if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
                raise ValueError(f"{key} must be a finite number, got {value!r}")
        for key in positive:
            if getattr(self, key) <= 0:
                raise ValueError(f"{key} must be > 0, got {getattr(self, key)}")
        for key in non_negative:
            if getattr(self, key) < 0:
                raise ValueError(f"{key} must be >= 0, got {getattr(self, key)}")
        if not isinstance(self.seed, int) or isinstance(self.seed, bool):
            raise TypeError(f"seed must be an integer, got {self.seed!r}")


@dataclass
class ForceSensorModel:
    """Noise and first-order low-pass filter of a 6-axis F/T reading, one sample per period.

    y_k = y_{k-1} + a (x_k + n_k - y_{k-1}),  a = 1 - exp(-2 pi f_c T),  n_k ~ N(0, sigma^2)
    per axis (force sigma ``noise_std`` [N], torque ``torque_noise_std`` [N m]), seeded.
    """

    params: ForceParams
    period: float
    _state: FloatArray | None = field(default=None, init=False)

    def __post_init__(self) -> None:
        if not (math.isfinite(self.period) and self.period > 0):
            raise ValueError(f"period must be > 0 [s], got {self.period}")
        self._rng = np.random.default_rng(self.params.seed)
        self._alpha = 1.0 - math.exp(-2.0 * math.pi * self.params.cutoff_hz * self.period)
        p = self.params
        self._sigma = np.array([p.noise_std] * 3 + [p.torque_noise_std] * 3)

    def filter(self, wrench: FloatArray) -> FloatArray:
        """Filtered noisy reading [N, N m], (6,), from the true one (6,)."""
        noisy = np.asarray(wrench, float) + self._sigma * self._rng.standard_normal(6)
        if self._state is None:
            self._state = noisy
        else:
            self._state = self._state + self._alpha * (noisy - self._state)
        return self._state.copy()


def contact_normal_force(wrench: FloatArray, tool_rotation: FloatArray, normal: FloatArray,
                         tool_mass: float) -> float:
    """f_c = N^T F of eq (9): contact force on the tool along the pan normal [N].

    The sensor gives the wrench the flange exerts on the tool, in the tool frame. For the
    tool at rest, flange + contact + weight = 0, so the contact force in the world is
    F = -R_2 F_sensor - m g.

    Args:
        wrench: sensor reading [Fx, Fy, Fz, Mx, My, Mz] in the tool frame, (6,).
        tool_rotation: R_2, tool frame in the world, (3, 3).
        normal: N, pan normal in the world (unit), (3,).
        tool_mass: m [kg].
    """
    force = -tool_rotation @ np.asarray(wrench, float)[:3] - tool_mass * GRAVITY
    return float(normal @ force)


@dataclass
class ForcePI:
    """PI contact force controller f_F of eq (9) along the pan normal.

    delta = f_c^0 - f_c;  I_k = clip(I_{k-1} + ki delta T, +-max_offset);
    f_F = clip(kp delta + I_k, +-max_offset) [m]. f_F > 0 moves the tool into the pan.
    """

    params: ForceParams
    integral: float = 0.0

    def step(self, measured: float, period: float) -> float:
        """Offset f_F [m] for a measured normal force [N] over one period [s]."""
        p = self.params
        delta = p.set_point - measured
        self.integral = min(max(self.integral + p.ki * delta * period, -p.max_offset), p.max_offset)
        return min(max(p.kp * delta + self.integral, -p.max_offset), p.max_offset)
