"""trajectory_node: streams the targets of the scenario's reference source (/relative_target, ...).

What it publishes is the reference source's (:meth:`ReferenceSource.stream
<dualarm_control.references.base.ReferenceSource>`): the relative targets of a segments or
goals scenario on ``/relative_target``; with ``plan:=FILE`` a plan's joint reference on
``/joint_reference`` and its relative pose on ``/relative_target``. The stream starts from the
first ``/joint_states`` (measured start configuration). Real-time mode: one target per control
period on a tick of the spin loop (``ros.node.Ticker``), timed on the node's clock (simulation time
with ``use_sim_time``) from the controller's first cycle (``wait_for_controller``: until
controller_node reports one on /diagnostics the first target is held, and after 2 s the node says
so), so that a scenario never runs to "complete" in front of a controller that never cycled. Lockstep mode: one target per joint state, stamped with the joint state's
stamp, so the controller can pair them. When the stream's end (trajectory plus the scenario's
settle time) has come the node logs completion, publishes a final ``/diagnostics`` status
"complete" and exits 0; with ``repeat:=true`` (soak runs) it starts the scenario again from the
pose of the next joint state instead, forever. A malformed or unusable joint state (bad CDR,
wrong or missing joint names, NaN; in lockstep a stamp older than the last one) is rejected with
a throttled log line and not used. In real-time mode the node subscribes to ``/joint_states``
only until the stream starts (and again for the next run with ``repeat``): at 1 kHz a state it
does not use costs a wake-up and a decode every period.

``mode:=interactive`` (issue 18): the source is live goals and twists
(:class:`~dualarm_control.references.goals.GoalsSource` without a script): the node holds the
measured relative pose, follows ``/relative_goal`` and ``/relative_twist``, reports on
``/diagnostics`` every cycle and never completes (:mod:`dualarm_control.nodes.interactive`);
it keeps ``/joint_states`` to judge the arms' arrival and stalls.
"""

from __future__ import annotations

import sys
import time
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from trajectory_msgs.msg import JointTrajectory, MultiDOFJointTrajectory

from dualarm_control.cell_robot import node_scenario
from dualarm_control.drive_monitor import GoalOutcome, SegmentJudge
from dualarm_control.drive_status import STALLED
from dualarm_control.hardware import HARDWARE_PARAMETERS, profile_from_values
from dualarm_control.kinematics import DualArmModel
from dualarm_control.params import ParamSpec, positive
from dualarm_control.references.base import (
    JOINT_REFERENCE,
    RELATIVE_TARGET,
    RunOptions,
    TargetStream,
)
from dualarm_control.references.goals import GoalsSource, GoalsStream
from dualarm_control.references.plan import PlanSource
from dualarm_control.ros import convert
from dualarm_control.ros.cell_topic import CellPublisher
from dualarm_control.ros.hardware_io import JointStates, declare_with_profile
from dualarm_control.ros.inputs import StampGate, Throttle
from dualarm_control.ros.local_bus import LocalBus, local_publisher
from dualarm_control.ros.node import Tick, clock_ns, declare, run, usage
from dualarm_control.ros.node_exit import exit_process
from dualarm_control.ros.priority import (
    log_priority,
    node_scheduling,
    thread_priority_spec,
)
from dualarm_control.ros.qos import QOS_PARAMETER, publisher_depth, stream_qos
from dualarm_control.scenario import ROBOT_PARAMETER
from dualarm_control.trajectory import MotionLimits

DEFAULT_PRIORITY = 40
SCENARIO, INTERACTIVE = "scenario", "interactive"
CONTROLLER_NOTE_S = 2.0  # real time: holding the first target longer than this is said (throttled)
PARAMETERS = (
    ParamSpec("scenario", "assembly", "scenario name (config/scenarios/<name>.yaml) or YAML path", read_only=True),
    ParamSpec("mode", SCENARIO, "scenario: stream the scenario's reference; interactive: hold the measured pose "
              "and follow /relative_goal and /relative_twist", choices=lambda: [SCENARIO, INTERACTIVE],
              read_only=True),
    ParamSpec("control_period", 0.005, "target period in real-time mode [s]", check=positive, read_only=True),
    ParamSpec("lockstep", False, "publish one target per joint state, with its stamp", read_only=True),
    ParamSpec("plan", "", "plan.json of `dualarm plan`: stream its joint trajectory on /joint_reference "
              "(and its relative pose on /relative_target) instead of the scenario's segments", read_only=True),
    QOS_PARAMETER,
    thread_priority_spec(DEFAULT_PRIORITY, "the target stream (below the simulator's and controller's 50)"),
    ParamSpec("repeat", False, "start the scenario again from the current pose when it completes (soak runs)",
              read_only=True),
    ParamSpec("wait_for_controller", True, "real time: hold the first target until controller_node reports a "
              "cycle on /diagnostics, so that the scenario's clock starts when the arms can follow (false: at the "
              "first joint state, with no controller in sight)", read_only=True),
    ParamSpec("start_after_reader", "", "real time: hold the first target until a node of this name reads "
              "/relative_target (a recorder: the bag then holds the run from t = 0; '' = no wait)", read_only=True),
    ROBOT_PARAMETER,
    *HARDWARE_PARAMETERS,  # the joint-state topics (issue 29; the outputs are validated as the controller's)
)


class TrajectoryNode:
    """Node shell around a reference source's :class:`~dualarm_control.references.base.TargetStream`."""

    def __init__(self, context: Any, priority_note: str = "disabled", bus: LocalBus | None = None) -> None:
        from dualarm_control.nodes.interactive import (
            LIMIT_PREFIX,
            InteractiveDrive,
            limit_specs,
        )

        self.node = Node("trajectory_node", context=context)
        self.bus = bus
        p = declare_with_profile(self.node, PARAMETERS)
        self.scenario, robot_note = node_scenario(p, "trajectory_node")
        self.node.get_logger().info(robot_note)
        self.profile = profile_from_values(p, self.scenario.robot.joint_names, "trajectory_node")
        self.lockstep = bool(p["lockstep"])
        self.repeat = bool(p["repeat"])
        self.period = float(p["control_period"])
        self.repetitions = 0
        self.model = DualArmModel(self.scenario.robot)
        n = self.node
        self.log = n.get_logger()
        self.qos = stream_qos(p["qos_reliability"])
        self.drive: InteractiveDrive | None = None
        self.source: Any = self.scenario.reference
        if p["plan"]:
            self.source = PlanSource.from_file(self.model, p["plan"])
        if p["mode"] == INTERACTIVE:  # live goals; the scenario's absolute frame (issue 41) with its own
            frame = getattr(self.scenario.reference, "frame", None)
            self.source = GoalsSource(None, frame)
            limits = declare(n, limit_specs(self.scenario.limits))
            self.drive = InteractiveDrive(n, self.model, MotionLimits(
                **{k[len(LIMIT_PREFIX):]: v for k, v in limits.items()}), self.qos, frame)
        depth = stream_qos(p["qos_reliability"], publisher_depth(self.lockstep))
        self.pub = local_publisher(bus, n.create_publisher(MultiDOFJointTrajectory, RELATIVE_TARGET, depth),
                                   RELATIVE_TARGET)
        self.pub_joint = (local_publisher(bus, n.create_publisher(JointTrajectory, JOINT_REFERENCE, depth),
                                          JOINT_REFERENCE) if JOINT_REFERENCE in self.source.streams else None)
        self.pub_diag = n.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.states: JointStates | None = None  # the joint-state subscriptions while they are needed
        self.subscribe_states()
        self.throttle = Throttle(1.0)
        self.gate = StampGate("joint_states")
        self.stream: TargetStream | None = None
        self.judge: SegmentJudge | None = None  # a segments scenario: each segment's verdict, live (issue 40)
        self.start_ns = 0
        self.stage = ""
        self.finished = False
        self.ticks: list[Tick] = [] if self.lockstep else [(self.period, self.on_tick)]  # ros.node.Ticker
        # real time: the scenario's clock starts at the controller's first cycle (None: not seen yet)
        self.controller_seen: float | None = None if (p["wait_for_controller"] and not self.lockstep
                                                      and self.drive is None) else 0.0
        self.sub_diag = None if self.controller_seen is not None else n.create_subscription(
            DiagnosticArray, "/diagnostics", self.on_diagnostics, 100)
        self.held_since = time.monotonic()  # real time: since when the first target is held
        self.awaited_reader = "" if self.lockstep else str(p["start_after_reader"])
        self.log.info(f"scenario '{self.scenario.name}': {self.source.describe()}, "
                      f"{'lockstep' if self.lockstep else 'real-time'}; waiting for /joint_states")
        log_priority(self.log, priority_note, p["thread_priority"])
        self.cell_topic = CellPublisher(n)  # /dualarm/cell: what this run runs with, latched (for its bag)

    def subscribe_states(self) -> None:
        self.states = JointStates(self.node, self.profile, self.model.joint_names, self.qos, self.on_joint_state,
                                  lambda stamp, reason: self.reject(f"joint state rejected: {reason}"), self.reject,
                                  self.bus)

    def on_joint_state(self, stamp: int, q: np.ndarray, received: int) -> None:
        if self.finished:
            return
        verdict = self.gate.check(stamp)
        if verdict.message:
            self.reject(verdict.message)
        if not verdict.accepted:
            return
        if self.drive is not None:
            self.drive.q = q
        if self.stream is None:
            options = RunOptions(self.scenario.limits, self.scenario.settle_time)
            self.stream = self.source.stream(self.model, q, options, self.period)
            self.start_ns = stamp if self.lockstep else clock_ns(self.node.get_clock())
            self.held_since = time.monotonic()
            if self.drive is not None and isinstance(self.stream, GoalsStream):
                self.drive.start(self.stream.generator, self.stream.absolute)
            if self.drive is None:
                self.log.info(f"targets: {self.stream.end:.2f} s (with settle {self.scenario.settle_time:.2f} s)")
            if self.drive is None:  # segments, a plan: each part's verdict, live
                self.judge = self.source.judge(self.model, q, self.scenario.limits,
                                               self.scenario.collision_model(self.model))
        if self.lockstep:
            self.publish(stamp, stamp - self.start_ns, q)
        elif self.judge is not None and self.controller_seen is not None:  # real time: the state at its receipt
            self.outcomes(stamp, self.judge.feed((clock_ns(self.node.get_clock()) - self.start_ns) / 1e9, q))

    def reject(self, reason: str) -> None:
        """Throttled warning for an unusable input (the sample is not used)."""
        line = self.throttle.text(reason)
        if line is not None:
            self.log.warning(line)

    def on_diagnostics(self, msg: DiagnosticArray) -> None:
        """Real time, before the controller's first cycle: a controller_node status counting cycles starts
        the scenario's clock."""
        if self.controller_seen is None and any(
                s.name == "controller_node" and any(kv.key == "cycles" and kv.value not in ("", "0") for kv in s.values)
                for s in msg.status):
            self.controller_seen = time.monotonic()
            self.start_ns = clock_ns(self.node.get_clock())
            then = f"once {self.awaited_reader} reads {RELATIVE_TARGET}" if self.awaited_reader else "now"
            self.log.info(f"controller_node cycling ({self.controller_seen - self.held_since:.2f} s after the first "
                          f"target): the scenario's clock starts {then}")

    def on_tick(self) -> None:
        if self.sub_diag is not None and self.controller_seen is not None:
            self.node.destroy_subscription(self.sub_diag)  # (not destroyed in its own callback)
            self.sub_diag = None
        if self.stream is not None:
            if self.states is not None and self.drive is None and self.judge is None:  # started: the timer drives it
                self.states.close()  # (not destroyed in its own callback)
                self.states = None
            now = clock_ns(self.node.get_clock())
            if self.awaited_reader and not self.reader_arrived():  # hold: the clock starts when it reads
                self.publish(now, 0)
                self.start_ns = now
                waited = time.monotonic() - self.held_since
                if waited > CONTROLLER_NOTE_S:
                    self.reject(f"holding the first target: {self.awaited_reader} does not read {RELATIVE_TARGET} "
                                f"after {waited:.0f} s")
                return
            if self.controller_seen is None:  # hold the first target until the controller cycles
                self.publish(now, 0)
                waited = time.monotonic() - self.held_since
                if waited > CONTROLLER_NOTE_S:
                    self.reject(f"holding the first target: no controller_node cycle on /diagnostics after "
                                f"{waited:.0f} s (wait_for_controller:=false starts without one)")
                return
            self.publish(now, now - self.start_ns)

    def reader_arrived(self) -> bool:
        """Whether the node ``start_after_reader`` names subscribes /relative_target (said once when it does)."""
        if any(info.node_name == self.awaited_reader for info in self.node.get_subscriptions_info_by_topic(
                RELATIVE_TARGET)):
            self.log.info(f"{self.awaited_reader} reads {RELATIVE_TARGET}: the scenario's clock can start")
            self.awaited_reader = ""
            return True
        return False

    def outcomes(self, stamp: int, verdicts: list[GoalOutcome]) -> None:
        """Each segment's verdict in the log and on /diagnostics (a stall as WARN, naming what held the arms)."""
        for verdict in verdicts:
            stalled = verdict.state == STALLED
            if stalled:  # rclpy: one severity per call site (a shared call raised on a stall after a reach)
                self.log.warning(verdict.text())
            else:
                self.log.info(verdict.text())
            self._status(stamp, 1 if stalled else 0, verdict.text(), verdict.t)

    def publish(self, stamp: int, elapsed_ns: int, q: np.ndarray | None = None) -> None:
        assert self.stream is not None
        t = elapsed_ns / 1e9
        if self.judge is not None and q is not None:  # lockstep: the state this target answers
            self.outcomes(stamp, self.judge.feed(t, q))
        if t >= self.stream.end:  # no target at or after the end: as many cycles as the in-process run
            if self.judge is not None:
                self.outcomes(stamp, self.judge.finish())
            self.log.info(f"scenario '{self.scenario.name}' complete at t={t:.2f} s")
            self._status(stamp, 0, "complete", t)
            self.repetitions += 1
            if self.repeat:  # the next joint state plans the next run from where the arms are
                self.stream, self.stage = None, ""
                if self.states is None:
                    self.subscribe_states()
            else:
                self.finished = True  # run() stops spinning after this callback
            return
        try:
            sample = self.stream.sample(t)
        except Exception as exc:  # a live command drove ruckig into a failure: hold, do not stop the cell
            if self.drive is None:
                raise
            self.drive.recover(exc)
            sample = self.stream.sample(t)
        self.pub.publish(convert.target_message(stamp, elapsed_ns, sample.relative, sample.absolute))
        if self.pub_joint is not None and sample.joints is not None:
            self.pub_joint.publish(convert.joint_reference_message(stamp, elapsed_ns, self.model.joint_names,
                                                                   *sample.joints))
        if self.drive is not None:
            for status in self.drive.cycle(stamp):
                self.pub_diag.publish(status)
        elif sample.stage != self.stage:
            self.stage = sample.stage
            self.log.info(f"t={t:.2f} s: {sample.stage}")
            self._status(stamp, 0, sample.stage, t)

    def _status(self, stamp: int, level: int, message: str, t: float) -> None:
        values = {"scenario": self.scenario.name, "time_s": f"{t:.3f}", "duration_s": f"{self.stream_end:.3f}",
                  "repetitions": self.repetitions}
        self.pub_diag.publish(convert.diagnostics(stamp, "trajectory_node", level, message, values))

    @property
    def stream_end(self) -> float:
        return self.stream.end if self.stream is not None else 0.0


def main(args: list[str] | None = None) -> int:
    argv = list(sys.argv if args is None else args)
    # Applied to every thread (the middleware's too) once the node is built: a starved target stream
    # stops the controller (target_timeout), as `dualarm soak` showed on a loaded machine.
    request = node_scheduling(argv, DEFAULT_PRIORITY, "trajectory_node")
    return run(lambda context: TrajectoryNode(context, request.note), argv,
               usage("trajectory_node", __doc__ or "", PARAMETERS), request.granted)


if __name__ == "__main__":
    exit_process(main())
