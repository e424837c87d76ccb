"""trajectory_node: streams the ruckig relative targets of a scenario on ``/relative_target``.

The trajectory starts from the relative pose of the first ``/joint_states`` (forward
kinematics). Real-time mode: one target per control period on a timer, timed from the first
joint state on the node's clock (simulation time with ``use_sim_time``). Lockstep mode: one
target per joint state, stamped with the joint state's stamp, so the controller can pair them. When the trajectory plus the
scenario's settle time has elapsed the node logs completion, publishes a final
``/diagnostics`` status "complete" and exits 0; with ``repeat:=true`` (soak runs) it starts the
scenario again from the pose of the next joint state instead, forever. A malformed or unusable
joint state (bad CDR, wrong or missing joint names, NaN; in lockstep a stamp older than the
last one) is rejected with a throttled log line and not used. In real-time mode the node
subscribes to ``/joint_states`` only until the trajectory starts (and again for the next run
with ``repeat``): at 1 kHz a state it does not use costs a wake-up and a decode every period.
"""

from __future__ import annotations

import sys
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory, MultiDOFJointTrajectory

from dualarm_control.kinematics import DualArmModel
from dualarm_control.params import ParamSpec, positive
from dualarm_control.references.plan import PlanSource
from dualarm_control.ros import convert
from dualarm_control.ros.inputs import StampGate, Throttle, subscribe_checked
from dualarm_control.ros.node import (
    declare,
    priority_from_args,
    request_realtime_priority,
    run,
    thread_priority_spec,
    usage,
)
from dualarm_control.ros.qos import QOS_PARAMETER, publisher_depth, stream_qos
from dualarm_control.scenario import load_scenario
from dualarm_control.trajectory import RelativeTrajectory

DEFAULT_PRIORITY = 40
PARAMETERS = (
    ParamSpec("scenario", "assembly", "scenario name (config/scenarios/<name>.yaml) or YAML path", read_only=True),
    ParamSpec("control_period", 0.005, "target period in real-time mode [s]", check=positive, read_only=True),
    ParamSpec("lockstep", False, "publish one target per joint state, with its stamp", read_only=True),
    ParamSpec("plan", "", "plan.json of `dualarm plan`: stream its joint trajectory on /joint_reference "
              "(and its relative pose on /relative_target) instead of the scenario's segments", read_only=True),
    QOS_PARAMETER,
    thread_priority_spec(DEFAULT_PRIORITY, "the target stream (below the simulator's and controller's 50)"),
    ParamSpec("repeat", False, "start the scenario again from the current pose when it completes (soak runs)",
              read_only=True),
)


class TrajectoryNode:
    """Node shell around :class:`RelativeTrajectory`."""

    def __init__(self, context: Any, priority_note: str = "disabled") -> None:
        self.node = Node("trajectory_node", context=context)
        p = declare(self.node, PARAMETERS)
        self.scenario = load_scenario(p["scenario"])
        self.lockstep = bool(p["lockstep"])
        self.repeat = bool(p["repeat"])
        self.repetitions = 0
        self.model = DualArmModel()
        self.plan = PlanSource.from_file(self.model, p["plan"]) if p["plan"] else None
        self.order = {name: i for i, name in enumerate(self.model.joint_names)}
        n = self.node
        qos = stream_qos(p["qos_reliability"])
        depth = publisher_depth(self.lockstep)
        self.pub = n.create_publisher(MultiDOFJointTrajectory, "/relative_target", stream_qos(p["qos_reliability"], depth))
        self.pub_diag = n.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.pub_joint = n.create_publisher(JointTrajectory, "/joint_reference", stream_qos(p["qos_reliability"], depth))
        self.qos = qos
        self.states: Any = None  # the /joint_states subscription while one is needed
        self.subscribe_states()
        self.log = n.get_logger()
        self.throttle = Throttle(1.0)
        self.gate = StampGate("joint_states")
        self.trajectory: RelativeTrajectory | None = None
        self.start_ns = 0
        self.segment = -1
        self.end_s = 0.0
        self.finished = False
        if not self.lockstep:
            n.create_timer(p["control_period"], self.on_tick)
        what = (self.plan or self.scenario.reference).describe()
        self.log.info(f"scenario '{self.scenario.name}': {what}, "
                      f"{'lockstep' if self.lockstep else 'real-time'}; waiting for /joint_states")
        if priority_note and priority_note != "disabled":
            self.log.warning(priority_note)

    def subscribe_states(self) -> None:
        self.states = subscribe_checked(self.node, JointState, "/joint_states", self.on_joint_state, self.qos,
                                        self.reject, convert.JointStateInput(self.order))

    def on_joint_state(self, sample: tuple[int, tuple[np.ndarray, np.ndarray] | str]) -> None:
        if self.finished:
            return
        stamp, decoded = sample
        if isinstance(decoded, str):
            self.reject(f"joint state rejected: {decoded}")
            return
        verdict = self.gate.check(stamp)
        if verdict.message:
            self.reject(verdict.message)
        if not verdict.accepted:
            return
        if self.trajectory is None:
            self.trajectory = self.scenario.trajectory(*self.model.relative_pose(decoded[0]))
            self.start_ns = stamp if self.lockstep else self.node.get_clock().now().nanoseconds
            duration, settle = ((self.plan.duration, self.plan.settle_time) if self.plan
                                else (self.trajectory.duration, self.scenario.settle_time))
            self.end_s = duration + settle
            self.log.info(f"trajectory: {duration:.2f} s + settle {settle:.2f} s")
        if self.lockstep:
            self.publish(stamp, stamp - self.start_ns)

    def reject(self, reason: str) -> None:
        """Throttled warning for an unusable input (the sample is not used)."""
        line = self.throttle.text(reason)
        if line is not None:
            self.log.warning(line)

    def on_tick(self) -> None:
        if self.trajectory is not None:
            if self.states is not None:  # started: the timer drives the stream (not destroyed in its own callback)
                self.node.destroy_subscription(self.states)
                self.states = None
            now = self.node.get_clock().now().nanoseconds
            self.publish(now, now - self.start_ns)

    def publish(self, stamp: int, elapsed_ns: int) -> None:
        assert self.trajectory is not None
        t = elapsed_ns / 1e9
        if t >= self.end_s:  # no target at or after the end: as many cycles as the in-process run
            self.log.info(f"scenario '{self.scenario.name}' complete at t={t:.2f} s")
            self._status(stamp, 0, "complete", t)
            self.repetitions += 1
            if self.repeat:  # the next joint state plans the next run from where the arms are
                self.trajectory, self.segment = None, -1
                if self.states is None:
                    self.subscribe_states()
            else:
                self.finished = True  # run() stops spinning after this callback
            return
        if self.plan is not None:
            ref = self.plan.sample(t)
            self.pub_joint.publish(convert.joint_reference_message(stamp, elapsed_ns, self.model.joint_names,
                                                                   ref.joint_positions, ref.joint_velocities))
            self.pub.publish(convert.target_message(stamp, elapsed_ns, ref))
            return
        sample = self.trajectory.sample(t)
        self.pub.publish(convert.target_message(stamp, elapsed_ns, sample))
        if sample.segment != self.segment and not sample.done:
            self.segment = sample.segment
            self.log.info(f"t={t:.2f} s: segment {sample.segment + 1}/{len(self.trajectory.segments)} "
                          f"'{sample.segment_name}'")
            self._status(stamp, 0, f"segment {sample.segment_name}", t)

    def _status(self, stamp: int, level: int, message: str, t: float) -> None:
        values = {"scenario": self.scenario.name, "time_s": f"{t:.3f}", "duration_s": f"{self.end_s:.3f}",
                  "repetitions": self.repetitions}
        self.pub_diag.publish(convert.diagnostics(stamp, "trajectory_node", level, message, values))


def main(args: list[str] | None = None) -> int:
    argv = list(sys.argv if args is None else args)
    # Applied to every thread (the middleware's too) once the node is built: a starved target stream
    # stops the controller (target_timeout), as `dualarm soak` showed on a loaded machine.
    why_not = request_realtime_priority(priority_from_args(argv, DEFAULT_PRIORITY, "trajectory_node"))
    return run(lambda context: TrajectoryNode(context, why_not), argv,
               usage("trajectory_node", __doc__ or "", PARAMETERS))


if __name__ == "__main__":
    raise SystemExit(main())
