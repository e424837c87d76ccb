"""controller_node: closed-loop control of the cell (paper 000, Fig. 3), 200 Hz by default.

Runs the scenario's tracker (``scenario``, on its robot or ``robot``): the one the in-process
runner runs, with the same model, gain and cycle count (``ReferenceSource.tracker``). Subscribes
``/joint_states`` and the streams of what it follows: ``/relative_target`` (segments, goals),
also a planned joint trajectory on ``/joint_reference`` (``plan:=FILE``: qd_ref + K (q_ref - q),
K the plan's execution.gain, eq 23 bounds), or none for the tasks of a task scenario
(``scenario:=pan_cleaning``, paper 001; ``/wrench`` with ``force:=true``, eq 9). Publishes
``/velocity_controller/commands`` (the default hardware profile: ``hardware.*`` gives the command
outputs and the joint-state topics, docs/hardware.md) and ``/diagnostics`` (one per cycle), and ``/relative_pose``
every cycle while it has a reader. The control math is the core's.

Real time: a command per joint state (read -> update -> write, as ros2_control); a tick at the
control period (at most 200 Hz) is the watchdog. Lockstep: one command per joint-state stamp,
once every stream's sample of that stamp has arrived. Watchdogs (real time, docs/safety.md):
joint states (with force: a /wrench) older than ``stale_timeout``; a target stream silent for
``target_timeout`` while its last sample asked for motion (one that stops at rest is no fault).
Either gives the safe state: zero commands, /diagnostics ERROR with the reason, logged once;
the node recovers at the first cycle with fresh inputs. Rejected inputs (malformed, wrong
joints, NaN/inf, an older stamp, a target beyond reach) are logged (throttled), counted and on
/diagnostics; the last valid one is kept; a restarted time source is accepted after 3 samples.
A solver failure gives the bounded least-squares fallback; a result beyond its velocity bounds
is "bounds_violated" (ERROR, counted as ``solver_failures`` and ``bounds_violations``).

Task mode: t = joint-state stamp - first stamp (lockstep: t = k T, as the in-process runner);
/diagnostics carries t, the normal offset and the filtered force at full precision (``dualarm
report`` recomputes the task values from them); after ``duration`` it reports "complete", exits 0.
Live parameters (those not read-only: ``solver``, ``gain``, ...): a value the core refuses is
refused with its reason; an accepted one takes effect at the next cycle, logged and counted, and
the controller keeps its state across it (the previous command: the acceleration bound holds; the
solver's warm start and proximal memory while the solver stays the same).
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, WrenchStamped
from rclpy.node import Node
from trajectory_msgs.msg import JointTrajectory, MultiDOFJointTrajectory

from dualarm_control import controller as core
from dualarm_control.errors import DualArmError, InputRejected
from dualarm_control.hardware import HARDWARE_PARAMETERS, profile_from_values
from dualarm_control.kinematics import DualArmModel
from dualarm_control.limits.collision import CollisionReport
from dualarm_control.params import ParamSpec, non_negative, positive
from dualarm_control.references.base import (
    JOINT_REFERENCE,
    RELATIVE_TARGET,
    WRENCH,
    RunOptions,
    StreamSample,
    Tracker,
)
from dualarm_control.references.plan import PlanSource
from dualarm_control.ros import convert, inputs, local_bus
from dualarm_control.ros import node as shell
from dualarm_control.ros.cell_topic import CellPublisher
from dualarm_control.ros.hardware_check import check_graph
from dualarm_control.ros.hardware_io import (
    CommandSink,
    JointStates,
    declare_with_profile,
)
from dualarm_control.ros.output import CommandOutput
from dualarm_control.ros.qos import QOS_PARAMETER, publisher_depth, stream_qos
from dualarm_control.scenario import ROBOT_PARAMETER, load_scenario
from dualarm_control.status import Status

DEFAULT_PRIORITY = 50
WATCHDOG_MIN_PERIOD_S = 0.005  # the watchdog ticks at the control rate, at most 200 Hz
STATS_EVERY = 200  # cycles between percentile updates
MOVING = 1e-9  # a target twist / reference velocity norm above this is motion [m/s, rad/s]
STARTUP_WAIT_S = 10.0  # real time: no consistent joint state this long after the start (no startup_check) is an ERROR
CHECK_PERIOD_S = 0.1  # hardware.startup_check: the graph is checked this often until it matches
END_DELAY_S = 0.5  # task mode: spin this long after the last cycle, so that a recorder gets the last messages
NODE_PARAMETERS = (
    ParamSpec("lockstep", False, "compute one command per joint-state stamp (deterministic runs)", read_only=True),
    ParamSpec("stale_timeout", 0.015, "joint states older than this give a zero command [s] (3 periods)",
              check=positive),
    ParamSpec("target_timeout", 0.05, "no target for longer than this while the last one was moving gives a "
              "zero command [s] (10 periods, the simulator's command timeout)", check=positive),
    QOS_PARAMETER,
    shell.thread_priority_spec(DEFAULT_PRIORITY, "the control loop"),
    ParamSpec("scenario", "assembly", "scenario (name or YAML path): its robot and what a cycle tracks, as the "
              "in-process runner (relative targets on /relative_target; a task scenario such as pan_cleaning: "
              "its tasks)", read_only=True),
    ParamSpec("plan", "", "plan.json of `dualarm plan`: track its joint trajectory on /joint_reference "
              "(qd_ref + K (q_ref - q), K = the plan's execution.gain, eq 23 bounds)", read_only=True),
    ParamSpec("task_gain", 0.0, "task mode: gain k of every task [1/s] (0: the scenario's first gain, or "
              "force.gain with force)", check=non_negative, read_only=True),
    ParamSpec("force", False, "task mode: force feedback on /wrench (eq 9)", read_only=True),
    ParamSpec("duration", 0.0, "task mode: run length [s] of task time, then exit (0: the scenario's)",
              check=non_negative, read_only=True),
    ParamSpec("task_start_readers", 0, "task mode, real time: zero commands until /diagnostics has this many "
              "readers (the launcher sets 1 when recording: the bag then holds the run from t = 0)",
              check=non_negative, read_only=True),
    ROBOT_PARAMETER,
    *HARDWARE_PARAMETERS,
)
ALL_PARAMETERS = core.CONTROLLER_PARAMETERS + NODE_PARAMETERS


class ControllerNode:
    """Node shell: parameters -> topics -> the scenario's tracker
    (:meth:`~dualarm_control.references.base.ReferenceSource.tracker`, the in-process runner's)."""

    def __init__(self, context: Any, priority_note: str = "disabled", bus: local_bus.LocalBus | None = None) -> None:
        self.node = n = Node("controller_node", context=context)
        self.log = n.get_logger()
        self.values = declare_with_profile(n, ALL_PARAMETERS)
        self.lockstep = bool(self.values["lockstep"])
        self.scenario = load_scenario(self.values["scenario"], self.values["robot"])
        self.profile = profile_from_values(self.values, self.scenario.robot.joint_names, n.get_name())
        # the parameters, with the scenario's allowed contacts (the assembly's tools) in the collision limit
        self.params = self.scenario.controller_params(core.controller_params(self.values, n.get_name()))
        self.model = DualArmModel(self.scenario.robot)
        self.robot_ref = self.model.description.reference
        # The same tracker as the in-process runner's (source.tracker): model, gain and cycle count
        source: Any = (PlanSource.from_file(self.model, self.values["plan"]) if self.values["plan"]
                       else self.scenario.reference)
        self.tracker: Tracker = source.tracker(self.model, self.params, self.run_options())
        self.timed = self.tracker.steps is not None  # tasks: t from the stamps, the run ends after its steps
        # What a cycle consumes besides the joint state: the reference source's streams.
        self.streams: tuple[str, ...] = source.streams + ((WRENCH,) if self.tracker.uses_wrench else ())
        self.inputs = inputs.StreamInputs(self.streams, self.lockstep)
        self.state: tuple[int, np.ndarray, int] | None = None  # (stamp_ns, q, received monotonic ns)
        self.last_commanded_stamp: int | None = None
        self.collision_active = False
        self.timing = inputs.CycleTiming(realtime=not self.lockstep)
        self.first_stamp: int | None = None  # task mode: stamp of the first joint state (t = 0)
        self.completed_at: float | None = None  # task mode: monotonic s at which the duration was reached
        qos = stream_qos(self.values["qos_reliability"])
        depth = publisher_depth(self.lockstep)
        self.pub_pose = n.create_publisher(PoseStamped, "/relative_pose", depth)
        m = self.model
        self.sink = CommandSink(n, self.profile, m.joint_names, (m.q_min, m.q_max, m.qd_max), self.params.period,
                                stream_qos(self.values["qos_reliability"], depth), bus)
        self.out = CommandOutput("controller_node", self.log, self.sink,
                                 n.create_publisher(DiagnosticArray, "/diagnostics", depth), self.model.nq, self.timing)
        self.out.solver = self.params.solver
        order = {name: i for i, name in enumerate(self.model.joint_names)}

        def subscribe(msg_type: Any, topic: str, callback: Any, qos: Any, decoder: Any = None) -> None:
            inputs.subscribe_checked(n, msg_type, topic, callback, qos, self.on_malformed, decoder, bus,
                                     lambda exc: self.on_rejected(topic, exc))

        self.joint_states = JointStates(n, self.profile, m.joint_names, qos, self.on_joint_state, self.out.reject,
                                        self.on_malformed, bus)
        if RELATIVE_TARGET in self.streams:
            subscribe(MultiDOFJointTrajectory, RELATIVE_TARGET, lambda s: self.on_input(RELATIVE_TARGET, *s),
                      qos, convert.TargetInput(self.model.relative_reach()))
        if JOINT_REFERENCE in self.streams:
            subscribe(JointTrajectory, JOINT_REFERENCE,
                      self.message_input(JOINT_REFERENCE, lambda msg: convert.joint_reference(msg, order)), qos)
        if WRENCH in self.streams:
            subscribe(WrenchStamped, WRENCH, self.message_input(WRENCH, convert.wrench_vector), 10)
        self.live = shell.LiveParameters(n, {s.name: s for s in ALL_PARAMETERS}, self.values, lambda merged: (
            core.RelativeController(self.model, self.scenario.controller_params(core.controller_params(merged, n.get_name())),
                                    collision=self.tracker.controller.collision_model)))
        self.ticks: list[shell.Tick] = ([] if self.lockstep else  # ros.node.Ticker, not an rclpy timer
                                        [(max(self.params.period, WATCHDOG_MIN_PERIOD_S), self.on_watchdog)])
        check_s = float(self.values["hardware.startup_check"])
        self.started, self.wait_next, self.wait_text = time.monotonic(), 0.0, "waiting for joint_states"
        self.wait_deadline = check_s or STARTUP_WAIT_S  # no consistent joint state by then: ERROR
        self.check_deadline = time.monotonic() + check_s if check_s > 0 else None  # None: checked (or no check)
        if self.check_deadline is not None:
            self.ticks.append((CHECK_PERIOD_S, self.on_startup_check))
        self.log.info(f"{self.tracker.label} on scenario '{self.scenario.name}' ({source.describe()}"
                      f"{f', {self.tracker.steps} cycles' if self.timed else ''}), robot '{self.model.description.name}'"
                      f" ({self.model.nq} joints), solver '{self.params.solver}' (K={self.params.gain}, "
                      f"T={self.params.period} s, {'lockstep' if self.lockstep else 'real-time, event-driven'}), "
                      f"{acceleration_text(self.params.acceleration_limit)}")
        shell.log_priority(self.log, priority_note, self.values["thread_priority"])
        self.cell_topic = CellPublisher(n)  # /dualarm/cell: what this run runs with, latched (for its bag)

    def run_options(self) -> RunOptions:
        """The run options of the scenario and the task parameters (0: the scenario's)."""
        v = self.values
        return RunOptions(self.scenario.limits, self.scenario.settle_time, float(v["task_gain"]) or None,
                          bool(v["force"]), float(v["duration"]) or None)

    @property
    def controller(self) -> core.RelativeController:
        return self.tracker.controller

    def close(self) -> None:
        self.log.info(self.out.summary())

    def apply_pending(self) -> None:
        """An accepted live parameter change takes effect at the cycle boundary: the controller
        built with the new values when they were set (off the cycle) continues from the running
        one (:meth:`~dualarm_control.controller.RelativeController.continue_from`: the previous
        command, so the acceleration bound holds; the solver's memory where the solver stays)."""
        change = self.live.take(f" at cycle {self.out.count['cycles']}")
        if change is not None:
            self.values, built = change
            # the tracker keeps its own state (tasks: the force loop) and solves with the new controller
            self.tracker.controller = built.continue_from(self.controller)
            self.params = self.controller.params
            self.out.solver = self.params.solver
            self.out.count["parameter_switches"] += 1

    def on_malformed(self, reason: str) -> None:
        """A sample that failed to deserialize (see :func:`subscribe_checked`): reported, dropped."""
        self.out.reject(self.node.get_clock().now().nanoseconds, reason)

    def stamp_accepted(self, stream: str, stamp: int) -> bool:
        """Monotonic stamps per stream (:class:`StampGate`); a restarted time source is logged and reported."""
        verdict = self.inputs.check(stream, stamp)
        if not verdict.accepted:
            self.out.reject(stamp, verdict.message)
        elif verdict.message:
            self.log.warning(verdict.message)
            self.out.report(stamp, verdict.message, "time_source_restarted")
            if stream == "/joint_states":
                self.last_commanded_stamp = None
        return verdict.accepted

    def on_joint_state(self, stamp: int, q: np.ndarray, now: int) -> None:
        """A consistent state of both arms (:class:`JointStates`; a rejected sample is reported there and
        the last good state kept: it goes stale -> safe command)."""
        if not self.stamp_accepted("/joint_states", stamp):
            return
        self.timing.arrival(now, self.params.period)
        self.state = (stamp, q, now)
        self.sink.measure(q)
        self.try_cycle()

    def message_input(self, stream: str, decode: Callable[[Any], Any]) -> Callable[[Any], None]:
        """The callback of a stream read from the rclpy message: ``decode(msg)`` at the header's stamp to
        :meth:`on_input`, or its rejection (:class:`InputRejected`) to :meth:`on_rejected`."""
        def receive(msg: Any) -> None:
            try:
                value = decode(msg)
            except InputRejected as exc:
                self.on_rejected(stream, exc)
            else:
                self.on_input(stream, convert.stamp_ns(msg.header.stamp), value)
        return receive

    def on_rejected(self, stream: str, exc: InputRejected) -> None:
        """A sample of one of the source's streams that its decoder rejected: counted and reported at its stamp."""
        self.out.reject(exc.stamp or 0, f"{stream.lstrip('/')} rejected: {exc.reason}")

    def on_input(self, stream: str, stamp: int, value: Any) -> None:
        """A sample of one of the source's streams; lockstep: it may complete a cycle."""
        if self.stamp_accepted(stream, stamp):
            self.inputs.put(stream, stamp, value)
            if self.lockstep:
                self.try_cycle()

    def try_cycle(self) -> None:
        """A cycle for the current joint state once its inputs are there (lockstep: the samples of
        its stamp; real time: the latest, fresh ones, else a safe command)."""
        if self.state is None or self.completed_at is not None:
            return
        stamp, q, _ = self.state
        if stamp == self.last_commanded_stamp and (self.lockstep or self.timed):
            return
        if self.check_deadline is not None:  # the profile is not known to match the graph yet: no motion
            if not self.lockstep:
                self.out.safe(stamp, "checking the hardware profile against the graph")
            return
        inputs = self.inputs.at(stamp) if self.lockstep else self.fresh_inputs(stamp)
        if inputs is None:
            return  # lockstep: a sample of this stamp is on the way; real time: a safe command was sent
        t = self.task_time(stamp) if self.timed else 0.0
        if t is None:
            return  # before the start (readers) or after the end (complete)
        if not self.lockstep:
            self.out.leave_safe_state()
        self.apply_pending()
        ref = inputs.get(JOINT_REFERENCE)
        sample = (StreamSample(inputs[RELATIVE_TARGET], (ref[1], ref[2]) if ref is not None else None, "")
                  if RELATIVE_TARGET in inputs else None)
        cycle = self.tracker.track(q, sample, t, inputs.get(WRENCH))
        latency = self.finish_cycle(cycle)
        if math.isfinite(cycle.position_error):
            local_bus.publish_if_subscribed(self.pub_pose, lambda: convert.pose_stamped(stamp, cycle.position, cycle.rotation))
        extra = {"scenario": self.values["scenario"], **self.tracker.report(cycle, t)}
        for report in cycle.reports.values():  # every limit's, by name (docs/limits.md)
            extra.update(report.values())
        if cycle.collision is not None:
            self.log_collision(cycle.collision)
        if not self.timed:
            extra.update(self.timing.values(latency, refresh=self.out.count["cycles"] % STATS_EVERY == 1))
        self.publish_cycle(stamp, cycle, self.params.solver, extra)

    def log_collision(self, report: CollisionReport) -> None:
        """One log line when the collision limit starts holding a pair at its bound, one when it lets go."""
        active = report.active > 0
        if active != self.collision_active:
            self.collision_active = active
            if active:
                self.log.warning(f"collision constraint active: {report.text()}")
            else:
                self.log.info("collision constraint released")

    def fresh_inputs(self, stamp: int) -> dict[str, Any] | None:
        """Real time: the latest sample of every stream, or None after a safe command (none yet,
        a stale wrench, a target stream stopped mid-motion)."""
        sample = {}
        for stream in self.streams:
            if stream not in self.inputs.latest:
                self.out.safe(stamp, f"waiting for {stream.lstrip('/')}")
                return None
            value, received = self.inputs.latest[stream]
            age = time.monotonic_ns() - received
            if stream == WRENCH and age > self.values["stale_timeout"] * 1e9:
                self.out.enter_safe_state(stamp, f"wrench stale by {age / 1e6:.1f} ms")
                return None
            sample[stream] = value
        reason = self.target_fault(time.monotonic_ns())
        if reason:
            self.out.enter_safe_state(stamp, reason)
            return None
        return sample

    def task_time(self, stamp: int) -> float | None:
        """A timed tracker's t [s] at ``stamp`` (lockstep: k T, as the in-process runner), or None
        before its start (waiting for the recorder's /diagnostics readers) or after its steps."""
        assert self.tracker.steps is not None
        if self.first_stamp is None:
            readers = int(self.values["task_start_readers"])
            if not self.lockstep and self.out.pub_diag.get_subscription_count() < readers:
                self.out.safe(stamp, f"waiting for {readers} /diagnostics reader(s) before the task starts")
                return None
            self.first_stamp = stamp
        elapsed = stamp - self.first_stamp
        step = round(elapsed / (self.params.period * 1e9))
        if step >= self.tracker.steps:
            self.complete(stamp)
            return None
        return step * self.params.period if self.lockstep else elapsed * 1e-9

    def complete(self, stamp: int) -> None:
        """Task time is over: report it, stop commanding (the simulator's command timeout brings the
        arms to rest) and end spinning half a second later, so that the last messages reach a recorder."""
        self.completed_at = time.monotonic()
        self.log.info(f"task scenario '{self.values['scenario']}' complete after {self.out.count['cycles']} cycles")
        self.out.status(stamp, 0, "complete", {"solver": self.params.solver, "status": "complete",
                                               **self.out.counters()})

    @property
    def finished(self) -> bool:
        """run() stops spinning half a second (wall clock) after the task completed."""
        return self.completed_at is not None and time.monotonic() - self.completed_at > END_DELAY_S

    def finish_cycle(self, cycle: core.Cycle) -> float:
        """Send a cycle's command and count it; returns the state-to-command latency [s]."""
        assert self.state is not None
        stamp, _, received = self.state
        self.out.cycle(cycle.velocities, cycle.result)
        self.last_commanded_stamp = stamp
        return self.timing.command(stamp, received, self.params.period)

    def publish_cycle(self, stamp: int, cycle: core.Cycle, solver: str, extra: dict[str, Any]) -> None:
        """The cycle's /diagnostics: status, solver figures, counters and the mode's ``extra`` values."""
        r = cycle.result
        self.out.status(stamp, 2 if r.failed else int(r.status != Status.SOLVED), r.detail or r.status, {
            "solver": solver, "status": r.status, "solve_time_s": f"{r.solve_time:.6e}",
            "iterations": r.iterations, "active_joints": r.active_joints, "control_period_s": self.params.period,
            "stamp_ns": stamp, **extra, **self.out.counters(), "watchdog": self.out.watchdog_text(),
            "mode": "lockstep" if self.lockstep else "realtime", "robot": self.robot_ref})

    def on_watchdog(self) -> None:
        """Real-time mode: zero command while there is no joint state yet, or a watchdog fault."""
        if self.state is None:
            self.wait_for_state()
            return
        now = time.monotonic_ns()
        age = now - self.state[2]
        timeout = self.values["stale_timeout"] * 1e9
        reason = ((self.stale_topics(now, timeout) or f"joint_states stale by {age / 1e6:.1f} ms") if age > timeout
                  else self.target_fault(now))
        if reason:
            self.out.enter_safe_state(self.state[0], reason)

    def wait_for_state(self) -> None:
        """Real time, no consistent joint state yet: a zero command every tick with why it waits (the
        joint-state topics' publishers, deliveries, refusals, missing joints, stamps; looked up once a
        second), WARN on /diagnostics and in the log; ERROR (the safe state) past ``hardware.startup_check``
        or :data:`STARTUP_WAIT_S`."""
        now = time.monotonic()
        if now >= self.wait_next:
            self.wait_next = now + 1.0
            cause = self.joint_states.waiting_reason()
            self.wait_text = f"waiting for joint_states{f': {cause}' if cause else ''}"
        stamp = self.node.get_clock().now().nanoseconds
        if now - self.started > self.wait_deadline:
            self.out.enter_safe_state(stamp, f"{self.wait_text} (none consistent after {self.wait_deadline:g} s)")
        else:
            self.out.safe(stamp, self.wait_text)

    def on_startup_check(self) -> None:
        """``hardware.startup_check``: commands start once the profile matches the graph; past the deadline
        the controller is refused (exit 2) with one line per problem."""
        if self.check_deadline is None:
            return
        report = check_graph(self.node, self.profile, self.model.joint_names, self.joint_states.names_seen())
        if report.ok:
            self.check_deadline = None
            self.log.info("hardware profile matches the graph:\n" + "\n".join(report.lines))
            if self.state is not None and self.lockstep:
                self.try_cycle()
        elif time.monotonic() > self.check_deadline:
            raise DualArmError("the hardware profile does not match the graph: " + "; ".join(report.problems))

    def stale_topics(self, now: int, timeout: float) -> str:
        """Several joint-state topics: which one is stale (the arm it carries), or their stamps beyond the
        tolerance ('' with one topic: today's reason)."""
        assembler = self.joint_states.assembler
        return assembler.stale_reason(now, timeout) if len(assembler.topics) > 1 else ""

    def target_fault(self, now: int) -> str:
        """Why the target streams count as stopped mid-motion ('' if they do not): their last sample
        is older than ``target_timeout`` and asked for motion (a non-zero twist or joint reference velocity)."""
        latest = self.inputs.latest
        if RELATIVE_TARGET not in latest:
            return ""
        speed = latest[RELATIVE_TARGET][0].speed
        if JOINT_REFERENCE in latest:
            speed = max(speed, float(np.linalg.norm(latest[JOINT_REFERENCE][0][2])))
        age = now - max(latest[s][1] for s in (RELATIVE_TARGET, JOINT_REFERENCE) if s in latest)
        if speed <= MOVING or age <= self.values["target_timeout"] * 1e9:
            return ""
        return f"{self.streams[-1].lstrip('/')} stopped mid-motion: none for {age / 1e6:.1f} ms"


def acceleration_text(limit: tuple[float, ...]) -> str:
    """The start log's words for the joint acceleration bound (``acceleration_limit``) the run uses."""
    if not limit:
        return "no joint acceleration bound (acceleration_limit: [0.0])"
    values = "/".join(f"{a:g}" for a in limit)
    return f"joint acceleration bound {values} rad/s^2" + (" on every joint" if len(limit) == 1 else " per joint")


def main(args: list[str] | None = None) -> int:
    argv = list(sys.argv if args is None else args)
    # Applied to every thread (the middleware's too) once the node is built (ros/node.py).
    request = shell.request_realtime_priority(shell.priority_from_args(argv, DEFAULT_PRIORITY, "controller_node"))
    help_text = shell.usage("controller_node", __doc__ or "", ALL_PARAMETERS)
    return shell.run(lambda context: ControllerNode(context, request.note), argv, help_text, request.granted)


if __name__ == "__main__":
    raise SystemExit(main())
