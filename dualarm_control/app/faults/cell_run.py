"""One real-time run of the cell for fault injection: the three nodes and a reference recorder as
real processes (:class:`~dualarm_control.app.run.launcher.Launch`), optionally in network namespaces.

The run knows the scenario's trajectory, so faults "mid-motion" are injected when the relative
target is moving (its twist is non-zero), timed from the trajectory node's start.
"""

from __future__ import annotations

import os
import re
import signal
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import numpy as np

from dualarm_control.app.faults.episodes import GraphStreams, read_record
from dualarm_control.app.faults.netns import exec_prefix
from dualarm_control.app.run.launcher import (
    Launch,
    Process,
    node_command,
    recorder_command,
)

RECORDED = ("/diagnostics", "/joint_states", "/velocity_controller/commands", "/relative_pose")
START_TIMEOUT_S = 60.0
MOVING = 1e-6  # target twist norm above which the target moves [m/s, rad/s]


class RunError(RuntimeError):
    """The run did not reach the state a fault needs (a node failed to start, a log line never came)."""


def trajectory_motion(scenario: str) -> tuple[np.ndarray, np.ndarray]:
    """Times [s] (every 10 ms) and whether the scenario's relative target moves at each."""
    from dualarm_control.kinematics import DualArmModel
    from dualarm_control.scenario import load_scenario

    sc = load_scenario(scenario)
    model = DualArmModel()
    traj = sc.trajectory(*model.relative_pose(sc.initial_positions))
    times = np.arange(0.0, traj.duration, 0.01)
    moving = np.array([max(np.linalg.norm(s.linear_velocity), np.linalg.norm(s.angular_velocity)) > MOVING
                       for s in (traj.sample(t) for t in times)])
    return times, moving


class CellRun:
    """sim_node (in namespace ``sim_ns``), controller_node, trajectory_node and a recorder (in ``ctrl_ns``)."""

    def __init__(self, out: Path, scenario: str, node_args: Sequence[str] = (), sim_ns: str = "",
                 ctrl_ns: str = "", env: Mapping[str, str] | None = None,
                 sim_env: Mapping[str, str] | None = None, node_extra: Mapping[str, Sequence[str]] | None = None,
                 helpers: Mapping[str, list[str]] | None = None, topics: Sequence[str] = RECORDED) -> None:
        """``node_extra``: more ROS arguments per node (remappings); ``helpers``: more processes (name ->
        command, in ``ctrl_ns``) started before the nodes, e.g. a lossy relay; ``topics``: what the run's
        bag records (a hardware profile's topics in place of the default ones)."""
        self.topics = tuple(topics)
        self.out = Path(out)
        self.scenario = scenario
        self.node_args = list(node_args)
        self.node_extra = dict(node_extra or {})
        self.helpers = dict(helpers or {})
        self.sim_ns, self.ctrl_ns = sim_ns, ctrl_ns
        self.env = dict(env or {})
        self.sim_env = dict(sim_env) if sim_env is not None else self.env
        self.launch = Launch(echo=False)
        self.bag = self.out / "bag"
        self.t0 = 0.0  # monotonic time of the trajectory's start
        self.times, self.moving = trajectory_motion(scenario)

    def _cmd(self, ns: str, cmd: list[str]) -> list[str]:
        return [*exec_prefix(ns), *cmd] if ns else cmd

    def start_node(self, name: str) -> Process:
        args = [*self.node_args, *self.node_extra.get(name, [])]
        if name != "controller_node":
            args += ["-p", f"scenario:={self.scenario}"]
        if name == "sim_node":
            return self.launch.start(name, self._cmd(self.sim_ns, node_command(name, args)), self.sim_env)
        return self.launch.start(name, self._cmd(self.ctrl_ns, node_command(name, args)), self.env)

    def start_recorder(self, name: str, path: Path, topics: Sequence[str] = RECORDED) -> Process:
        return self.launch.start(name, self._cmd(self.ctrl_ns, recorder_command(path, topics)), self.env)

    def start(self, extra_recorders: Mapping[str, Path] = {}) -> None:
        """Start everything; return once every recorder is subscribed and the trajectory has started."""
        self.out.mkdir(parents=True, exist_ok=True)
        recorders = [self.start_recorder("bag", self.bag, self.topics)]
        recorders += [self.start_recorder(name, path) for name, path in extra_recorders.items()]
        for name, cmd in self.helpers.items():
            self.launch.start(name, self._cmd(self.ctrl_ns, cmd), self.env)
        for name in ("controller_node", "trajectory_node", "sim_node"):
            self.start_node(name)
        end = time.monotonic() + START_TIMEOUT_S
        for rec in recorders:
            if not rec.ready.wait(max(0.0, end - time.monotonic())):
                raise RunError(f"recorder {rec.name} not ready after {START_TIMEOUT_S:.0f} s:\n" + self.tail(rec.name))
        self.wait_line("trajectory_node", "targets: ", timeout=max(1.0, end - time.monotonic()))
        self.t0 = time.monotonic()

    def process(self, name: str) -> Process:
        """The latest process started under ``name``."""
        return [p for p in self.launch.procs if p.name == name][-1]

    def tail(self, name: str, n: int = 15) -> str:
        return "\n".join(self.process(name).lines[-n:])

    def wait_line(self, name: str, text: str, timeout: float = 30.0, start: int = 0) -> int:
        """Wait for a line of ``name`` containing ``text`` from line index ``start``; its index."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            proc = self.process(name)
            for i, line in enumerate(proc.lines[start:], start):
                if text in line:
                    return i
            time.sleep(0.02)
        raise RunError(f"{name}: '{text}' not seen within {timeout:.0f} s; last lines:\n{self.tail(name)}")

    def line_after_ms(self, name: str, text: str, since_ns: int, timeout: float) -> float:
        """[ms] from ``since_ns`` (wall clock) to the stamp of the latest ``name`` process's first line containing
        ``text``; inf when none came within ``timeout`` [s]. E.g. after a simulator's restart, its first command:
        its reader can match the controller's writer seconds after the controller has its states again (seen:
        0 commands 1.2 s after the recovery; about 2 s later on a quiet machine)."""
        try:
            i = self.wait_line(name, text, timeout)
        except RunError:
            return float("inf")
        stamp = log_stamp(self.process(name).lines[i])
        return float("nan") if stamp is None else (stamp * 1e9 - since_ns) / 1e6

    def send(self, name: str, sig: int) -> int:
        """Send ``sig`` to the latest ``name`` process; the wall-clock time [ns] it was sent."""
        t = time.time_ns()
        os.kill(self.process(name).popen.pid, sig)
        return t

    def pause(self, name: str, seconds: float, until: Callable[[], bool] | None = None,
              hold_after: float = 0.0, timeout: float = 30.0) -> tuple[int, int]:
        """SIGSTOP ``name`` for ``seconds``, and past that until ``until()`` holds (polled; at most ``timeout``
        s, then it is resumed anyway) and ``hold_after`` s more; wall-clock times [ns] of the stop and of the
        SIGCONT. A watchdog episode waits for the controller's safe state this way: on a loaded machine the
        controller may read the last states late, and the safe window must still be seen."""
        stopped = self.send(name, signal.SIGSTOP)
        time.sleep(seconds)
        if until is not None:
            end = time.monotonic() + timeout
            while not until() and time.monotonic() < end:
                time.sleep(0.01)
            time.sleep(hold_after)
        return stopped, self.send(name, signal.SIGCONT)

    def elapsed(self) -> float:
        """Trajectory time [s] now."""
        return time.monotonic() - self.t0

    def wait_moving(self, hold: float, earliest: float = 0.0) -> float:
        """Sleep until the target will move for at least ``hold`` s (trajectory time >= ``earliest``);
        the trajectory time reached. RunError if the trajectory has no such window left."""
        now = max(self.elapsed(), earliest) + 0.05
        n = int(np.ceil(hold / 0.01))
        for i in range(int(np.searchsorted(self.times, now)), len(self.times) - n):
            if self.moving[i:i + n].all():
                time.sleep(max(0.0, self.times[i] - self.elapsed()))
                return self.elapsed()
        raise RunError(f"no {hold:.1f} s of motion left after t={now:.1f} s in '{self.scenario}'")

    def stop(self) -> dict[str, int | None]:
        """Stop every process; write each one's output to ``<out>/<name>.log`` (``<name>.2.log`` for a restart)."""
        self.launch.stop()
        seen: dict[str, int] = {}
        for proc in self.launch.procs:
            seen[proc.name] = seen.get(proc.name, 0) + 1
            suffix = f".{seen[proc.name]}" if seen[proc.name] > 1 else ""
            (self.out / f"{proc.name}{suffix}.log").write_text("\n".join(proc.lines) + "\n")
        return {p.name: p.popen.returncode for p in self.launch.procs}

    def record(self) -> GraphStreams:
        return read_record(self.bag)


def log_stamp(line: str) -> float | None:
    """The wall-clock stamp [s] of a ROS log line ``[LEVEL] [sec.nsec] [node]: ...`` (None without one)."""
    stamp = re.search(r"\[(\d+\.\d+)\]", line)
    return None if stamp is None else float(stamp[1])
