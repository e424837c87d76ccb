"""controller_node: closed-loop relative pose control (paper 000, Fig. 3), 200 Hz by default.

Subscribes ``/joint_states`` and ``/relative_target``; publishes
``/velocity_controller/commands``, ``/relative_pose`` and ``/diagnostics`` (one per cycle).
All control math is :class:`dualarm_control.controller.RelativeController`.

Cycle (real-time mode): event-driven, read -> update -> write as ros2_control does: a
command is computed as soon as a joint state arrives. A timer at the control period, but at
most 200 Hz (one wake-up fewer per cycle at 1 kHz), is only the watchdog. Lockstep mode: one command per joint-state stamp, computed when the target with
the same stamp has arrived (no watchdog: the simulator waits for the command).

Watchdogs (real-time mode), checked on every watchdog tick and before every cycle:

* **stale joint states**: none received for more than ``stale_timeout`` (default 15 ms, 3
  periods);
* **target stream stopped mid-motion**: no ``/relative_target`` (or ``/joint_reference``)
  received for more than ``target_timeout`` (default 50 ms, 10 periods) while the last one was
  moving (a non-zero twist, or a non-zero joint reference velocity). A stream that stops with a
  target at rest (the end of a trajectory, a hold) is not a fault: the pose is held.

Either sends the safe state: a zero-velocity command every watchdog tick and /diagnostics level ERROR
(2) with the reason, logged once when it starts. The node recovers by itself at the first
cycle whose inputs are fresh again: commands resume, /diagnostics goes back to OK, the
recovery is logged once with the time spent in the safe state.

Safe behaviour (documented, docs/safety.md): an unusable message (malformed CDR, wrong,
missing or duplicate joint names, wrong counts, NaN/inf, a stamp older than the last accepted
one, a target beyond the cell's reach) is rejected with a throttled log line and a
/diagnostics entry, and the last valid input kept (a state then goes stale -> zero command);
a time source that restarted is accepted after 3 consecutive monotonic samples ("time source
restarted"); no target yet -> zero command; a solver failure gives the bounded least-squares
fallback (status "fallback", counted as ``solver_fallbacks``); a solver result beyond its
velocity bounds by more than the solver's tolerance gets the same command with status
"bounds_violated" (a failure: ERROR, counted as ``solver_failures`` and ``bounds_violations``).

Task mode (paper 001, ``scenario:=pan_cleaning``, a scenario with ``tasks``): no
``/relative_target``; every joint state drives one cycle of
:class:`~dualarm_control.references.tasks.TasksController` (the tasks at gain
``task_gain``, with ``force:=true`` the force loop of eq (9) on the latest ``/wrench``) at task
time t = joint-state stamp - first joint-state stamp (lockstep: t = k T, k the step count of
the stamps, as the in-process runner counts). /diagnostics carries per cycle the task time,
the normal offset f_F and the filtered force the cycle used (full precision, what ``dualarm
report`` needs to recompute the task values from /joint_states). The run ends after
``duration`` (0: the scenario's) of task time: the node reports "complete" and exits 0. The
target watchdog does not apply (there is no target stream); the stale-state watchdog does,
and in the force variant a /wrench older than ``stale_timeout`` is stale input too.

Live parameters: ``solver``, ``gain``, ``l1_weight``, the QP tolerances (every controller
parameter that is not read-only) can be set on the running node (``dualarm param set`` or
``ros2 param set``). A value the core refuses is refused with its reason; an accepted change
takes effect at the next cycle boundary, is logged and counted on /diagnostics.
"""

from __future__ import annotations

import sys
import time
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, WrenchStamped
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray
from trajectory_msgs.msg import JointTrajectory, MultiDOFJointTrajectory

from dualarm_control.controller import (
    CONTROLLER_PARAMETERS,
    Cycle,
    RelativeController,
    controller_params,
)
from dualarm_control.errors import DualArmError, ScenarioError
from dualarm_control.kinematics import DualArmModel
from dualarm_control.metrics import percentiles
from dualarm_control.params import ParamSpec, non_negative, positive
from dualarm_control.references.tasks import TasksController
from dualarm_control.ros import convert
from dualarm_control.ros.inputs import StampGate, Throttle, subscribe_checked
from dualarm_control.ros.node import (
    declare,
    priority_from_args,
    request_realtime_priority,
    run,
    usage,
)
from dualarm_control.ros.qos import QOS_PARAMETER, publisher_depth, stream_qos
from dualarm_control.scenario import load_scenario
from dualarm_control.solvers.base import BOUNDS_VIOLATED

NODE_PARAMETERS = (
    ParamSpec("lockstep", False, "compute one command per joint-state stamp (deterministic runs)", read_only=True),
    ParamSpec("stale_timeout", 0.015, "joint states older than this give a zero command [s] (3 periods)",
              check=positive),
    ParamSpec("target_timeout", 0.05, "no target for longer than this while the last one was moving gives a "
              "zero command [s] (10 periods, the simulator's command timeout)", check=positive),
    QOS_PARAMETER,
    ParamSpec("thread_priority", 50, "SCHED_FIFO priority of the control loop (0: normal scheduling)",
              check=lambda v: "" if 0 <= v <= 99 else "an integer in [0, 99]", read_only=True, bounds=(0, 99)),
    ParamSpec("reference", "relative", "what is tracked: the relative target (the solvers) or a planned "
              "joint trajectory on /joint_reference (qd_ref + joint_gain (q_ref - q), eq 23 bounds)",
              choices=lambda: ["relative", "joint"], read_only=True),
    ParamSpec("scenario", "", "task scenario (e.g. pan_cleaning, name or YAML path): run its tasks instead of "
              "following /relative_target ('': relative mode)", read_only=True),
    ParamSpec("task_gain", 0.0, "task mode: gain k of every task [1/s] (0: the scenario's first gain, or "
              "force.gain with force)", check=non_negative, read_only=True),
    ParamSpec("force", False, "task mode: force feedback on /wrench (eq 9)", read_only=True),
    ParamSpec("duration", 0.0, "task mode: run length [s] of task time, then exit (0: the scenario's)",
              check=non_negative, read_only=True),
    ParamSpec("task_start_readers", 0, "task mode, real time: zero commands until /diagnostics has this many "
              "readers (the launcher sets 1 when recording: the bag then holds the run from t = 0)",
              check=non_negative, read_only=True),
    ParamSpec("joint_gain", 30.0, "K of the joint-space tracking of reference:=joint [1/s]", check=positive),
)
DEFAULT_PRIORITY = 50
WATCHDOG_MIN_PERIOD_S = 0.005  # the watchdog ticks at the control rate, at most 200 Hz
WINDOW = 2000  # samples kept for jitter/latency percentiles
STATS_EVERY = 200  # cycles between percentile updates
NAN2 = (float("nan"), float("nan"))
MOVING = 1e-9  # a target twist / reference velocity norm above this is motion [m/s, rad/s]
ERROR = 2
END_DELAY_S = 0.5  # task mode: spin this long after the last cycle, so that a recorder gets the last messages


class ControllerNode:
    """Node shell around :class:`RelativeController`."""

    def __init__(self, context: Any, priority_note: str = "disabled") -> None:
        self.node = Node("controller_node", context=context)
        self.specs = {s.name: s for s in CONTROLLER_PARAMETERS + NODE_PARAMETERS}
        self.values = declare(self.node, self.specs.values())
        self.params = controller_params(self.values, self.node.get_name())
        self.lockstep = bool(self.values["lockstep"])
        self.stale_ns = int(self.values["stale_timeout"] * 1e9)
        self.target_ns = int(self.values["target_timeout"] * 1e9)
        self.task: TasksController | None = None
        self.task_gain = float("nan")
        self.task_steps = 0  # task mode: cycles to run (duration / period, rounded up)
        if self.values["scenario"]:
            self.task = self.make_task_controller()
            self.model = self.task.model
            self.controller = self.task.controller
        else:
            self.model = DualArmModel()
            self.controller = RelativeController(self.model, self.params)
        self.pending: tuple[dict[str, Any], RelativeController] | None = None
        self.order = {name: i for i, name in enumerate(self.model.joint_names)}
        n = self.node
        qos = stream_qos(self.values["qos_reliability"])
        depth = publisher_depth(self.lockstep)
        self.pub_cmd = n.create_publisher(Float64MultiArray, "/velocity_controller/commands",
                                          stream_qos(self.values["qos_reliability"], depth))
        self.pub_pose = n.create_publisher(PoseStamped, "/relative_pose", depth)
        self.pub_diag = n.create_publisher(DiagnosticArray, "/diagnostics", depth)
        self.reach = self.model.relative_reach()
        subscribe_checked(n, JointState, "/joint_states", self.on_joint_state, qos, self.on_malformed,
                          convert.JointStateInput(self.order))
        if self.task is None:
            subscribe_checked(n, MultiDOFJointTrajectory, "/relative_target", self.on_target, qos,
                              self.on_malformed, convert.TargetInput(self.reach))
        elif self.task.force:
            subscribe_checked(n, WrenchStamped, "/wrench", self.on_wrench, 10, self.on_malformed)
        self.joint_mode = self.values["reference"] == "joint"
        if self.joint_mode:
            subscribe_checked(n, JointTrajectory, "/joint_reference", self.on_joint_reference, qos, self.on_malformed)
        self.gates = {name: StampGate(name) for name in ("joint_states", "relative_target", "joint_reference",
                                                         "wrench")}
        self.joint_ref: tuple[int, np.ndarray, np.ndarray] | None = None
        self.joint_refs: dict[int, tuple[int, np.ndarray, np.ndarray]] = {}  # lockstep: by stamp
        n.add_on_set_parameters_callback(self.on_set_parameters)
        self.log = n.get_logger()
        self.state: tuple[int, np.ndarray, int] | None = None  # (stamp_ns, q, received monotonic ns)
        self.target: convert.TargetValue | None = None
        self.targets: dict[int, convert.TargetValue] = {}  # lockstep: by stamp
        self.last_commanded_stamp: int | None = None
        self.cycles = self.missed = self.failures = self.switches = self.safe_commands = 0
        self.fallbacks = self.rejected = self.bound_violations = 0
        self.target_received: int | None = None  # monotonic ns of the last valid target / joint reference
        self.fault: tuple[str, int] | None = None  # watchdog reason and monotonic ns it started
        self.trips = 0
        self.unmatched = 0  # commands published while no subscriber was matched (nobody received them)
        self.throttle = Throttle(1.0)
        self.last_arrival_ns: int | None = None
        self.interval = float("nan")  # last joint-state inter-arrival time [s]
        self.jitter: list[float] = []
        self.latency: list[float] = []
        self.stats: tuple[tuple[float, float], tuple[float, float]] = (NAN2, NAN2)
        self.first_stamp: int | None = None  # task mode: stamp of the first joint state (t = 0)
        self.wrench: tuple[int, np.ndarray, int] | None = None  # task mode: (stamp_ns, wrench, received ns)
        self.wrenches: dict[int, np.ndarray] = {}  # lockstep force variant: by stamp
        self.completed_at: float | None = None  # task mode: monotonic s at which the duration was reached
        if not self.lockstep:
            n.create_timer(max(self.params.period, WATCHDOG_MIN_PERIOD_S), self.on_watchdog)
        tracked = "joint reference" if self.joint_mode else f"solver '{self.params.solver}'"
        if self.task is not None:
            tracked += (f" on task scenario '{self.values['scenario']}' (k={self.task_gain:g}"
                        f"{', force feedback' if self.task.force else ''}, {self.task_steps} cycles)")
        self.log.info(f"{tracked} (K={self.params.gain}, T={self.params.period} s, "
                      f"{'lockstep' if self.lockstep else 'real-time, event-driven'})")
        if priority_note and priority_note != "disabled":
            self.log.warning(priority_note)
        elif not priority_note:
            self.log.info(f"running under SCHED_FIFO priority {self.values['thread_priority']}")

    def make_task_controller(self) -> TasksController:
        """Task mode: the scenario's tasks on its URDF at gain ``task_gain`` (ScenarioError -> exit 2)."""
        scenario = load_scenario(self.values["scenario"])
        if scenario.tasks is None:
            raise ScenarioError(f"controller_node.scenario: {scenario.name!r} has no tasks (a segment scenario "
                                "follows /relative_target: leave scenario empty)")
        spec, force = scenario.tasks, bool(self.values["force"])
        self.task_gain = float(self.values["task_gain"]) or (spec.force.gain if force else spec.gains[0])
        duration = float(self.values["duration"]) or spec.duration
        self.task_steps = int(np.ceil(duration / self.params.period - 1e-9))
        return TasksController(DualArmModel(scenario.urdf_path), self.params, spec, self.task_gain, force)

    def close(self) -> None:
        jp = percentiles(np.array(self.jitter)) if self.jitter else NAN2
        lp = percentiles(np.array(self.latency)) if self.latency else NAN2
        self.log.info(f"{self.cycles} cycles, {self.missed} missed deadlines, {self.failures} solver failures, "
                      f"{self.fallbacks} solver fallbacks, {self.rejected} rejected inputs, "
                      f"{self.safe_commands} safe commands, {self.unmatched} unmatched commands, "
                      f"{self.trips} watchdog trips, {self.switches} parameter switches, "
                      f"period jitter p50/p99 {jp[0] * 1e3:.3f}/{jp[1] * 1e3:.3f} ms, "
                      f"state-to-command latency p50/p99 {lp[0] * 1e3:.3f}/{lp[1] * 1e3:.3f} ms "
                      f"(last {WINDOW} cycles)")

    # --- live parameters ------------------------------------------------------------
    def on_set_parameters(self, parameters: list[Any]) -> SetParametersResult:
        """Validate a live change with the core's rules; build the new controller now, swap it in
        at the next cycle boundary. A refused change leaves the running controller untouched."""
        changes = {p.name: p.value for p in parameters if p.name in self.specs}
        if not changes:
            return SetParametersResult(successful=True)
        name = self.node.get_name()
        try:
            for key, value in changes.items():
                self.specs[key].validate(value, name)
            merged = {**self.values, **changes}
            controller = RelativeController(self.model, controller_params(merged, name))
        except (DualArmError, ValueError) as exc:
            self.log.warning(f"parameter change refused: {exc}")
            return SetParametersResult(successful=False, reason=str(exc))
        self.pending = (merged, controller)
        return SetParametersResult(successful=True)

    def apply_pending(self) -> None:
        if self.pending is None:
            return
        merged, controller = self.pending
        self.pending = None
        changed = {k: v for k, v in merged.items() if self.values.get(k) != v}
        self.values, self.controller, self.params = merged, controller, controller.params
        if self.task is not None:  # the task loop keeps its force state, solves with the new controller
            self.task.controller = controller
        self.stale_ns = int(merged["stale_timeout"] * 1e9)
        self.target_ns = int(merged["target_timeout"] * 1e9)
        self.switches += 1
        self.log.info(f"parameters changed at cycle {self.cycles}: "
                      + ", ".join(f"{k}={v!r}" for k, v in changed.items()))

    # --- inputs -----------------------------------------------------------------
    def on_malformed(self, reason: str) -> None:
        """A sample that failed to deserialize (see :func:`subscribe_checked`): reported, dropped."""
        self.reject(self.node.get_clock().now().nanoseconds, reason)

    def reject(self, stamp: int, reason: str) -> None:
        """A rejected input: counted, on /diagnostics and in the throttled log; the last valid input is kept."""
        self.rejected += 1
        self.report(stamp, reason, "input_rejected")

    def stamp_accepted(self, stream: str, stamp: int) -> bool:
        """Monotonic stamps per stream (:class:`StampGate`); a restarted time source is logged and reported."""
        verdict = self.gates[stream].check(stamp)
        if not verdict.accepted:
            self.reject(stamp, verdict.message)
        elif verdict.message:
            self.log.warning(verdict.message)
            self.report(stamp, verdict.message, "time_source_restarted")
            for pending in (self.targets, self.joint_refs):  # lockstep samples of the old time base
                for old in [s for s in pending if s > stamp]:
                    del pending[old]
            if stream == "joint_states":
                self.last_commanded_stamp = None
        return verdict.accepted

    def on_joint_state(self, sample: tuple[int, tuple[np.ndarray, np.ndarray] | str]) -> None:
        stamp, decoded = sample
        if isinstance(decoded, str):  # keep the last good state; it goes stale -> safe command
            self.reject(stamp, decoded)
            return
        if not self.stamp_accepted("joint_states", stamp):
            return
        now = time.monotonic_ns()
        self.track_arrival(now)
        self.state = (stamp, decoded[0], now)
        if self.task is not None:
            self.on_task_state()
        elif self.lockstep:
            self.try_lockstep()
        elif self.target is None:
            self.publish_safe(stamp, "waiting for relative_target")
        elif self.joint_mode and self.joint_ref is None:
            self.publish_safe(stamp, "waiting for joint_reference")
        else:
            self.cycle(self.target, self.joint_ref)

    def on_target(self, sample: tuple[int, convert.TargetValue | str]) -> None:
        stamp, value = sample
        if isinstance(value, str):
            self.reject(stamp, f"relative_target rejected: {value}")
            return
        if not self.stamp_accepted("relative_target", value.stamp_ns):
            return
        self.target = value
        self.target_received = time.monotonic_ns()
        if self.lockstep:
            self.targets[value.stamp_ns] = value
            self.try_lockstep()

    def on_joint_reference(self, msg: Any) -> None:
        value = convert.joint_reference(msg, self.order)
        if isinstance(value, str):
            self.reject(convert.stamp_ns(msg.header.stamp), f"joint_reference rejected: {value}")
            return
        if not self.stamp_accepted("joint_reference", value[0]):
            return
        self.joint_ref = value
        self.target_received = time.monotonic_ns()
        if self.lockstep:
            self.joint_refs[value[0]] = value
            self.try_lockstep()

    def on_wrench(self, msg: Any) -> None:
        """Task mode, force variant: the F/T reading at the brush (the latest one; lockstep: by stamp)."""
        value = convert.wrench_vector(msg)
        stamp = convert.stamp_ns(msg.header.stamp)
        if isinstance(value, str):
            self.reject(stamp, f"wrench rejected: {value}")
            return
        if not self.stamp_accepted("wrench", stamp):
            return
        self.wrench = (stamp, value, time.monotonic_ns())
        if self.lockstep:
            self.wrenches[stamp] = value
            self.on_task_state()

    # --- task mode (paper 001) ----------------------------------------------------
    def on_task_state(self) -> None:
        """One task cycle per joint state; lockstep: once per stamp, with the wrench of that stamp
        (force variant); real time: the latest wrench, which must be fresh."""
        assert self.task is not None and self.state is not None
        stamp = self.state[0]
        if self.completed_at is not None or stamp == self.last_commanded_stamp:
            return
        wrench = None
        if self.task.force:
            if self.lockstep:
                if stamp not in self.wrenches:
                    return  # its wrench is on the way
                wrench = self.wrenches[stamp]
                for old in [s for s in self.wrenches if s <= stamp]:
                    del self.wrenches[old]
            elif self.wrench is None:
                self.publish_safe(stamp, "waiting for wrench")
                return
            else:
                age = time.monotonic_ns() - self.wrench[2]
                if age > self.stale_ns:
                    self.enter_safe_state(stamp, f"wrench stale by {age / 1e6:.1f} ms")
                    return
                wrench = self.wrench[1]
        if self.first_stamp is None:
            readers = int(self.values["task_start_readers"])
            if not self.lockstep and self.pub_diag.get_subscription_count() < readers:
                self.publish_safe(stamp, f"waiting for {readers} /diagnostics reader(s) before the task starts")
                return
            self.first_stamp = stamp
        elapsed = stamp - self.first_stamp
        step = round(elapsed / (self.params.period * 1e9))
        if step >= self.task_steps:
            self.complete(stamp)
            return
        t = step * self.params.period if self.lockstep else elapsed * 1e-9  # lockstep: as the in-process runner
        if not self.lockstep:
            self.leave_safe_state()
        self.apply_pending()
        cycle = self.task.step(self.state[1], t, wrench)
        self.finish_cycle(stamp, cycle.velocities, cycle.result, self.state[2])
        self.publish_task_diagnostics(stamp, t, cycle)

    def complete(self, stamp: int) -> None:
        """Task time is over: report it, stop commanding (the simulator's command timeout brings the
        arms to rest) and end spinning half a second later, so that the last messages reach a recorder."""
        self.completed_at = time.monotonic()
        self.log.info(f"task scenario '{self.values['scenario']}' complete after {self.cycles} cycles")
        self.pub_diag.publish(convert.diagnostics(stamp, "controller_node", 0, "complete", {
            "solver": self.params.solver, "status": "complete", **self.counters()}))

    @property
    def finished(self) -> bool:
        """run() stops spinning once set: half a second (wall clock: sim time stops with the
        lockstep commands) after the task completed."""
        return self.completed_at is not None and time.monotonic() - self.completed_at > END_DELAY_S

    def publish_task_diagnostics(self, stamp: int, t: float, cycle: Cycle) -> None:
        """Per task cycle: status and timing, plus the cycle's task time, normal offset and filtered
        force at full precision (repr) -- with /joint_states what the report recomputes the task values from."""
        out, r = cycle, cycle.result
        level = 2 if r.failed else (1 if r.status != "solved" else 0)
        circle = next((rows for rows in out.rows if self.task is not None and self.task.circle is not None
                       and rows.name == self.task.circle.name), None)
        values = {
            "solver": self.params.solver,
            "status": r.status,
            "solve_time_s": f"{r.solve_time:.6e}",
            "cycle_time_s": repr(out.cycle_time),
            "iterations": r.iterations,
            "active_joints": r.active_joints,
            "control_period_s": self.params.period,
            "stamp_ns": stamp,
            "scenario": self.values["scenario"],
            "task_gain": repr(self.task_gain),
            "force": int(self.task is not None and self.task.force),
            "task_time_s": repr(t),
            "normal_offset_m": repr(cycle.normal_offset),
            "measured_force_n": repr(cycle.measured_force),
            "circle_error_m": f"{float(np.linalg.norm(circle.value)) if circle is not None else float('nan'):.6e}",
            **self.counters(),
            "watchdog": self.watchdog_text(),
            "mode": "lockstep" if self.lockstep else "realtime",
        }
        self.pub_diag.publish(convert.diagnostics(stamp, "controller_node", level, r.detail or r.status, values))

    # --- cycles -----------------------------------------------------------------
    def track_arrival(self, now: int) -> None:
        """Period jitter and missed periods of the joint-state stream that drives the cycle."""
        period_ns = self.params.period * 1e9
        if self.last_arrival_ns is not None and not self.lockstep:
            dt = now - self.last_arrival_ns
            self.interval = dt / 1e9
            self._keep(self.jitter, abs(dt - period_ns) / 1e9)
            if dt > 1.5 * period_ns:
                self.missed += round(dt / period_ns) - 1
        self.last_arrival_ns = now

    def try_lockstep(self) -> None:
        if self.state is None or self.state[0] == self.last_commanded_stamp:
            return
        target = self.targets.get(self.state[0])
        ref = self.joint_refs.get(self.state[0]) if self.joint_mode else None
        if target is None or (self.joint_mode and ref is None):
            return
        for old in [s for s in self.targets if s <= self.state[0]]:
            del self.targets[old]
        for old in [s for s in self.joint_refs if s <= self.state[0]]:
            del self.joint_refs[old]
        self.cycle(target, ref)

    def on_watchdog(self) -> None:
        """Real-time mode: zero command while there is no joint state yet, or a watchdog fault."""
        if self.state is None:
            self.publish_safe(self.node.get_clock().now().nanoseconds, "waiting for joint_states")
            return
        now = time.monotonic_ns()
        age = now - self.state[2]
        reason = f"joint_states stale by {age / 1e6:.1f} ms" if age > self.stale_ns else self.target_fault(now)
        if reason:
            self.enter_safe_state(self.state[0], reason)

    def target_moving(self) -> bool:
        """The last target asks for motion: non-zero twist, or non-zero joint reference velocity."""
        if self.target is None:
            return False
        twist = self.target.speed
        if self.joint_mode and self.joint_ref is not None:
            twist = max(twist, float(np.linalg.norm(self.joint_ref[2])))
        return twist > MOVING

    def target_fault(self, now: int) -> str:
        """Why the target stream counts as stopped mid-motion ('' if it does not)."""
        if self.target_received is None or not self.target_moving():
            return ""
        age = now - self.target_received
        if age <= self.target_ns:
            return ""
        name = "joint_reference" if self.joint_mode else "relative_target"
        return f"{name} stopped mid-motion: none for {age / 1e6:.1f} ms"

    def enter_safe_state(self, stamp: int, reason: str) -> None:
        """Watchdog fault: zero command, /diagnostics ERROR with the reason, logged once per fault."""
        if self.fault is None:
            self.fault = (reason, time.monotonic_ns())
            self.trips += 1
            self.log.error(f"safe state: {reason}; zero-velocity commands until the inputs return")
        self.publish_safe(stamp, reason, ERROR)

    def leave_safe_state(self) -> None:
        if self.fault is not None:
            reason, since = self.fault
            self.fault = None
            self.log.info(f"recovered after {(time.monotonic_ns() - since) / 1e9:.3f} s in the safe state "
                          f"({reason}); commands resume")

    def cycle(self, target: convert.TargetValue, ref: tuple[int, np.ndarray, np.ndarray] | None = None) -> None:
        assert self.state is not None
        if not self.lockstep:
            reason = self.target_fault(time.monotonic_ns())
            if reason:
                self.enter_safe_state(self.state[0], reason)
                return
            self.leave_safe_state()
        self.apply_pending()
        stamp, q, received = self.state
        if ref is not None:
            out = self.controller.track_joints(q, ref[1], ref[2], target, self.values["joint_gain"])
        else:
            out = self.controller.step(q, target)
        latency = self.finish_cycle(stamp, out.velocities, out.result, received)
        if np.all(np.isfinite(out.position)):
            self.pub_pose.publish(convert.pose_stamped(stamp, out.position, out.rotation))
        self.publish_diagnostics(stamp, out, latency)

    def finish_cycle(self, stamp: int, velocities: np.ndarray, result: Any, received: int) -> float:
        """Send a cycle's command and count it; returns the state-to-command latency [s]."""
        self.send_command(velocities)
        # Real time: from the state's stamp (its publication, wall clock) to the command's
        # publication, transport included. Lockstep stamps are simulation time: from receipt.
        latency = (time.monotonic_ns() - received if self.lockstep else time.time_ns() - stamp) / 1e9
        self._keep(self.latency, latency)
        if not self.lockstep and latency > self.params.period:
            self.missed += 1
        self.last_commanded_stamp = stamp
        self.cycles += 1
        if result.failed:
            self.failures += 1
            self.bound_violations += result.status == BOUNDS_VIOLATED
            self.warn(f"solver {result.status}: {result.detail}; safe command sent")
        elif result.fell_back:
            self.fallbacks += 1
            self.warn(f"solver fallback: {result.detail}")
        return latency

    def publish_safe(self, stamp: int, reason: str, level: int = 1) -> None:
        """Zero-velocity command with the reason on /diagnostics (``level``) and in the (throttled) log."""
        self.send_command(np.zeros(self.model.nq))
        self.safe_commands += 1
        self.report(stamp, reason, "safe_command", level)

    def send_command(self, velocities: np.ndarray) -> None:
        self.pub_cmd.publish(convert.float_array(velocities))
        if self.pub_cmd.get_subscription_count() == 0:
            self.unmatched += 1

    def warn(self, text: str) -> None:
        """Log at most once a second (with the count of suppressed lines)."""
        line = self.throttle.text(text)
        if line is not None:
            self.log.warning(line)

    def report(self, stamp: int, reason: str, status: str, level: int = 1) -> None:
        """Reason on /diagnostics (every time, WARN unless ``level`` says otherwise) and in the log
        (throttled), with the counters that account for every command sent."""
        self.warn(f"{status}: {reason}")
        self.pub_diag.publish(convert.diagnostics(stamp, "controller_node", level, reason, {
            "solver": self.params.solver, "status": status, "watchdog": self.watchdog_text(), **self.counters()}))

    def watchdog_text(self) -> str:
        return "ok" if self.fault is None else self.fault[0]

    def counters(self) -> dict[str, int]:
        """Cumulative counts: ``cycles + safe_commands`` is every command this node has published,
        ``unmatched_commands`` of them while no subscriber was matched."""
        return {"cycles": self.cycles, "safe_commands": self.safe_commands, "unmatched_commands": self.unmatched,
                "watchdog_trips": self.trips, "missed_deadlines": self.missed, "solver_failures": self.failures,
                "solver_fallbacks": self.fallbacks, "rejected_inputs": self.rejected,
                "bounds_violations": self.bound_violations}

    def publish_diagnostics(self, stamp: int, out: Cycle, latency: float) -> None:
        r = out.result
        level = 2 if r.failed else (1 if r.status != "solved" else 0)
        if self.cycles % STATS_EVERY == 1:  # percentiles once a second, not every cycle
            self.stats = (percentiles(np.array(self.jitter)) if self.jitter else NAN2,
                          percentiles(np.array(self.latency)))
        jit, lat = self.stats
        values = {
            "solver": "joint_tracking" if self.joint_mode else self.params.solver,
            "status": r.status,
            "solve_time_s": f"{r.solve_time:.6e}",
            "cycle_time_s": f"{out.cycle_time:.6e}",
            "iterations": r.iterations,
            "active_joints": r.active_joints,
            "position_error_m": f"{out.position_error:.6e}",
            "orientation_error_rad": f"{out.orientation_error:.6e}",
            "control_period_s": self.params.period,
            "stamp_ns": stamp,
            **self.counters(),
            "watchdog": self.watchdog_text(),
            "parameter_switches": self.switches,
            "period_jitter_p50_s": f"{jit[0]:.6e}",
            "period_jitter_p99_s": f"{jit[1]:.6e}",
            "state_interval_s": f"{self.interval:.6e}",
            "state_to_command_latency_s": f"{latency:.6e}",
            "state_to_command_latency_p50_s": f"{lat[0]:.6e}",
            "state_to_command_latency_p99_s": f"{lat[1]:.6e}",
            "mode": "lockstep" if self.lockstep else "realtime",
        }
        self.pub_diag.publish(convert.diagnostics(stamp, "controller_node", level, r.detail or r.status, values))

    @staticmethod
    def _keep(buffer: list[float], value: float) -> None:
        buffer.append(value)
        if len(buffer) > WINDOW:
            del buffer[: len(buffer) - WINDOW]


def main(args: list[str] | None = None) -> int:
    argv = list(sys.argv if args is None else args)
    # Applied to every thread (the middleware's too) once the node is built (ros/node.py).
    why_not = request_realtime_priority(priority_from_args(argv, DEFAULT_PRIORITY, "controller_node"))
    help_text = usage("controller_node", __doc__ or "", CONTROLLER_PARAMETERS + NODE_PARAMETERS)
    return run(lambda context: ControllerNode(context, why_not), argv, help_text)


if __name__ == "__main__":
    raise SystemExit(main())
