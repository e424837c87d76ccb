"""controller_node: closed-loop relative pose control at 200 Hz (paper 000, Fig. 3).

Subscribes ``/joint_states`` and ``/relative_target``; publishes
``/velocity_controller/commands``, ``/relative_pose`` and ``/diagnostics`` (one per cycle).
All control math is :class:`dualarm_control.controller.RelativeController`.

Safe behaviour (documented): no joint state yet, a stale one (older than ``stale_timeout``),
an unusable message (wrong joint count, NaN) or no target yet -> a zero-velocity command,
with the reason in /diagnostics and the log. Solver failures give the solver's safe command.

Real-time mode: a drift-free timer; jitter, missed deadlines and state-to-command latency
are measured and reported. Lockstep mode: one command per joint-state stamp, computed when
the target with the same stamp has arrived.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from dualarm_control import ros
from dualarm_control.controller import (
    CONTROLLER_PARAMETERS,
    ControlOutput,
    RelativeController,
    controller_params,
)
from dualarm_control.kinematics import DualArmModel
from dualarm_control.metrics import percentiles
from dualarm_control.nodes.common import declare, request_realtime_priority, run_node
from dualarm_control.params import ParamSpec, positive
from dualarm_control.ros import convert

NODE_PARAMETERS = (
    ParamSpec("lockstep", False, "compute one command per joint-state stamp (deterministic runs)"),
    ParamSpec("stale_timeout", 0.05, "joint states older than this give a zero command [s]", check=positive),
    ParamSpec("thread_priority", 50, "SCHED_FIFO priority of the control loop (0: normal scheduling)",
              check=lambda v: "" if 0 <= v <= 99 else "an integer in [0, 99]"),
)
DEFAULT_PRIORITY = 50
WINDOW = 2000  # samples kept for jitter/latency percentiles
STATS_EVERY = 200  # cycles between percentile updates


class ControllerNode:
    """Node shell around :class:`RelativeController`."""

    def __init__(self, priority_note: str = "disabled") -> None:
        self.node = ros.Node("controller_node")
        values = declare(self.node, CONTROLLER_PARAMETERS + NODE_PARAMETERS)
        self.params = controller_params(values, self.node.get_name())
        self.lockstep = bool(values["lockstep"])
        self.stale_ns = int(values["stale_timeout"] * 1e9)
        self.model = DualArmModel()
        self.controller = RelativeController(self.model, self.params)
        self.order = {name: i for i, name in enumerate(self.model.joint_names)}
        n = self.node
        self.pub_cmd = n.create_publisher(ros.msgs.Float64MultiArray, "/velocity_controller/commands", 10)
        self.pub_pose = n.create_publisher(ros.msgs.PoseStamped, "/relative_pose", 10)
        self.pub_diag = n.create_publisher(ros.msgs.DiagnosticArray, "/diagnostics", 10)
        n.create_subscription(ros.msgs.JointState, "/joint_states", self.on_joint_state, 10)
        n.create_subscription(ros.msgs.MultiDOFJointTrajectory, "/relative_target", self.on_target, 10)
        self.log = n.get_logger()
        self.state: tuple[int, np.ndarray, int] | None = None  # (stamp_ns, q, received monotonic ns)
        self.target: convert.TargetValue | None = None
        self.targets: dict[int, convert.TargetValue] = {}  # lockstep: by stamp
        self.last_commanded_stamp: int | None = None
        self.cycles = 0
        self.last_warning = 0.0
        self.missed = 0
        self.failures = 0
        self.last_tick_ns: int | None = None
        self.jitter: list[float] = []
        self.latency: list[float] = []
        self.stats: tuple[tuple[float, ...], tuple[float, ...]] = ((float("nan"),) * 2, (float("nan"),) * 2)
        if not self.lockstep:
            n.create_timer(self.params.period, self.on_tick)
        self.log.info(f"solver '{self.params.solver}' (K={self.params.gain}, T={self.params.period} s, "
                      f"{'lockstep' if self.lockstep else 'real-time'})")
        if priority_note and priority_note != "disabled":
            self.log.warning(priority_note)
        elif not priority_note:
            self.log.info(f"running under SCHED_FIFO priority {values['thread_priority']}")

    def close(self) -> None:
        nan2 = (float("nan"),) * 2
        jp = percentiles(np.array(self.jitter)) if self.jitter else nan2
        lp = percentiles(np.array(self.latency)) if self.latency else nan2
        self.log.info(f"{self.cycles} cycles, {self.missed} missed deadlines, {self.failures} solver failures, "
                      f"period jitter p50/p99 {jp[0] * 1e3:.3f}/{jp[1] * 1e3:.3f} ms, "
                      f"state-to-command latency p50/p99 {lp[0] * 1e3:.3f}/{lp[1] * 1e3:.3f} ms "
                      f"(last {WINDOW} cycles)")

    # --- inputs -----------------------------------------------------------------
    def on_joint_state(self, msg: Any) -> None:
        decoded = convert.joint_vectors(msg, self.order)
        if isinstance(decoded, str):  # keep the last good state; it goes stale -> safe command
            self.report_rejected(convert.stamp_ns(msg.header.stamp), decoded)
            return
        self.state = (convert.stamp_ns(msg.header.stamp), decoded[0], time.monotonic_ns())
        if self.lockstep:
            self.try_lockstep()

    def on_target(self, msg: Any) -> None:
        value = convert.target_value(msg)
        if isinstance(value, str):
            self.log.error(f"relative_target rejected: {value}")
            return
        self.target = value
        if self.lockstep:
            self.targets[value.stamp_ns] = value
            self.try_lockstep()

    # --- cycles -----------------------------------------------------------------
    def try_lockstep(self) -> None:
        if self.state is None or self.state[0] == self.last_commanded_stamp:
            return
        target = self.targets.get(self.state[0])
        if target is None:
            return
        for old in [s for s in self.targets if s <= self.state[0]]:
            del self.targets[old]
        self.cycle(target)

    def on_tick(self) -> None:
        now = time.monotonic_ns()
        period_ns = self.params.period * 1e9
        if self.last_tick_ns is not None:
            dt = now - self.last_tick_ns
            self._keep(self.jitter, abs(dt - period_ns) / 1e9)
            if dt > 1.5 * period_ns:
                self.missed += round(dt / period_ns) - 1
        self.last_tick_ns = now
        if self.state is None:
            self.publish_safe(0, "waiting for joint_states")
            return
        if time.time_ns() - self.state[0] > self.stale_ns:
            self.publish_safe(self.state[0], f"joint_states stale by {(time.time_ns() - self.state[0]) / 1e6:.1f} ms")
            return
        if self.target is None:
            self.publish_safe(self.state[0], "waiting for relative_target")
            return
        self.cycle(self.target)
        if (time.monotonic_ns() - now) > period_ns:
            self.missed += 1

    def cycle(self, target: convert.TargetValue) -> None:
        assert self.state is not None
        stamp, q, received = self.state
        out = self.controller.step(q, target)
        self.pub_cmd.publish(convert.float_array(out.velocities))
        latency = (time.monotonic_ns() - received) / 1e9
        self._keep(self.latency, latency)
        self.last_commanded_stamp = stamp
        self.cycles += 1
        if out.result.failed:
            self.failures += 1
            self.log.warning(f"solver {out.result.status}: {out.result.detail}; safe command sent")
        if np.all(np.isfinite(out.position)):
            self.pub_pose.publish(convert.pose_stamped(stamp, out.position, out.rotation))
        self.publish_diagnostics(stamp, out, latency)

    def publish_safe(self, stamp: int, reason: str) -> None:
        """Zero-velocity command with the reason on /diagnostics (throttled in the log)."""
        self.pub_cmd.publish(convert.float_array(np.zeros(self.model.nq)))
        self.report_rejected(stamp, reason, status="safe_command")

    def report_rejected(self, stamp: int, reason: str, status: str = "input_rejected") -> None:
        """Reason on /diagnostics (every time) and in the log (at most once a second)."""
        now = time.monotonic()
        if now - self.last_warning > 1.0:
            self.last_warning = now
            self.log.warning(f"{status}: {reason}")
        self.pub_diag.publish(convert.diagnostics(stamp or time.time_ns(), "controller_node", 1, reason,
                                                  {"solver": self.params.solver, "status": status}))

    def publish_diagnostics(self, stamp: int, out: ControlOutput, latency: float) -> None:
        r = out.result
        level = 2 if r.failed else (1 if r.status != "solved" else 0)
        if self.cycles % STATS_EVERY == 1:  # percentiles once a second, not every cycle
            self.stats = (percentiles(np.array(self.jitter)) if self.jitter else (float("nan"),) * 2,
                          percentiles(np.array(self.latency)))
        jit, lat = self.stats
        values = {
            "solver": self.params.solver,
            "status": r.status,
            "solve_time_s": f"{r.solve_time:.6e}",
            "cycle_time_s": f"{out.cycle_time:.6e}",
            "iterations": r.iterations,
            "active_joints": r.active_joints,
            "position_error_m": f"{out.position_error:.6e}",
            "orientation_error_rad": f"{out.orientation_error:.6e}",
            "control_period_s": self.params.period,
            "stamp_ns": stamp,
            "cycles": self.cycles,
            "missed_deadlines": self.missed,
            "solver_failures": self.failures,
            "period_jitter_p50_s": f"{jit[0]:.6e}",
            "period_jitter_p99_s": f"{jit[1]:.6e}",
            "state_to_command_latency_s": f"{latency:.6e}",
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
    import sys

    argv = list(sys.argv if args is None else args)
    # Before any DDS thread exists, so they inherit it; the parameter is read from the raw args
    # because the node (and its parameter machinery) does not exist yet.
    priority = DEFAULT_PRIORITY
    for i, a in enumerate(argv[:-1]):
        if a == "-p" and argv[i + 1].startswith("thread_priority:="):
            try:
                priority = int(argv[i + 1].split(":=", 1)[1])
            except ValueError:
                pass  # declare() rejects it with exit 2
    why_not = request_realtime_priority(priority)
    return run_node(lambda: ControllerNode(why_not), argv)


if __name__ == "__main__":
    raise SystemExit(main())
