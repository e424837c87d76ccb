"""The trajectory node's interactive mode: goals and twists from any ROS 2 tool (issue 18).

Subscribes ``/relative_goal`` (geometry_msgs/PoseStamped) and ``/relative_twist``
(geometry_msgs/TwistStamped), both in frame ``left_tool`` (F1; an empty frame id reads as
``left_tool``), and gives them to the live :class:`~dualarm_control.references.goals.GoalsSource`'s
generator; a refused command (NaN/inf, quaternion far from unit norm, unknown frame, beyond
reach, stamp older than the last accepted: :mod:`dualarm_control.drive_commands`) changes
nothing and is reported ``rejected`` with its reason. The motion limits
(``limits.<MotionLimits field>``) are live parameters, validated as the scenario file's. Every
cycle the drive keys (:func:`~dualarm_control.drive_status.status_values`: state, goal
stamp, measured distance and angle to the goal, time to go) go on ``/diagnostics``; the arms'
arrival and stalls are judged by :class:`~dualarm_control.drive_monitor.GoalMonitor` (a stall
at the collision limit names the pair: "collision constraint: left_flange – right_link_5 at
0.030 m; ..."). One log line per goal accepted, preempted, reached, stalled or rejected.
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import fields
from typing import Any

import numpy as np
import pinocchio as pin
from geometry_msgs.msg import PoseStamped, TwistStamped
from rcl_interfaces.msg import SetParametersResult

from dualarm_control.collision import CollisionModel
from dualarm_control.drive_monitor import GoalMonitor
from dualarm_control.drive_status import (
    ABSOLUTE_STATUS_NAME,
    JOGGING,
    MOVING,
    STATUS_NAME,
)
from dualarm_control.errors import DualArmError
from dualarm_control.kinematics import DualArmModel, FloatArray
from dualarm_control.nodes.drive_channel import DriveChannel
from dualarm_control.online_trajectory import CommandResult, OnlineTrajectory
from dualarm_control.params import ParamSpec, positive
from dualarm_control.references.absolute import HOLD_REASON, AbsoluteFrame
from dualarm_control.ros.drive import (
    ABSOLUTE_GOAL_TOPIC,
    ABSOLUTE_TWIST_TOPIC,
    GOAL_TOPIC,
    TWIST_TOPIC,
)
from dualarm_control.ros.inputs import Throttle
from dualarm_control.trajectory import MotionLimits

LIMIT_PREFIX = "limits."


def limit_specs(limits: MotionLimits) -> list[ParamSpec]:
    """Live parameters ``limits.<field>`` with the scenario's values as defaults."""
    return [ParamSpec(LIMIT_PREFIX + f.name, float(getattr(limits, f.name)), f"motion limit {f.name} (live)",
                      check=positive) for f in fields(MotionLimits)]


def _stamp_s(stamp: Any) -> float:
    return float(stamp.sec) + 1e-9 * float(stamp.nanosec)


class InteractiveDrive:
    """Commands in, drive status out, for the trajectory node (module docstring)."""

    def __init__(self, node: Any, model: DualArmModel, limits: MotionLimits, qos: Any,
                 frame: AbsoluteFrame | None = None) -> None:
        self.node = node
        self.log = node.get_logger()
        self.model = model
        self.limits = limits
        self.pending_limits: MotionLimits | None = None
        # stalls are explained by the closest link pair (the controller's collision limit stops the arms at d_s)
        collision = CollisionModel(model, allowed=model.description.collision_allowed)
        self.relative = DriveChannel(STATUS_NAME, "goal", GoalMonitor(model, collision=collision), model.relative_pose)
        self.q: FloatArray | None = None
        self.throttle = Throttle(1.0)
        node.create_subscription(PoseStamped, GOAL_TOPIC, self.on_goal, 10)
        node.create_subscription(TwistStamped, TWIST_TOPIC, self.on_twist, qos)
        node.add_on_set_parameters_callback(self.on_set_parameters)
        self.frame = frame  # the scenario's absolute frame (issue 41): its goals and twists, under the relative pose
        self.absolute: DriveChannel | None = None
        if frame is not None:
            pose = functools.partial(frame.pose, model)
            self.absolute = DriveChannel(ABSOLUTE_STATUS_NAME, "absolute goal",
                                         GoalMonitor(model, collision=collision, pose=pose), pose)
            node.create_subscription(PoseStamped, ABSOLUTE_GOAL_TOPIC, self.on_absolute_goal, 10)
            node.create_subscription(TwistStamped, ABSOLUTE_TWIST_TOPIC, self.on_absolute_twist, qos)

    @property
    def generator(self) -> OnlineTrajectory | None:
        """The relative pose's generator (None until the first joint state)."""
        return self.relative.generator

    def start(self, generator: OnlineTrajectory, absolute: OnlineTrajectory | None = None) -> None:
        """Hold the generators' (measured) poses; commands apply from now."""
        self.relative.generator = generator
        generator.set_limits(self.limits)
        self.log.info("interactive: holding the measured relative pose; goals on "
                      f"{GOAL_TOPIC}, twists on {TWIST_TOPIC} (frame left_tool)")
        if absolute is not None and self.absolute is not None:
            self.absolute.generator = absolute
            absolute.set_limits(self.limits)
            self.log.info(f"interactive: holding the measured absolute pose; absolute goals on {ABSOLUTE_GOAL_TOPIC}, "
                          f"twists on {ABSOLUTE_TWIST_TOPIC} (frame world)"
                          + ("; the relative pose is held (hold: relative commands refused)"
                             if self.frame is not None and self.frame.hold else ""))

    def _held(self, stamp: float | None, what: str) -> bool:
        """True (and the command refused, naming why) when the relative pose is held (``hold``)."""
        if self.frame is None or not self.frame.hold:
            return False
        self._reject(stamp, f"{what} rejected: {HOLD_REASON}")
        return True

    def on_absolute_goal(self, msg: Any) -> None:
        self._absolute(msg, "absolute goal", lambda gen, stamp: gen.command_goal(
            [msg.pose.position.x, msg.pose.position.y, msg.pose.position.z],
            [msg.pose.orientation.x, msg.pose.orientation.y, msg.pose.orientation.z, msg.pose.orientation.w],
            frame=msg.header.frame_id, stamp=stamp))

    def on_absolute_twist(self, msg: Any) -> None:
        lin, ang = msg.twist.linear, msg.twist.angular
        self._absolute(msg, "absolute twist", lambda gen, stamp: gen.command_twist(
            [lin.x, lin.y, lin.z], [ang.x, ang.y, ang.z], frame=msg.header.frame_id, stamp=stamp))

    def _absolute(self, msg: Any, what: str, command: Any) -> None:
        """An absolute command to the absolute frame's generator (its own stamps and status)."""
        channel = self.absolute
        assert channel is not None
        stamp = _stamp_s(msg.header.stamp)
        goal = what == "absolute goal"
        if channel.generator is None:
            self._reject(stamp if goal else None, f"{what} rejected: not started (no joint state yet)", channel)
            return
        if self._answer(command(channel.generator, stamp), stamp if goal else None, what, channel):
            channel.monitor.reset()
            if goal:
                p = msg.pose.position
                self.log.info(f"absolute goal accepted: xyz [{p.x:.4f}, {p.y:.4f}, {p.z:.4f}] m (world), "
                              f"stamp {stamp:.9f}")

    # ---------------------------------------------------------------- commands
    def on_goal(self, msg: Any) -> None:
        gen = self.generator
        stamp = _stamp_s(msg.header.stamp)
        if gen is None:
            self._reject(stamp, "not started (no joint state yet)")
            return
        if self._held(stamp, "goal"):
            return
        p, o = msg.pose.position, msg.pose.orientation
        before = gen.state if gen.goal is not None else ""
        result = gen.command_goal([p.x, p.y, p.z], [o.x, o.y, o.z, o.w], frame=msg.header.frame_id, stamp=stamp)
        if not self._answer(result, stamp, "goal"):
            return
        self.relative.monitor.reset()
        if before in (MOVING, JOGGING) or result.reason:
            self.log.info(f"goal preempted by the goal of stamp {stamp:.9f}")
        assert gen.goal is not None
        angle = float(np.linalg.norm(pin.log3(gen.goal.rotation)))
        self.log.info(f"goal accepted: xyz [{p.x:.4f}, {p.y:.4f}, {p.z:.4f}] m, rotation angle {angle:.4f} rad, "
                      f"stamp {stamp:.9f}")

    def on_twist(self, msg: Any) -> None:
        gen = self.generator
        stamp = _stamp_s(msg.header.stamp)
        if gen is None or self._held(None, "twist"):
            return
        lin, ang = msg.twist.linear, msg.twist.angular
        had_goal = gen.goal is not None and gen.state == MOVING
        result = gen.command_twist([lin.x, lin.y, lin.z], [ang.x, ang.y, ang.z], frame=msg.header.frame_id,
                                   stamp=stamp)
        if self._answer(result, None, "twist"):
            self.relative.monitor.reset()
            if had_goal:
                self.log.info("goal preempted by a twist")

    def _answer(self, result: CommandResult, stamp: float | None, what: str,
                channel: DriveChannel | None = None) -> bool:
        if result.accepted:
            (channel or self.relative).rejected = None
            return True
        self._reject(stamp, f"{what} rejected: {result.reason}", channel)
        return False

    def _reject(self, stamp: float | None, reason: str, channel: DriveChannel | None = None) -> None:
        (channel or self.relative).reject(stamp, reason)
        line = self.throttle.text(reason)
        if line is not None:
            self.log.warning(line)

    def on_set_parameters(self, parameters: list[Any]) -> SetParametersResult:
        """A live limit change, validated as the scenario file's (applied at the next cycle)."""
        changes = {p.name[len(LIMIT_PREFIX):]: p.value for p in parameters if p.name.startswith(LIMIT_PREFIX)}
        if not changes:
            return SetParametersResult(successful=True)
        try:
            limits = dataclasses.replace(self.pending_limits or self.limits, **changes)
        except (DualArmError, ValueError, TypeError) as exc:
            self.log.warning(f"limit change refused: {exc}")
            return SetParametersResult(successful=False, reason=str(exc))
        self.pending_limits = limits
        self.log.info(f"limits changed: {', '.join(f'{k}={v:g}' for k, v in changes.items())}")
        return SetParametersResult(successful=True)

    def recover(self, exc: Exception) -> None:
        """The generator failed (ruckig): hold where the arms are, report it, keep running."""
        gen = self.generator
        assert gen is not None and self.q is not None
        self.log.error(f"online trajectory failed ({type(exc).__name__}: {str(exc).strip()[:200]}); "
                       "holding the measured relative pose")
        for channel in (self.relative, self.absolute):
            if channel is not None and channel.generator is not None:
                channel.generator.hold(*channel.pose(self.q))
                channel.generator.goal = None
                channel.monitor.reset()
        self.relative.rejected = (None, f"trajectory failed: {type(exc).__name__}", gen.time)

    # ---------------------------------------------------------------- per cycle
    def cycle(self, stamp_ns: int) -> list[bytes]:
        """After the cycle's step: apply new limits, judge the goals, the /diagnostics statuses (CDR): the relative
        pose's, and the absolute frame's when the scenario has one."""
        gen = self.generator
        if gen is None or self.q is None:
            return []
        if self.pending_limits is not None:
            self.limits, self.pending_limits = self.pending_limits, None
            for channel in (self.relative, self.absolute):
                if channel is not None and channel.generator is not None:
                    channel.generator.set_limits(self.limits)
        out = [self.relative.status(stamp_ns, self.q, self.log)]
        if self.absolute is not None:
            out.append(self.absolute.status(stamp_ns, self.q, self.log))
        return [status for status in out if status is not None]
