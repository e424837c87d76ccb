"""Start nodes as separate processes (the ``dualarm launch`` / ``dualarm run`` verbs).

Output lines are prefixed with the node name. Everything stops cleanly on Ctrl-C/SIGTERM
or when the trajectory node reports the scenario complete (exits 0); the exit code is
non-zero if any process failed.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from dualarm_control.references.base import HELD_OBJECT_POSE, RELATIVE_TARGET
from dualarm_control.ros.env import (
    LAUNCHER_PID_VARIABLE,
    RECORDER_NODE,
    localhost_environment,
)
from dualarm_control.ros.node import StopOnSignal
from dualarm_control.ros.node_exit import ACK_TIMEOUT_S

if TYPE_CHECKING:
    from dualarm_control.hardware import HardwareProfile

NODES = {
    "sim_node": "dualarm_sim.sim_node",
    "controller_node": "dualarm_control.nodes.controller_node",
    "trajectory_node": "dualarm_control.nodes.trajectory_node",
}
CONTAINER, CONTAINER_MODULE = "cell_container", "dualarm_control.nodes.container"
LAYOUTS = {
    3: (("controller_node",), ("trajectory_node",), ("sim_node",)),
    2: (("controller_node", "trajectory_node"), ("sim_node",)),
    1: (("controller_node", "trajectory_node", "sim_node"),),
}
"""Processes of ``dualarm launch --processes N``: which nodes share a process (started in this order)."""
STOP_GRACE_S = ACK_TIMEOUT_S + 5.0
"""The grace of a node before SIGTERM: longer than a stopping lockstep node's wait for its readers'
acknowledgements (``ros.node_exit.ACK_TIMEOUT_S``, 15 s), so that the node ends that wait itself and exits 0.
Under ``stress-ng --cpu 1`` a lockstep sim_node's wait for a starved recorder outlasted the former 10 s
grace: SIGTERM then ended it (exit -15) and the launch failed. A node that exits at once costs nothing."""
STOPPED_LAST = ("bag",)
"""Processes stopped after every other one: the recorder takes what the nodes still send."""
RECORDER_STOP_GRACE_S = 120.0
"""The grace of a recorder (:data:`STOPPED_LAST`) before SIGTERM: it takes what is still queued (up to
``ros/recorder.py: DRAIN_ENDED_MAX_S``), computes /tf and closes the bag, seconds each when it is starved
on a busy machine; a SIGTERM then would cost the bag its end or its index."""
INTERACTIVE = "interactive"
"""`dualarm launch interactive`: the trajectory node in mode:=interactive (issue 18)."""
INTERACTIVE_CELL = "interactive_demo"
"""The scenario whose cell (start configuration) and limits `dualarm launch interactive` uses."""
GRAPH_TOPICS = ("/joint_states", "/velocity_controller/commands", "/relative_target", "/relative_pose",
                "/diagnostics", "/wrench", "/clock")
PLAN_TOPICS = (*GRAPH_TOPICS, "/joint_reference")
LIVE_OBSTACLES = "/collision_objects"
"""Recorded too when the scenario has moving obstacles (the simulator publishes them there every step)."""
"""What ``--record`` records: the cell's graph."""
TASK_TOPICS = ("/joint_states", "/velocity_controller/commands", "/diagnostics", "/wrench", "/clock")
"""What ``--record`` records on a task scenario (no target, no relative pose; the force variant adds
the simulator's ``/contact_force``)."""


def params_profile(params: Sequence[str], joint_names: Sequence[str]) -> HardwareProfile:
    """The controller's hardware profile in the ``params`` files (the default profile without one)."""
    from dualarm_control.hardware import load_profile
    from dualarm_control.params import read_params_files

    return load_profile(read_params_files(params, "controller_node"), joint_names, "controller_node")


def with_profile_topics(topics: Sequence[str], params: Sequence[str], joint_names: Sequence[str]) -> tuple[str, ...]:
    """``topics`` with the joint-state and command topics of the hardware profile of the ``params`` files
    (docs/hardware.md) in place of the default profile's (the same topics without a profile)."""
    from dualarm_control.hardware import load_profile

    profile = params_profile(params, joint_names)
    default = load_profile({}, joint_names)
    out: list[str] = []
    for topic in topics:
        out += (profile.joint_states if topic in default.joint_states else
                profile.topics if topic in default.topics else (topic,))
    return tuple(dict.fromkeys(out))


def node_command(node: str, ros_args: Sequence[str]) -> list[str]:
    """Command line running ``node`` with this interpreter; KeyError lists the valid nodes."""
    if node not in NODES:
        raise KeyError(f"unknown node {node!r}; valid choices: {', '.join(NODES)}")
    args = list(ros_args)
    return [sys.executable, "-u", "-m", NODES[node], *(args if args[:1] == ["--ros-args"] or not args
                                                         else ["--ros-args", *args])]


def scoped(node: str, args: Sequence[str]) -> list[str]:
    """A node's ``-p NAME:=VALUE`` arguments in rcl's node-scoped form ``-p NODE:NAME:=VALUE`` (other
    arguments as they are): one command line for nodes sharing a process."""
    return [f"{node}:{arg}" if i and args[i - 1] == "-p" else arg for i, arg in enumerate(args)]


def container_command(node_args: Mapping[str, Sequence[str]]) -> list[str]:
    """Command line of ``cell_container`` running the nodes of ``node_args`` (name -> its ROS arguments)."""
    ros_args: list[str] = []
    for node, args in node_args.items():
        args = scoped(node, args)
        for i, arg in enumerate(args):
            pair = args[i - 1: i + 1] if i and args[i - 1] == "--params-file" else args[i: i + 2]
            if pair[0] == "--params-file" and any(ros_args[j: j + 2] == pair for j in range(len(ros_args))):
                continue  # a params file once: it is keyed by node name
            ros_args.append(arg)
    return [sys.executable, "-u", "-m", CONTAINER_MODULE, "--nodes", ",".join(node_args), "--ros-args", *ros_args]


def recorder_command(path: Path, topics: Sequence[str], use_sim_time: bool = False,
                     after_data: Sequence[str] = (), after_matched: Sequence[str] = ()) -> list[str]:
    """Command line of ``dualarm bag record -o PATH TOPICS`` with this interpreter."""
    return [sys.executable, "-u", "-m", "dualarm_control.app.cli", "bag", "record", "-o", str(path), *topics,
            *(["--use-sim-time"] if use_sim_time else []), *(f"--after-data={t}" for t in after_data),
            *(f"--after-matched={t}" for t in after_matched)]


@dataclass
class Process:
    name: str
    popen: subprocess.Popen[str]
    lines: list[str] = field(default_factory=list)
    ready: threading.Event = field(default_factory=threading.Event)


class Launch:
    """A group of child processes with prefixed output and orderly shutdown.

    Every output line is kept in its :class:`Process`; ``echo`` also prints it, prefixed."""

    def __init__(self, ready_marker: str = "bag: ready", echo: bool = True) -> None:
        self.procs: list[Process] = []
        self.ready_marker = ready_marker
        self.echo = echo
        self._lock = threading.Lock()

    def start(self, name: str, cmd: list[str], env: Mapping[str, str] | None = None) -> Process:
        """Start ``cmd`` (its own process group); ``env`` adds to this process's environment, and the
        localhost discovery default applies unless the result sets its own discovery."""
        env = dict(localhost_environment({**os.environ, **(env or {})}), PYTHONUNBUFFERED="1")
        env[LAUNCHER_PID_VARIABLE] = str(os.getpid())  # the node stops if the launcher dies (ros.node)
        popen = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env,
                                 start_new_session=True)
        proc = Process(name, popen)
        threading.Thread(target=self._pump, args=(proc,), daemon=True).start()
        self.procs.append(proc)
        return proc

    def _pump(self, proc: Process) -> None:
        assert proc.popen.stdout is not None
        for line in proc.popen.stdout:
            line = line.rstrip("\n")
            if self.ready_marker in line:
                proc.ready.set()
            if "pybullet build time" in line:
                continue
            proc.lines.append(line)
            if self.echo:
                with self._lock:
                    print(f"[{proc.name}] {line}", flush=True)

    def wait_until(self, finished: str, timeout: float | None = None,
                   stop: StopOnSignal | None = None) -> dict[str, int | None]:
        """Wait until process ``finished`` exits, any process fails, ``timeout`` [s] or a signal
        (``stop``, Ctrl-C); then stop all."""
        deadline = None if timeout is None else time.monotonic() + timeout
        try:
            while True:
                if stop is not None and stop.signal is not None:
                    print("[launch] Ctrl-C: stopping every node", flush=True)
                    break
                codes = {p.name: p.popen.poll() for p in self.procs}
                if codes.get(finished) is not None or any(c not in (None, 0) for c in codes.values()):
                    break
                if deadline is not None and time.monotonic() > deadline:
                    print(f"[launch] timeout after {timeout:.0f} s", flush=True)
                    break
                time.sleep(0.05)
        finally:
            self.stop()
        return {p.name: p.popen.returncode for p in self.procs}

    def stop(self) -> None:
        """Stop the nodes, then the recorders (:data:`STOPPED_LAST`): a lockstep node waits at its exit
        until its samples are acknowledged (``ros.node_exit.flush_publishers``), which needs the recorder
        alive, so a recorder lagging behind a fast lockstep run still gets the run's end."""
        self._stop([p for p in self.procs if p.name not in STOPPED_LAST], STOP_GRACE_S)
        self._stop(self.procs, RECORDER_STOP_GRACE_S)

    def _stop(self, procs: Sequence[Process], grace: float) -> None:
        """SIGINT every live one of ``procs`` (like Ctrl-C), escalate to SIGTERM/SIGKILL after ``grace`` [s]."""
        for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGKILL):
            alive = [p for p in procs if p.popen.poll() is None]
            if not alive:
                return
            for p in alive:
                try:
                    os.killpg(p.popen.pid, sig)
                except ProcessLookupError:
                    pass
            end = time.monotonic() + grace
            while time.monotonic() < end and any(p.popen.poll() is None for p in alive):
                time.sleep(0.05)


def launch_scenario(
    scenario: str,
    params: Sequence[str],
    controller_args: Sequence[str],
    lockstep: bool,
    record: Path | None,
    timeout: float | None = None,
    rate_hz: float | None = None,
    record_topics: Sequence[str] = GRAPH_TOPICS,
    plan: Path | None = None,
    force: bool = False,
    interactive: bool = False,
    processes: int = 3,
    env: Mapping[str, str] | None = None,
    robot: str | None = None,
) -> int:
    """Run the three nodes (and a recorder of ``record_topics``) on ``scenario``; ``rate_hz`` sets every
    node's control period. Returns 0 if the scenario completed cleanly, 130 on Ctrl-C.

    A task scenario (pan_cleaning, paper 001) runs sim_node and controller_node only: the
    controller runs the scenario's tasks (``-p scenario:=NAME``), its task time comes from the
    joint-state stamps, so there is no trajectory_node; the run ends when the controller reports
    the scenario's duration complete. ``force`` selects the force variant in both nodes.

    ``interactive`` (issue 18): the trajectory node in ``mode:=interactive`` on the scenario's
    cell and limits: it holds the measured relative pose and follows /relative_goal and
    /relative_twist (and, with the scenario's absolute frame, /absolute_goal and /absolute_twist: issue 41),
    until Ctrl-C or ``timeout``; in real time, or with ``lockstep`` as fast as the nodes go (a command applies at
    the cycle it arrives in).

    ``processes`` (:data:`LAYOUTS`): 3, each node its own process (the default); 2, the simulator
    alone and the controller with the trajectory node in one ``cell_container``; 1, every node in
    one ``cell_container`` (nodes/container.py). Fewer than 3 runs in real time only.
    ``env`` adds to the environment of every process started (``dualarm bench --realtime --baseline``).
    ``robot`` (``--robot``): the robot every node runs on instead of the scenario's (a name or a YAML path);
    every node gets ``-p robot:=`` the robot's reference (the controller has no scenario in relative mode).
    """
    from dualarm_control.cell_robot import cell_robot, robot_note
    from dualarm_control.scenario import load_scenario

    robot, profile_robot = cell_robot(params, robot)  # the profile's robot (hardware.robot) first
    loaded = load_scenario(scenario, robot)
    print(f"[launch] {robot_note(loaded, profile_robot, robot or '')}", flush=True)
    tasks = loaded.tasks is not None
    if interactive and (tasks or plan is not None):
        raise ValueError("interactive runs on a relative motion scenario (no plan or tasks)")
    if processes not in LAYOUTS:
        raise ValueError(f"processes must be one of {sorted(LAYOUTS)}, got {processes!r}")
    if processes != 3 and lockstep:
        raise ValueError(f"{processes} processes run in real time: lockstep runs use separate processes")
    if force and not tasks:
        raise ValueError(f"force feedback applies to task scenarios (pan_cleaning), not to {scenario!r}")
    common = ["-p", f"lockstep:={'true' if lockstep else 'false'}", "-p", f"robot:={loaded.robot.reference}"]
    if rate_hz is not None:
        common += ["-p", f"control_period:={1.0 / rate_hz!r}"]
    with_scenario = ["-p", f"scenario:={scenario}"]
    sim_time = ["-p", "use_sim_time:=true"] if lockstep else []  # lockstep stamps are simulation time
    if plan is not None:  # execute a plan: joint reference from the trajectory node, tracked by the controller
        with_scenario += ["-p", f"plan:={Path(plan).resolve()}"]
    for f in params:
        common += ["--params-file", str(Path(f).resolve())]
    if profile_robot:  # a relative hardware.robot is the profile file's: every node gets it made absolute
        common += ["-p", f"hardware.robot:={profile_robot}"]
    trajectory_args = [*with_scenario, "-p", "mode:=interactive"] if interactive else with_scenario
    if tasks:
        with_scenario += ["-p", f"force:={'true' if force else 'false'}"]
    controller_args = [*with_scenario, *controller_args]  # the controller runs the scenario's tracker
    if tasks:
        if record is not None:  # real time: the task starts once the recorder reads /diagnostics
            controller_args += ["-p", "task_start_readers:=1"]
        if record_topics == GRAPH_TOPICS:
            held = loaded.tasks is not None and loaded.tasks.held is not None  # its wrist sensors instead
            record_topics = ((*TASK_TOPICS, "/left/wrench", "/right/wrench", HELD_OBJECT_POSE) if held
                             else (*TASK_TOPICS, "/contact_force") if force else TASK_TOPICS)
    finisher = "controller_node" if tasks else "trajectory_node"
    launch = Launch()
    interrupted = False
    with StopOnSignal() as stop:  # Ctrl-C / SIGTERM set a flag the wait checks: no exception mid-call
        try:
            if plan is not None and record_topics == GRAPH_TOPICS:
                record_topics = PLAN_TOPICS
            if loaded.moving_obstacles and LIVE_OBSTACLES not in record_topics:  # the hand's markers, every step
                record_topics = (*record_topics, LIVE_OBSTACLES)
            if record is not None:  # subscribes the graph's topics once they all have a publisher
                record_topics = with_profile_topics(record_topics, params, loaded.robot.joint_names)
                state_topics = params_profile(params, loaded.robot.joint_names).joint_states
                # Real-time task runs start once the recorder reads /diagnostics (task_start_readers); it
                # subscribes that topic last, once the others deliver: the bag then holds the run from t = 0.
                gate = ("/diagnostics",) if tasks and not lockstep else ()
                # Lockstep: the simulator starts once the recorder reads every joint-state topic of the profile,
                # which it subscribes last, once its other readers matched their publishers (none of their
                # messages is lost; a profile's /left and /right topics too: with /joint_states alone gated, a
                # recorder under load missed a whole run's /relative_pose and /relative_target).
                last = tuple(t for t in state_topics if t in record_topics) if lockstep else ()
                # Real-time relative runs hold the first target until the recorder reads /relative_target
                # (start_after_reader), which it subscribes last, once its other readers matched their publishers
                # (a recorder slower to start than a 1.5 s scenario recorded none of its per-cycle topics).
                if not tasks and not lockstep and RELATIVE_TARGET in record_topics:
                    last = (RELATIVE_TARGET,)
                    trajectory_args = [*trajectory_args, "-p", f"start_after_reader:={RECORDER_NODE}"]
                launch.start("bag", recorder_command(record, record_topics, lockstep, gate, last), env)
            readers = (1 if tasks else 2) + (record is not None)
            node_args = {"controller_node": [*common, *sim_time, *controller_args]}
            if not tasks:
                node_args["trajectory_node"] = [*common, *sim_time, *trajectory_args]
            node_args["sim_node"] = [*common, *with_scenario, "-p", f"lockstep_subscribers:={readers}"]
            for group in LAYOUTS[processes]:
                members = {node: node_args[node] for node in group if node in node_args}
                if len(members) > 1:
                    name = CONTAINER if len(members) == len(node_args) else f"{CONTAINER}_{len(members)}"
                    launch.start(name, container_command(members), env)
                    finisher = name if finisher in members else finisher
                elif members:
                    (node, args), = members.items()
                    launch.start(node, node_command(node, args), env)
            codes = launch.wait_until(finisher, timeout, stop)
            interrupted = stop.signal is not None
        except KeyboardInterrupt:
            interrupted = True
            print("[launch] Ctrl-C: stopping every node", flush=True)
            launch.stop()
            codes = {p.name: p.popen.returncode for p in launch.procs}
    failed = {n: c for n, c in codes.items() if c != 0}
    if failed:
        print(f"[launch] failed: {', '.join(f'{n} (exit {c})' for n, c in failed.items())}", flush=True)
    elif interrupted:
        print(f"[launch] stopped cleanly: {', '.join(codes)} exited 0", flush=True)
    else:
        print(f"[launch] scenario complete: {', '.join(codes)} exited 0", flush=True)
    if interrupted:
        return 130
    return 0 if codes.get(finisher) == 0 and not failed else 1
