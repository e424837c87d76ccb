"""The phases of a carry (issue 41, item 5): close on a box resting on a support, lift it, carry it along a path
of the absolute frame, set it down, release it and retreat; the targets of the held scenario's two tasks at t.

A held-object task scenario (:mod:`dualarm_control.references.held`) becomes a carry with these keys (under
``scenario.``):

* ``absolute_segments``: the absolute frame's path, segments with the keys of a segments scenario's
  (:mod:`dualarm_control.references.segments`: ``type: pose`` with ``position`` / ``rpy_deg``, or ``type: screw``
  with ``axis``, ``angle_deg``, ``advance``; ``hold`` [s]), world frame, timed by ruckig (``scenario.limits``)
  from the absolute task's pose (the object frame at the grasp);
* ``phases.close_time`` [s]: the hands move from where they start onto the grasp (the relative task's pose, the
  absolute task's pose) along a smoothstep over [0, close_time];
* ``phases.retreat`` [m], ``phases.retreat_time`` [s], ``phases.retreat_delay`` [s]: ``retreat_delay`` after
  ``held_object.release_time`` the hands move that far apart (each half of it, along the axis from the left tool to
  the right one), over retreat_time. The delay covers the offset between the controller's clock and the
  simulator's (which counts from the first motion command): in real time a retreat that began before the hands
  opened tore at the held box (287 N, the wrench limit stopped it).

Timeline: close in [0, close_time]; still until the grasp (``held_object.grasp_time``, the bias identified in
the still step before it) and the payload step after it (``internal_force.still_time``); the path from
``motion_start`` (grasp + 2 still) on; the end pose held until the release, and ``retreat_delay`` after it; then
the retreat.

Targets (:meth:`CarryPlan.relative` and :meth:`CarryPlan.absolute`): pose and twist (p [m], R, v [m/s],
w [rad/s]); the relative one in F1, the absolute one in the world. A blend with s(t) the smoothstep from pose 0
to pose 1 is p = p0 + s (p1 - p0), R = R0 exp(s phi), phi = log(R0^T R1), with v = s' (p1 - p0) and
w = s' R0 phi (its feed-forward).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import pinocchio as pin

from dualarm_control.errors import ScenarioError
from dualarm_control.internal_force import (
    InternalForceParams,
    blend_pose,
    ramp_fraction,
)
from dualarm_control.kinematics import FloatArray
from dualarm_control.references.segments import SegmentSpec, chain, segment_specs
from dualarm_control.scenario_keys import PREFIX, number
from dualarm_control.trajectory import MotionLimits, RelativeTrajectory


@dataclass(frozen=True)
class CarryPhases:
    """A carry's keys (module docstring).

    Attributes:
        segments: the absolute frame's path. close_time: [s], > 0. retreat: [m], >= 0. retreat_time: [s], > 0.
        release_time: when the hands open [s] (``held_object.release_time``). retreat_delay: [s], >= 0.
    """

    segments: tuple[SegmentSpec, ...]
    close_time: float
    retreat: float
    retreat_time: float
    release_time: float
    retreat_delay: float = 0.3

    @property
    def retreat_start(self) -> float:
        """When the hands start to move apart [s]."""
        return self.release_time + self.retreat_delay


PHASE_KEYS = ("close_time", "retreat", "retreat_time", "retreat_delay")


def parse_phases(flat: Mapping[str, Any], control: InternalForceParams, release_time: float) -> CarryPhases | None:
    """``absolute_segments`` and ``phases.*`` (module docstring); None without them; ScenarioError naming a bad
    value or a timeline out of order (the close must end before the bias's still step)."""
    given = PREFIX + "absolute_segments" in flat or any(k.startswith(PREFIX + "phases.") for k in flat)
    if not given:
        return None
    unknown = sorted(k for k in flat if k.startswith(PREFIX + "phases.") and k[len(PREFIX) + 7:] not in PHASE_KEYS)
    if unknown:
        raise ScenarioError(f"scenario parameter '{unknown[0]}': unknown (phases takes {', '.join(PHASE_KEYS)})")
    if PREFIX + "absolute_segments" not in flat:
        raise ScenarioError(f"scenario parameters '{PREFIX}phases.*' need the path, '{PREFIX}absolute_segments'")
    close = number(flat, "phases.close_time", 1.0)
    retreat = number(flat, "phases.retreat", 0.05)
    retreat_time = number(flat, "phases.retreat_time", 1.0)
    delay = number(flat, "phases.retreat_delay", 0.3)
    bias_step = control.grasp_time - control.still_time
    if not 0.0 < close <= bias_step + 1e-9:
        raise ScenarioError(f"scenario parameter '{PREFIX}phases.close_time': got {close}, expected > 0 and <= "
                            f"held_object.grasp_time - internal_force.still_time = {bias_step:g} s (the hands are "
                            "still while the sensors' bias is identified)")
    if retreat < 0 or retreat_time <= 0 or delay < 0:
        raise ScenarioError(f"scenario parameters '{PREFIX}phases.retreat' / 'retreat_time' / 'retreat_delay': got "
                            f"{retreat}, {retreat_time}, {delay}, expected >= 0 m, > 0 s and >= 0 s")
    if math.isinf(release_time):
        raise ScenarioError(f"scenario parameter '{PREFIX}held_object.release_time': a carry sets the box down "
                            "and releases it: give the time [s]")
    return CarryPhases(segment_specs(flat, "absolute_segments"), close, retreat, retreat_time, release_time, delay)


@dataclass(frozen=True)
class PoseTarget:
    """A target pose and twist: position [m] (3,), rotation (3, 3), linear_velocity [m/s] (3,),
    angular_velocity [rad/s] (3,) (as :class:`~dualarm_control.tasks.relative_pose.FixedTarget` reads them)."""

    position: FloatArray
    rotation: FloatArray
    linear_velocity: FloatArray
    angular_velocity: FloatArray


def blend_target(start: tuple[FloatArray, FloatArray], end: tuple[FloatArray, FloatArray], t: float,
                 t0: float, duration: float) -> PoseTarget:
    """The smoothstep blend of the module docstring at t [s] from pose ``start`` at t0 to ``end`` at t0 +
    duration, with its twist."""
    s = ramp_fraction(t, t0, duration)
    u = (t - t0) / duration
    rate = 6.0 * u * (1.0 - u) / duration if 0.0 < u < 1.0 else 0.0
    position, rotation = blend_pose(start, end, s)
    phi = pin.log3(start[1].T @ end[1])
    return PoseTarget(position, rotation, rate * (end[0] - start[0]), rate * (start[1] @ phi))


def _at_rest(pose: tuple[FloatArray, FloatArray]) -> PoseTarget:
    return PoseTarget(pose[0], pose[1], np.zeros(3), np.zeros(3))


class CarryPlan:
    """The two tasks' targets of one carry (module docstring) from the measured start poses.

    Args:
        phases: the keys. control: the internal-force parameters (grasp and still steps).
        relative_start, relative_grasp: (p [m], R) of F2 in F1 at the start and at the grasp.
        absolute_start, absolute_grasp: (p [m], R) of the absolute frame in the world at the start and at the grasp.
        grasp: the absolute frame in the left tool frame (None: the halfway frame). limits: ruckig's limits.
    """

    def __init__(self, phases: CarryPhases, control: InternalForceParams,
                 relative_start: tuple[FloatArray, FloatArray], relative_grasp: tuple[FloatArray, FloatArray],
                 absolute_start: tuple[FloatArray, FloatArray], absolute_grasp: tuple[FloatArray, FloatArray],
                 grasp: pin.SE3 | None, limits: MotionLimits) -> None:
        self.phases, self.control = phases, control
        self.relative_start, self.relative_grasp = relative_start, relative_grasp
        self.absolute_start, self.absolute_grasp = absolute_start, absolute_grasp
        self.path: RelativeTrajectory = path_of(phases, control, absolute_grasp, limits)
        self.path_end = control.motion_start + self.path.duration
        p_rel, r_rel = relative_grasp
        axis = p_rel / max(float(np.linalg.norm(p_rel)), 1e-12)  # F1: from the left tool to the right one
        end_p, end_r = self.path.end_position, self.path.end_rotation
        left_rotation = end_r @ (grasp.rotation.T if grasp is not None else np.eye(3))
        self.relative_retreat = (p_rel + phases.retreat * axis, r_rel)
        self.absolute_end = (end_p, end_r)
        shift = -0.5 * phases.retreat * (left_rotation @ axis) if grasp is not None else np.zeros(3)
        self.absolute_retreat = (end_p + shift, end_r)

    @property
    def end(self) -> float:
        """When the retreat is over [s]."""
        return self.phases.retreat_start + self.phases.retreat_time

    def stage(self, t: float) -> str:
        """The phase at t [s]: close, grasp (the still steps), carry, place (the end pose held), release, retreat."""
        if t < self.phases.close_time:
            return "close"
        if t < self.control.motion_start:
            return "grasp"
        if t < self.path_end:
            return "carry"
        if t < self.phases.release_time:
            return "place"
        return "release" if t < self.phases.retreat_start else "retreat"

    def relative(self, t: float) -> PoseTarget:
        """F2's target in F1 at t [s]."""
        if t < self.phases.close_time:
            return blend_target(self.relative_start, self.relative_grasp, t, 0.0, self.phases.close_time)
        if t < self.phases.retreat_start:
            return _at_rest(self.relative_grasp)
        return blend_target(self.relative_grasp, self.relative_retreat, t, self.phases.retreat_start,
                            self.phases.retreat_time)

    def absolute(self, t: float) -> PoseTarget:
        """The absolute frame's target in the world at t [s]."""
        if t < self.phases.close_time:
            return blend_target(self.absolute_start, self.absolute_grasp, t, 0.0, self.phases.close_time)
        if t < self.control.motion_start:
            return _at_rest(self.absolute_grasp)
        if t < self.phases.retreat_start:
            sample = self.path.sample(t - self.control.motion_start)
            return PoseTarget(sample.position, sample.rotation, sample.linear_velocity, sample.angular_velocity)
        return blend_target(self.absolute_end, self.absolute_retreat, t, self.phases.retreat_start,
                            self.phases.retreat_time)


def path_of(phases: CarryPhases, control: InternalForceParams, absolute_grasp: tuple[FloatArray, FloatArray],
            limits: MotionLimits) -> RelativeTrajectory:
    """The absolute frame's path (ruckig, world frame) from its pose at the grasp; ScenarioError when it would end
    after the release (the path starts at ``control.motion_start``)."""
    path = chain(phases.segments, np.asarray(absolute_grasp[0], float), np.asarray(absolute_grasp[1], float), limits)
    end = control.motion_start + path.duration
    still = control.payload_start if control.payload_start >= control.motion_start else phases.release_time
    if end > still + 1e-9:
        raise ScenarioError(f"scenario parameter '{PREFIX}held_object.release_time': got {phases.release_time} s, "
                            f"but the path ends at {end:.3f} s (motion start {control.motion_start:g} s + "
                            f"{path.duration:.3f} s), after the release or the payload's still step before it "
                            f"({still:g} s): release later")
    return path
