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
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped
from rclpy.node import Node

from dualarm_control import controller as core
from dualarm_control.cell_robot import node_scenario
from dualarm_control.errors import DualArmError
from dualarm_control.hardware import profile_from_values
from dualarm_control.kinematics import DualArmModel
from dualarm_control.nodes.controller_inputs import (
    ControllerInputs,
    cycle_wrench,
    stream_sample,
)
from dualarm_control.nodes.controller_setup import (
    ALL_PARAMETERS,
    DEFAULT_PRIORITY,
    controller_params,
    run_options,
    start_text,
    with_cell_defaults,
)
from dualarm_control.nodes.controller_status import (
    CollisionLog,
    cycle_status,
    cycle_values,
)
from dualarm_control.nodes.controller_streams import subscribe_streams
from dualarm_control.nodes.startup_wait import CHECK_PERIOD_S, StartupWait
from dualarm_control.nodes.task_clock import TaskClock
from dualarm_control.references.base import WRENCH, Tracker
from dualarm_control.references.held import tuned
from dualarm_control.references.plan import PlanSource
from dualarm_control.ros import convert, inputs, local_bus, node_exit, priority
from dualarm_control.ros import node as shell
from dualarm_control.ros.cell_topic import CellPublisher
from dualarm_control.ros.hardware_check import check_graph
from dualarm_control.ros.hardware_io import (
    CommandSink,
    JointStates,
    declare_with_profile,
)
from dualarm_control.ros.obstacle_io import obstacle_intake
from dualarm_control.ros.obstacle_markers import ObstacleTopics
from dualarm_control.ros.output import CommandOutput
from dualarm_control.ros.qos import publisher_depth, stream_qos

WATCHDOG_MIN_PERIOD_S = 0.005  # the watchdog ticks at the control rate, at most 200 Hz
STATS_EVERY_S = 1.0
"""Seconds of cycles between the timing percentiles' updates (2 x 2000 samples: 0.3 ms, a deadline at 1 kHz
when it came every 200 cycles)."""
END_DELAY_S = 0.5  # task mode: spin this long after the last cycle, so that a recorder gets the last messages


class ControllerNode:
    """Node shell: parameters -> topics -> the scenario's tracker
    (:meth:`~dualarm_control.references.base.ReferenceSource.tracker`, the in-process runner's)."""

    def __init__(self, context: Any, priority_note: str = "disabled", bus: local_bus.LocalBus | None = None) -> None:
        self.node = n = Node("controller_node", context=context)
        self.log = n.get_logger()
        self.values = declare_with_profile(n, ALL_PARAMETERS)
        self.lockstep = bool(self.values["lockstep"])
        self.scenario, robot_note = node_scenario(self.values, n.get_name())
        self.values = with_cell_defaults(n, self.scenario, self.values)  # the robot's or scenario's bound
        self.log.info(robot_note)
        self.profile = profile_from_values(self.values, self.scenario.robot.joint_names, n.get_name())
        self.params = controller_params(self.scenario, self.values, n.get_name())
        self.model = m = DualArmModel(self.scenario.robot)
        # The same tracker as the in-process runner's (source.tracker): model, gain and cycle count
        source: Any = (PlanSource.from_file(m, self.values["plan"]) if self.values["plan"]
                       else self.scenario.reference)
        self.tracker: Tracker = source.tracker(m, self.params, run_options(self.scenario, self.values))
        self.timed = self.tracker.steps is not None  # tasks: t from the stamps, the run ends after its steps
        self.clock = TaskClock(self.tracker.steps or 0, self.params.period, self.lockstep,
                               int(self.values["task_start_readers"]))
        self.state: tuple[int, np.ndarray, int] | None = None  # (stamp_ns, q, received monotonic ns)
        self.last_commanded_stamp: int | None = None
        self.collision_log = CollisionLog(self.log)
        self.timing = inputs.CycleTiming(realtime=not self.lockstep)
        self.stats_every = max(2, round(STATS_EVERY_S / self.params.period))  # cycles (>= 2: refreshed at count % it == 1)
        self.completed_at: float | None = None  # task mode: monotonic s at which the duration was reached
        qos = stream_qos(self.values["qos_reliability"])
        depth = publisher_depth(self.lockstep)
        self.pub_pose = n.create_publisher(PoseStamped, "/relative_pose", depth)
        self.sink = CommandSink(n, self.profile, m.joint_names, (m.q_min, m.q_max, m.qd_max), self.params.period,
                                stream_qos(self.values["qos_reliability"], depth), bus)
        self.out = CommandOutput("controller_node", self.log, self.sink,
                                 n.create_publisher(DiagnosticArray, "/diagnostics", depth), m.nq, self.timing)
        self.out.solver = self.params.solver
        self.joint_states = JointStates(n, self.profile, m.joint_names, qos, self.on_joint_state, self.out.reject,
                                        self.on_malformed, bus)
        # What a cycle consumes besides the joint state: the reference source's streams.
        wrenches = getattr(self.tracker, "wrench_streams", (WRENCH,)) if self.tracker.uses_wrench else ()
        self.inputs = ControllerInputs(source.streams + tuple(wrenches),
                                       self.lockstep, self.out, self.log, lambda: self.values,
                                       self.joint_states.assembler, self.try_cycle)
        subscribe_streams(n, self.inputs, m, qos, bus, self.on_malformed)
        self.live = shell.LiveParameters(n, {s.name: s for s in ALL_PARAMETERS}, self.values, self.build_live)
        if hasattr(self.tracker, "retune"):  # a held object: the internal-force gains and setpoint, live
            self.tracker.retune(self.values)
        self.ticks: list[shell.Tick] = ([] if self.lockstep else  # ros.node.Ticker, not an rclpy timer
                                        [(max(self.params.period, WATCHDOG_MIN_PERIOD_S), self.on_watchdog)])
        self.startup = StartupWait(float(self.values["hardware.startup_check"]))
        if self.startup.checking:
            self.ticks.append((CHECK_PERIOD_S, self.on_startup_check))
        self.log.info(start_text(self.tracker, self.scenario.name, source.describe(), m, self.params, self.lockstep))
        priority.log_priority(self.log, priority_note, self.values["thread_priority"])
        self.cell_topic = CellPublisher(n)  # /dualarm/cell: what this run runs with, latched (for its bag)
        self.obstacles = obstacle_intake(n, self.tracker.controller, self.values)  # off the control thread
        self.scene_topic = ObstacleTopics(n, self.scenario.obstacles, self.scenario.moving_obstacles)  # latched

    def close(self) -> None:
        if self.obstacles is not None:
            self.obstacles.stop()
        self.log.info(self.out.summary())

    def build_live(self, merged: dict[str, Any]) -> core.RelativeController:
        """What a live change needs: a new controller, and for a held object's tracker the check of its
        internal-force values (ValueError refuses the change, naming the bad value)."""
        held = getattr(self.tracker, "scenario_params", None)
        if held is not None:
            tuned(held, merged)
        return core.RelativeController(self.model, controller_params(self.scenario, merged, self.node.get_name()),
                                       collision=self.tracker.controller.collision_model)

    def apply_pending(self) -> None:
        """An accepted live parameter change takes effect at the cycle boundary: the controller
        built with the new values when they were set (off the cycle) continues from the running
        one (:meth:`~dualarm_control.controller.RelativeController.continue_from`: the previous
        command, so the acceleration bound holds; the solver's memory where the solver stays; each limit's
        state: a stall's brake, the live obstacles' feed)."""
        change = self.live.take(f" at cycle {self.out.count['cycles']}")
        if change is not None:
            self.values, built = change
            # the tracker keeps its own state (tasks: the force loop) and solves with the new controller
            self.tracker.controller = built.continue_from(self.tracker.controller)
            self.params = self.tracker.controller.params
            self.out.solver = self.params.solver
            self.out.count["parameter_switches"] += 1
            if hasattr(self.tracker, "retune"):
                self.tracker.retune(self.values)

    def on_malformed(self, reason: str) -> None:
        """A sample that failed to deserialize (see :func:`subscribe_checked`): reported, dropped."""
        self.out.reject(shell.clock_ns(self.node.get_clock()), reason)

    def on_joint_state(self, stamp: int, q: np.ndarray, now: int) -> None:
        """A consistent state of both arms (:class:`JointStates`; a rejected sample is reported there and
        the last good state kept: it goes stale -> safe command)."""
        verdict = self.inputs.check_stamp("/joint_states", stamp)
        if not verdict.accepted:
            return
        if verdict.message:  # a restarted time source: its stamps start again
            self.last_commanded_stamp = None
        self.timing.arrival(now, self.params.period)
        self.state = (stamp, q, now)
        self.sink.measure(q)
        self.try_cycle()

    def try_cycle(self) -> None:
        """A cycle for the current joint state once its inputs are there (lockstep: the samples of
        its stamp; real time: the latest, fresh ones, else a safe command)."""
        if self.state is None or self.completed_at is not None:
            return
        stamp, q, received = self.state
        if stamp == self.last_commanded_stamp and (self.lockstep or self.timed):
            return
        if self.startup.checking:  # the profile is not known to match the graph yet: no motion
            if not self.lockstep:
                self.out.safe(stamp, "checking the hardware profile against the graph")
            return
        inputs = self.inputs.for_cycle(stamp)
        if inputs is None:
            return  # lockstep: a sample of this stamp is on the way; real time: a safe command was sent
        t = self.task_time(stamp) if self.timed else 0.0
        if t is None:
            return  # before the start (readers) or after the end (complete)
        if not self.lockstep:
            self.out.leave_safe_state()
        self.apply_pending()
        cycle = self.tracker.track(q, stream_sample(inputs), t, cycle_wrench(inputs))
        self.out.cycle(cycle.velocities, cycle.result)
        self.last_commanded_stamp = stamp
        latency = self.timing.command(stamp, received, self.params.period)  # state-to-command [s]
        if math.isfinite(cycle.position_error):
            local_bus.publish_if_subscribed(self.pub_pose, lambda: convert.pose_stamped(stamp, cycle.position, cycle.rotation))
        if cycle.collision is not None:
            self.collision_log.update(cycle.collision)
        timing = (None if self.timed else
                  self.timing.values(latency, refresh=self.out.count["cycles"] % self.stats_every == 1))
        values = cycle_values(self.values["scenario"], self.tracker.report(cycle, t), cycle, timing)
        self.out.status(stamp, *cycle_status(stamp, cycle, self.params.solver, self.params.period, values,
                                             self.out.counters(), self.out.watchdog_text(), self.lockstep,
                                             self.model.description.reference))

    def task_time(self, stamp: int) -> float | None:
        """A timed tracker's t [s] at ``stamp`` (:class:`TaskClock`), or None before its start (a safe
        command while it waits for the recorder's /diagnostics readers) or after its steps (complete)."""
        waiting = self.clock.waiting(self.out.pub_diag.get_subscription_count)
        if waiting:
            self.out.safe(stamp, waiting)
            return None
        t = self.clock.time(stamp)
        if t is None:
            self.complete(stamp)
        return t

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

    def on_watchdog(self) -> None:
        """Real-time mode: zero command while there is no joint state yet, or a watchdog fault
        (:meth:`ControllerInputs.watchdog`)."""
        if self.state is None:
            text, late = self.startup.waiting(self.joint_states.waiting_reason)
            stamp = shell.clock_ns(self.node.get_clock())
            (self.out.enter_safe_state if late else self.out.safe)(stamp, text)
            return
        reason = self.inputs.watchdog(time.monotonic_ns(), self.state[2])
        if reason:
            self.out.enter_safe_state(self.state[0], reason)

    def on_startup_check(self) -> None:
        """``hardware.startup_check``: commands start once the profile matches the graph; past the deadline
        the controller is refused (exit 2) with one line per problem."""
        if not self.startup.checking:
            return
        report = check_graph(self.node, self.profile, self.model.joint_names, self.joint_states.names_seen())
        if report.ok:
            self.startup.matched()
            self.log.info("hardware profile matches the graph:\n" + "\n".join(report.lines))
            if self.state is not None and self.lockstep:
                self.try_cycle()
        elif self.startup.expired:
            raise DualArmError("the hardware profile does not match the graph: " + "; ".join(report.problems))


def main(args: list[str] | None = None) -> int:
    argv = list(sys.argv if args is None else args)
    # Applied to every thread (the middleware's too) once the node is built (ros/priority.py apply_priority, called by ros/node.py run).
    request = priority.node_scheduling(argv, DEFAULT_PRIORITY, "controller_node")
    help_text = shell.usage("controller_node", __doc__ or "", ALL_PARAMETERS)
    return shell.run(lambda context: ControllerNode(context, request.note), argv, help_text, request.granted)


if __name__ == "__main__":
    node_exit.exit_process(main())
