"""``dualarm faults``: the fault matrix, against real processes, on loopback and private namespaces.

Each row injects one fault into a real-time run of the cell (the three nodes and a reference
recorder as separate processes, :class:`~dualarm_control.app.faults.cell_run.CellRun`) and judges
the outcome from the run's bag (:mod:`~dualarm_control.app.faults.episodes`) and the nodes' logs.
A row that cannot run here (no root, no ``ip``, no netem in the kernel) is *skipped* with the
reason, never passed. Rows that share a run: the loopback faults (one run, in sequence, each
while the target moves), the across-hosts run and its link cut.
"""

from __future__ import annotations

import json
import re
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from dualarm_control.app.faults.cell_run import CellRun, RunError, log_stamp
from dualarm_control.app.faults.episodes import (
    GraphStreams,
    arm_stop,
    check_signalled_bag,
    completion,
    safe_episode,
)
from dualarm_control.app.faults.netns import (
    Link,
    netem_unavailable,
    private_link,
    unavailable,
)
from dualarm_control.app.faults.rows import (
    COMMAND_TIMEOUT_STEPS,
    LOOPBACK_ROWS,
    PROFILE_KILLS,
)
from dualarm_control.paths import config_path
from dualarm_control.ros.env import udp_only_env

PERIOD = 0.005
STALE_TIMEOUT = 0.015  # controller defaults (nodes/controller_setup.py: NODE_PARAMETERS)
TARGET_TIMEOUT = 0.05
PAUSE_S = 0.5
CUT_S = 1.0
RESTART_AFTER_S = 0.5
RECOVER_WITHIN_MS = 1000.0
RESTART_RECOVER_WITHIN_MS = 30000.0
LINK_CUT_HANG_GUARD_S = 30.0
"""link_cut: the verdict is that the cell recovers after the link is up, within this hang guard [s]; how soon
(1 s on a quiet machine, 1040-1074 ms seen under load) is a reported figure, not a verdict."""
FINAL_POSITION_M = 1e-3
FINAL_ORIENTATION_RAD = 1e-2
LOSS = ("loss", "10%")
LINK_NETEM = ("delay", "2ms", "1ms", "loss", "2%")

COLLISION_GOAL = ("0", "0", "-0.35", "3.14159265", "0", "0")
"""goal_into_collision: F2 35 cm behind F1, through the left forearm (xyz [m], rpy [rad])."""
SAFE_GOAL = ("0", "0", "0.15", "3.14159265", "0", "0")
SAFETY_DISTANCE = 0.03  # m, the collision limit's default d_s
RECORDER_EXIT_S = 30.0
"""How long a signalled recorder may take to close its bag and exit before the run is stopped."""
KILL_INTO_MOTION_S = 0.6
"""kill_controller: seconds into a window of at least 1.5 s of motion (a segment starts from rest)."""

EXPECTED = {
    "goal_into_collision": "interactive cell, real time: a goal through the other arm (xyz 0 0 -0.35, rpy pi 0 0) "
                           f"ends stalled with 'collision constraint: <pair> at d m', d >= {SAFETY_DISTANCE:g} m - "
                           "1 mm; the simulator counts no contact (its /diagnostics 'contacts' stays 0)",
    "stale_states": f"sim_node SIGSTOP {PAUSE_S:g} s (longer until the controller is safe) mid-motion: zero commands + /diagnostics ERROR once joint states "
                    f"are older than stale_timeout {STALE_TIMEOUT * 1e3:.0f} ms (tripped at <= +2 periods); OK again "
                    f"< {RECOVER_WITHIN_MS:.0f} ms after SIGCONT; one log line each way",
    "target_stopped": f"trajectory_node SIGSTOP {PAUSE_S:g} s (longer until safe) mid-motion: zero commands + ERROR once no target for "
                      f"target_timeout {TARGET_TIMEOUT * 1e3:.0f} ms (<= +2 periods); OK again < "
                      f"{RECOVER_WITHIN_MS:.0f} ms after SIGCONT; one log line each way",
    "kill_sim": f"kill -9 sim_node mid-run, restart it {RESTART_AFTER_S:g} s later: zero commands + ERROR while it is "
                f"gone, cycles resume (OK) once the new simulator publishes and the controller's commands reach it "
                f"(its log's 'first command received'; both < {RESTART_RECOVER_WITHIN_MS / 1e3:.0f} s)",
    "kill_controller": f"kill -9 controller_node mid-motion: the arms are at rest (all joints < 1e-3 rad/s) within "
                       f"command_timeout ({COMMAND_TIMEOUT_STEPS} steps) + 3 steps of its last command's arrival",
    **{name: f"kill -9 controller_node mid-motion on config/hardware/{profile}.yaml: the arms at rest (< 1e-3 rad/s) "
              f"within {steps} steps of its last command's arrival" + (" (the trajectory controller's cmd_timeout)"
                                                                      if steps > 3 else " (the last position holds)")
       for name, (profile, steps) in PROFILE_KILLS.items()},
    "recorder_sigint": "SIGINT to a bag recorder mid-run: exit 0, bag readable (rosbags AnyReader), every message "
                       "decodes, every /joint_states stamped before the signal (- 1 ms) is in it",
    "recorder_sigterm": "SIGTERM to a bag recorder mid-run: as for SIGINT",
    "best_effort_loss": "best-effort streams losing 10 % of their messages (netem loss on lo of a private namespace, "
                        "UDP only; without netem a relay process dropping 10 % of every stream): the scenario "
                        f"completes, final error < {FINAL_POSITION_M * 1e3:g} mm / {FINAL_ORIENTATION_RAD * 1e3:g} mrad",
    "across_hosts": "sim_node and controller/trajectory in two namespaces joined by a veth pair (10.231.x.x), Fast DDS "
                    "bound to it (config/fastdds_link.xml + ROS_STATIC_PEERS): scenario completes, final error < "
                    f"{FINAL_POSITION_M * 1e3:g} mm, no packet on the simulator namespace's lo; latency figures",
    "link_cut": f"link down {CUT_S:g} s mid-motion (ip link set down): ERROR (stale joint states), OK again after "
                f"the link is up (hang guard {LINK_CUT_HANG_GUARD_S:g} s; how soon is a figure)",
    "link_netem": f"across hosts with netem {' '.join(LINK_NETEM)} on the link, best-effort streams: completes, "
                  f"final error < {FINAL_POSITION_M * 1e3:g} mm; latency figures",
}


@dataclass
class Row:
    name: str
    fault: str
    expected: str
    observed: str
    status: str  # "pass", "FAIL" or "skipped"
    figures: dict[str, Any] = field(default_factory=dict)


def _row(name: str, passed: bool, observed: str, **figures: Any) -> Row:
    return Row(name, name.replace("_", " "), EXPECTED[name], observed, "pass" if passed else "FAIL", figures)


def _skipped(name: str, reason: str) -> Row:
    return Row(name, name.replace("_", " "), EXPECTED[name], f"skipped: {reason}", "skipped")


def _failed(names: Sequence[str], why: str) -> list[Row]:
    return [_row(n, False, f"run failed: {why}") for n in names]


# ------------------------------------------------------------------------------------- loopback run


@dataclass
class _Episode:
    start: int  # wall-clock ns of the fault
    resume: int  # wall-clock ns the input came back (process continued or restarted, link up)
    logs: tuple[int, int]  # controller log lines 'safe state' and 'recovered' during the episode
    commands_ms: float | None = None  # a restart: from the fault to the new simulator's first command [ms]


def _recovered(run: CellRun, line: int, timeout: float = 30.0) -> tuple[int, int]:
    """Wait for the controller's recovery line after log line ``line``; the episode's log counts."""
    end = run.wait_line("controller_node", "recovered after", timeout, start=line) + 1
    lines = run.process("controller_node").lines[line:end]
    return sum("safe state:" in t for t in lines), sum("recovered after" in t for t in lines)


SAFE_HOLD_S = 0.1
"""A pause lasts :data:`PAUSE_S`, and past that until the controller logged its safe state plus this [s]: the
zero commands while safe are seen even when a loaded machine delays the controller's reading of the last states
(a 0.5 s pause once ended before the controller, 490 ms behind, tripped: an empty safe window)."""


def _safe_since(run: CellRun, line: int) -> Callable[[], bool]:
    """Whether the controller logged 'safe state:' after its log line ``line``."""
    return lambda: any("safe state:" in t for t in run.process("controller_node").lines[line:])


def _episode_row(name: str, rec: GraphStreams, ep: _Episode, reason: str, limit_ms: float, within_ms: float) -> Row:
    e = safe_episode(rec, ep.start, ep.resume, reason)
    logs = ep.logs
    back = ep.commands_ms
    commands = {} if back is None else {"commands_back_ms": back}
    passed = (e.age_ms <= limit_ms and e.other_commands == 0 and e.zero_commands > 0
              and e.recovered_ms <= within_ms and logs[0] == logs[1] >= 1 and (back is None or back <= within_ms))
    text = "" if back is None else f"; commands reached the restarted simulator {back:.0f} ms after the fault"
    return _row(name, passed, f"{e.text()}; log: {logs[0]} 'safe state', {logs[1]} 'recovered'{text}",
                detected_ms=e.detected_ms, input_age_ms=e.age_ms, zero_commands=e.zero_commands,
                other_commands=e.other_commands, recovered_ms=e.recovered_ms, **commands)


def _recently_safe(run: CellRun, seconds: float) -> bool:
    """Whether the controller is in the safe state, or left it less than ``seconds`` ago (from the
    wall-clock stamp of its last 'recovered after' log line)."""
    for line in reversed(run.process("controller_node").lines):
        if "safe state:" in line:
            return True
        if "recovered after" in line:
            stamp = log_stamp(line)
            return stamp is None or time.time() - stamp < seconds
    return False


def _kill_controller(run: CellRun, name: str, say: Callable[[str], None]) -> bool:
    """SIGKILL the controller while the arms move at speed (not just after a watchdog episode); then 1 s."""
    earliest = run.elapsed() + 0.5
    while True:
        run.wait_moving(1.5, earliest=earliest)
        time.sleep(KILL_INTO_MOTION_S)  # past the segment's jerk-limited start: the arms move at speed
        if not _recently_safe(run, KILL_INTO_MOTION_S):
            break
        # a watchdog episode of a loaded machine just now: the arms may be at rest; the next window
        say(f"{name}: the controller was in the safe state within {KILL_INTO_MOTION_S:g} s; waiting")
        earliest = run.elapsed() + 0.5
    say(f"{name}: SIGKILL controller_node at t={run.elapsed():.2f} s")
    run.send("controller_node", signal.SIGKILL)
    time.sleep(1.0)
    return True


def _stop_row(name: str, rec: GraphStreams, killed: bool, within_steps: int) -> Row:
    """A controller-kill row: moving when killed, at rest within ``within_steps`` simulator steps of its last command."""
    stop = arm_stop(rec, 0)
    passed = killed and stop.speed_at_last > 0.01 and 0 <= stop.steps <= within_steps
    return _row(name, passed, stop.text(PERIOD), speed_at_kill=stop.speed_at_last, steps=stop.steps,
                sim_ms=stop.steps * PERIOD * 1e3, wall_ms=stop.wall_ms)


def loopback_rows(out: Path, scenario: str, only: Sequence[str], say: Callable[[str], None]) -> list[Row]:
    """The process faults on one loopback run, in sequence, each while the target moves."""
    names = [n for n in LOOPBACK_ROWS if n in only]
    if not names:
        return []
    run = CellRun(out / "loopback", scenario)
    recorders: dict[str, Path] = {n: out / "loopback" / n for n in ("recorder_sigint", "recorder_sigterm")
                                  if n in names}
    episodes: dict[str, _Episode] = {}
    signalled: dict[str, int] = {}
    killed_controller = False
    try:
        say(f"loopback run of '{scenario}': starting the nodes and {1 + len(recorders)} recorder(s)")
        run.start(recorders)
        for name, sig in (("recorder_sigint", signal.SIGINT), ("recorder_sigterm", signal.SIGTERM)):
            if name in recorders:
                run.wait_moving(0.1, earliest=1.0)
                signalled[name] = run.send(name, sig)
                say(f"{name}: {signal.Signals(sig).name} sent at t={run.elapsed():.2f} s")
        for name, node, reason in (("stale_states", "sim_node", "joint_states stale"),
                                   ("target_stopped", "trajectory_node", "stopped mid-motion")):
            if name in names:
                run.wait_moving(PAUSE_S + 0.3)
                line = len(run.process("controller_node").lines)
                say(f"{name}: SIGSTOP {node} for {PAUSE_S:g} s at t={run.elapsed():.2f} s")
                start, resume = run.pause(node, PAUSE_S, until=_safe_since(run, line), hold_after=SAFE_HOLD_S)
                episodes[name] = _Episode(start, resume, _recovered(run, line))
        if "kill_sim" in names:
            run.wait_moving(1.0)
            line = len(run.process("controller_node").lines)
            say(f"kill_sim: SIGKILL sim_node at t={run.elapsed():.2f} s, restart in {RESTART_AFTER_S:g} s")
            start = run.send("sim_node", signal.SIGKILL)
            time.sleep(RESTART_AFTER_S)
            resume = time.time_ns()
            run.start_node("sim_node")
            from dualarm_sim.sim_node import FIRST_COMMAND

            logs = _recovered(run, line, RESTART_RECOVER_WITHIN_MS / 1e3)
            # the restarted simulator's first command: the command path works again
            commands_ms = run.line_after_ms("sim_node", FIRST_COMMAND, start, RESTART_RECOVER_WITHIN_MS / 1e3)
            episodes["kill_sim"] = _Episode(start, resume, logs, commands_ms)
        if "kill_controller" in names:
            killed_controller = _kill_controller(run, "kill_controller", say)
    except RunError as exc:
        run.stop()
        return _failed(names, str(exc))
    for name in signalled:  # it closes its bag and exits by itself (seconds on a loaded machine): not stopped early
        try:
            run.process(name).popen.wait(timeout=RECORDER_EXIT_S)
        except subprocess.TimeoutExpired:
            pass  # stopped with the others; its exit code says so
    codes = run.stop()
    rec = run.record()
    rows = []
    limits = {"stale_states": (STALE_TIMEOUT + 2 * PERIOD) * 1e3, "target_stopped": (TARGET_TIMEOUT + 2 * PERIOD) * 1e3,
              "kill_sim": (STALE_TIMEOUT + 2 * PERIOD) * 1e3}
    reasons = {"stale_states": "joint_states stale", "target_stopped": "stopped mid-motion",
               "kill_sim": "joint_states stale"}
    for name in names:
        if name in episodes:
            within = RESTART_RECOVER_WITHIN_MS if name == "kill_sim" else RECOVER_WITHIN_MS
            rows.append(_episode_row(name, rec, episodes[name], reasons[name], limits[name], within))
        elif name == "kill_controller":
            rows.append(_stop_row(name, rec, killed_controller, COMMAND_TIMEOUT_STEPS + 3))
        elif name in signalled:
            check = check_signalled_bag(recorders[name], rec, signalled[name])
            code = codes.get(name)
            closed = any("bag closed (signal" in line for line in run.process(name).lines)
            passed = check.readable and check.missing == 0 and check.expected >= 50 and code == 0 and closed
            rows.append(_row(name, passed, f"exit {code}, {check.text()}", messages=check.messages,
                             expected=check.expected, missing=check.missing))
    return rows


# ---------------------------------------------------------------------------------- namespace runs


def _ros_env(profile: bool, peer: str = "") -> dict[str, str]:
    """Environment of the processes of a namespace run. SUBNET and the link profile are set only
    for processes started inside this tool's own network namespaces (``ip netns exec``), whose
    veth pair and 10.231.x.x addresses exist nowhere else: no traffic can leave the machine."""
    if not profile:  # one namespace, loopback only, user data over UDP (shared memory would bypass lo and its netem)
        return udp_only_env()
    return {"ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET", "ROS_STATIC_PEERS": peer,
            "FASTRTPS_DEFAULT_PROFILES_FILE": str(config_path("fastdds_link.xml"))}


def _completion_row(name: str, rec: GraphStreams, extra: str = "", ok: bool = True, **figures: Any) -> Row:
    c = completion(rec)
    passed = (ok and c.complete and c.position_error_m < FINAL_POSITION_M
              and c.orientation_error_rad < FINAL_ORIENTATION_RAD)
    return _row(name, passed, c.text() + extra, cycles=c.cycles, trips=c.trips, position_error_m=c.position_error_m,
                orientation_error_rad=c.orientation_error_rad, latency_p50_ms=c.latency_p50_ms,
                latency_p99_ms=c.latency_p99_ms, **figures)


DELIVERY_S = 1.0
"""After the trajectory node's exit: time for its last messages (the 'complete' status) to reach
the recorder before everything is stopped (the node logs 'complete at' before it publishes it)."""


def _run_to_completion(run: CellRun) -> None:
    end = run.times[-1] + 30.0
    run.wait_line("trajectory_node", "complete at", timeout=max(1.0, end - run.elapsed()))
    try:
        run.process("trajectory_node").popen.wait(timeout=10.0)  # it stops by itself once complete
    except subprocess.TimeoutExpired:
        pass  # stopped with the others
    time.sleep(DELIVERY_S)


RELAY_ROUTES = ("/raw/joint_states:/joint_states:sensor_msgs/msg/JointState",
                "/velocity_controller/commands:/raw/velocity_controller/commands:std_msgs/msg/Float64MultiArray",
                "/raw/relative_target:/relative_target:trajectory_msgs/msg/MultiDOFJointTrajectory")
RELAY_REMAPS = {"sim_node": ["-r", "/joint_states:=/raw/joint_states",
                             "-r", "/velocity_controller/commands:=/raw/velocity_controller/commands"],
                "trajectory_node": ["-r", "/relative_target:=/raw/relative_target"]}


def loss_rows(out: Path, scenario: str, only: Sequence[str], say: Callable[[str], None],
              relay_loss: float = 0.1) -> list[Row]:
    """Best-effort streams with 10 % loss: netem on lo of a private namespace, or (no netem in this
    kernel) a lossy relay process on loopback that every stream goes through. Runs to completion."""
    if "best_effort_loss" not in only:
        return []
    best_effort = ["-p", "qos_reliability:=best_effort"]
    why = netem_unavailable()
    if why and relay_loss <= 0.0:
        return [_skipped("best_effort_loss", why)]
    try:
        if not why:
            with private_link(peer=False) as link:
                link.netem(link.a, "lo", LOSS)
                say(f"best_effort_loss: netem {' '.join(LOSS)} on lo of {link.a}, best-effort streams")
                run = CellRun(out / "best_effort_loss", scenario, best_effort, sim_ns=link.a, ctrl_ns=link.a,
                              env=_ros_env(False))
                _run_whole(run)
            how = f"netem {' '.join(LOSS)} on lo"
        else:
            relay = [sys.executable, "-u", "-m", "dualarm_control.app.faults.lossy_relay", "--loss", str(relay_loss),
                     *RELAY_ROUTES]
            say(f"best_effort_loss: no netem ({why}); a relay process drops {relay_loss:.0%} of every stream")
            run = CellRun(out / "best_effort_loss", scenario, best_effort, node_extra=RELAY_REMAPS,
                          helpers={"relay": relay})
            _run_whole(run)
            how = "relay: " + "; ".join(line.removeprefix("relay ") for line in run.process("relay").lines
                                        if "dropped" in line) + f" (netem unavailable: {why})"
    except RunError as exc:
        return _failed(["best_effort_loss"], str(exc))
    return [_completion_row("best_effort_loss", run.record(), f"; loss by {how}")]


def _run_whole(run: CellRun) -> None:
    """Start ``run``, wait for the scenario to complete, stop (also on failure)."""
    try:
        run.start()
        _run_to_completion(run)
    finally:
        run.stop()


def link_rows(out: Path, scenario: str, only: Sequence[str], say: Callable[[str], None]) -> list[Row]:
    """Across hosts (and the link cut on the same run), then with netem on the link."""
    rows: list[Row] = []
    names = [n for n in ("across_hosts", "link_cut") if n in only]
    why = unavailable()
    if why:
        return [_skipped(n, why) for n in (*names, *(["link_netem"] if "link_netem" in only else []))]
    if names:
        rows += _link_run(out / "across_hosts", scenario, names, [], [], say)
    if "link_netem" in only:
        why = netem_unavailable()
        if why:
            rows.append(_skipped("link_netem", why))
        else:
            rows += _link_run(out / "link_netem", scenario, ["link_netem"], list(LINK_NETEM),
                              ["-p", "qos_reliability:=best_effort"], say)
    return rows


def _link_run(out: Path, scenario: str, names: Sequence[str], netem: list[str], node_args: list[str],
              say: Callable[[str], None]) -> list[Row]:
    with private_link() as link:
        if netem:
            link.netem(link.a, link.device, netem)
            link.netem(link.b, link.device, netem)
        run = CellRun(out, scenario, node_args, sim_ns=link.a, ctrl_ns=link.b,
                      env=_ros_env(True, link.address_a), sim_env=_ros_env(True, link.address_b))
        cut: _Episode | None = None
        try:
            say(f"{', '.join(names)}: sim_node in {link.a} ({link.address_a}), controller in {link.b} "
                f"({link.address_b})" + (f", netem {' '.join(netem)}" if netem else ""))
            run.start()
            if "link_cut" in names:
                cut = _cut_link(run, link, say)
            _run_to_completion(run)
        except RunError as exc:
            run.stop()
            return _failed(names, str(exc))
        run.stop()
        packets = link.tx_packets(link.a)
    rec = run.record()
    rows = []
    for name in names:
        if name == "link_cut" and cut is not None:
            rows.append(link_cut_row(rec, cut))
        elif name != "link_cut":
            on_link = f"; simulator namespace sent {packets.get(link.device, 0)} packets on the link, {packets['lo']} on lo"
            rows.append(_completion_row(name, rec, on_link, ok=packets["lo"] == 0 and packets.get(link.device, 0) > 0,
                                        link_packets=packets.get(link.device, 0), lo_packets=packets["lo"]))
    return rows


def link_cut_row(rec: GraphStreams, cut: _Episode) -> Row:
    """The link_cut row: safe state while the link is down, and recovered once it is up (within the hang
    guard); the recovery time is a figure (``recovered_ms``), not part of the verdict."""
    return _episode_row("link_cut", rec, cut, "joint_states stale", float("inf"), LINK_CUT_HANG_GUARD_S * 1e3)


def _cut_link(run: CellRun, link: Link, say: Callable[[str], None]) -> _Episode:
    run.wait_moving(CUT_S + 0.5)
    line = len(run.process("controller_node").lines)
    say(f"link_cut: {link.device} down for {CUT_S:g} s at t={run.elapsed():.2f} s")
    start = time.time_ns()
    link.set_up(False)
    time.sleep(CUT_S)
    resume = time.time_ns()
    link.set_up(True)
    return _Episode(start, resume, _recovered(run, line, LINK_CUT_HANG_GUARD_S))


def collision_rows(out: Path, scenario: str, only: Sequence[str], say: Callable[[str], None]) -> list[Row]:
    """A goal into collision on the interactive cell (``dualarm launch interactive --record``): the
    verdict from ``dualarm goal --wait``, the contacts from the simulator's statuses in the bag."""
    if "goal_into_collision" not in only:
        return []
    from dualarm_control.app.record.bag import SIM_STATUS, read_bag

    out = out / "goal_into_collision"
    out.mkdir(parents=True, exist_ok=True)
    cli = [sys.executable, "-m", "dualarm_control.app.cli"]
    launch = subprocess.Popen([*cli, "launch", "interactive", "--solver", "sparse_qp", "--record", str(out / "bag")],
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    lines: list[str] = []
    threading.Thread(target=lambda: lines.extend(launch.stdout or ()), daemon=True).start()  # keeps the pipe drained
    answers: list[tuple[int, str]] = []
    try:
        deadline = time.monotonic() + 180.0
        while not any("interactive: holding the measured relative pose" in line for line in list(lines)):
            if launch.poll() is not None or time.monotonic() > deadline:
                return _failed(["goal_into_collision"], "the interactive cell did not start: " + "".join(lines[-5:]))
            time.sleep(0.1)
        for goal in (SAFE_GOAL, COLLISION_GOAL):
            say(f"goal_into_collision: goal xyz {' '.join(goal[:3])} rpy {' '.join(goal[3:])}")
            done = subprocess.run([*cli, "goal", "--xyz", *goal[:3], "--rpy", *goal[3:], "--wait", "--timeout", "200"],
                                  capture_output=True, text=True, timeout=300, check=False)
            answers.append((done.returncode, (done.stdout.strip().splitlines() or [""])[-1]))
    finally:
        launch.send_signal(signal.SIGINT)
        try:
            launch.communicate(timeout=180)
        except subprocess.TimeoutExpired:
            launch.kill()
    if len(answers) < 2:
        return _failed(["goal_into_collision"], f"goals not answered: {answers}")
    (code_safe, _), (code, last) = answers
    bag = read_bag(out / "bag")
    contacts = max((int(st.values.get("contacts", "0")) for st in bag.statuses if st.name == SIM_STATUS), default=-1)
    match = re.search(r"collision constraint: (.+?) at ([0-9.]+) m", last)
    distance = float(match.group(2)) if match else float("nan")
    ok = (code_safe == 0 and code == 1 and match is not None and distance >= SAFETY_DISTANCE - 1e-3 and contacts == 0)
    observed = (f"safe goal: exit {code_safe}; collision goal: exit {code}, '{last}'; simulator contacts "
                f"{contacts if contacts >= 0 else 'not reported'}")
    return [_row("goal_into_collision", ok, observed, distance_m=distance, contacts=contacts)]


# ------------------------------------------------------------------------------------------ matrix


def format_table(rows: Sequence[Row]) -> str:
    lines = ["| fault | expected behaviour | observed | pass |", "|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r.fault} | {r.expected} | {r.observed} | {r.status} |")
    return "\n".join(lines)


def write_results(out: Path, rows: Sequence[Row], seconds: float) -> None:
    out.mkdir(parents=True, exist_ok=True)
    doc = {"seconds": round(seconds, 1), "passed": all(r.status != "FAIL" for r in rows),
           "rows": [asdict(r) for r in rows]}
    (out / "faults.json").write_text(json.dumps(doc, indent=2, default=str) + "\n")
    (out / "faults.md").write_text(f"# Fault matrix ({seconds:.0f} s)\n\n{format_table(rows)}\n")
