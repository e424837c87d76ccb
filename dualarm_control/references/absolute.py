"""Absolute references (issue 41): goals and twists of the absolute frame, tracked under the relative pose.

A goals scenario (:mod:`dualarm_control.references.goals`) may name the absolute frame it drives:

.. code-block:: yaml

    absolute_frame: halfway                   # the frame halfway between the tools (the default)
    absolute_frame:                           # or an object frame fixed to the left tool's grasp
      grasp_position: [0.0, 0.0, 0.15]        # [m], in the left tool frame
      grasp_rpy_deg: [0.0, 0.0, 0.0]
      weight: 100.0                           # optional: weighted beside the relative pose (weight 1) in one
                                              # least-squares problem instead of the second priority under it
    hold: true                                # the relative pose is held (an object in both hands)

With an absolute frame (or an ``absolute: true`` item in ``goals``), a second online generator
(:class:`~dualarm_control.online_trajectory.OnlineTrajectory` with frame ``world``) starts at the measured
absolute pose and follows the absolute goals and twists (pose and twist of the frame in the world); the
controller tracks it as the second priority under the relative pose
(:meth:`~dualarm_control.controller.RelativeController.step`). With ``hold`` a relative goal or twist is refused
(it would tear the grasp), naming why.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import pinocchio as pin

from dualarm_control.drive_commands import ABSOLUTE_FRAMES
from dualarm_control.errors import ScenarioError
from dualarm_control.kinematics import Configuration, DualArmModel, FloatArray
from dualarm_control.online_trajectory import OnlineTrajectory
from dualarm_control.scenario_keys import PREFIX
from dualarm_control.tasks import grasp_state, halfway_state
from dualarm_control.trajectory import MotionLimits

HALFWAY = "halfway"
HOLD_REASON = ("the relative pose is held (scenario.hold: an object in both hands), a relative goal or twist "
               "would tear the grasp; command the absolute frame (/absolute_goal, /absolute_twist)")
"""Why a relative command is refused while the relative pose is held."""


@dataclass(frozen=True)
class AbsoluteFrame:
    """The absolute frame a goals scenario drives.

    Attributes:
        grasp: the object frame in the left tool frame, or None (the halfway frame).
        hold: the relative pose is held: relative commands are refused (:data:`HOLD_REASON`).
        weight: None (the absolute pose is the second priority, under the relative one) or the slack weight it
            has beside the relative pose (weight 1) in one least-squares problem, > 0.
    """

    grasp: pin.SE3 | None = None
    hold: bool = False
    weight: float | None = None

    def pose(self, model: DualArmModel, q: FloatArray) -> tuple[FloatArray, FloatArray]:
        """The frame's world position [m] (3,) and rotation (3, 3) at q (n,) [rad]; ValueError for the halfway
        frame at a half turn."""
        conf = Configuration(model, q)
        state = halfway_state(conf) if self.grasp is None else grasp_state(conf, self.grasp)
        return state.position.copy(), state.rotation.copy()

    def generator(self, model: DualArmModel, q0: FloatArray, limits: MotionLimits, period: float) -> OnlineTrajectory:
        """A generator holding the frame's pose at q0, taking commands in the world frame."""
        return OnlineTrajectory(*self.pose(model, q0), limits=limits, period=period, frames=ABSOLUTE_FRAMES)


def _numbers(flat: Mapping[str, Any], key: str, default: list[float] | None) -> list[float]:
    value = flat.get(PREFIX + key, default)
    if not isinstance(value, list) or len(value) != 3 or not all(
            isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) for v in value):
        raise ScenarioError(f"scenario parameter '{PREFIX}{key}': got {value!r}, expected 3 finite numbers")
    return [float(v) for v in value]


def parse_absolute_frame(flat: Mapping[str, Any], absolute_items: bool) -> AbsoluteFrame | None:
    """``scenario.absolute_frame`` and ``scenario.hold`` (module docstring) of flattened parameters; None when the
    scenario names no absolute frame, holds nothing and has no absolute item (``absolute_items``)."""
    hold = flat.get(PREFIX + "hold", False)
    if not isinstance(hold, bool):
        raise ScenarioError(f"scenario parameter '{PREFIX}hold': got {hold!r}, expected true or false")
    frame = flat.get(PREFIX + "absolute_frame")
    grasp_key = "absolute_frame.grasp_position"
    if frame is not None and frame != HALFWAY:
        raise ScenarioError(f"scenario parameter '{PREFIX}absolute_frame': got {frame!r}, expected '{HALFWAY}' or "
                            "a mapping with grasp_position [m] and grasp_rpy_deg")
    unknown = sorted(k for k in flat if k.startswith(PREFIX + "absolute_frame.")
                     and k[len(PREFIX):] not in (grasp_key, "absolute_frame.grasp_rpy_deg", "absolute_frame.weight"))
    if unknown:
        raise ScenarioError(f"scenario parameter '{unknown[0]}': unknown (absolute_frame takes grasp_position, "
                            "grasp_rpy_deg and weight)")
    weight = flat.get(PREFIX + "absolute_frame.weight")
    if weight is not None and (isinstance(weight, bool) or not isinstance(weight, int | float)
                               or not math.isfinite(weight) or weight <= 0):
        raise ScenarioError(f"scenario parameter '{PREFIX}absolute_frame.weight': got {weight!r}, expected a number "
                            "> 0 (or no weight: the second priority)")
    grasp = None
    if PREFIX + grasp_key in flat:
        position = _numbers(flat, grasp_key, None)
        rpy = [math.radians(v) for v in _numbers(flat, "absolute_frame.grasp_rpy_deg", [0.0, 0.0, 0.0])]
        grasp = pin.SE3(pin.rpy.rpyToMatrix(*rpy), np.array(position))
    if frame is None and grasp is None and not hold and not absolute_items and weight is None:
        return None
    return AbsoluteFrame(grasp, hold, None if weight is None else float(weight))
