"""``dualarm soak``: the scenario on repeat at 200 Hz over ROS for minutes; memory, deadlines, accounting.

The three nodes run as processes (:class:`~dualarm_control.app.run.launcher.Launch`), the trajectory
node with ``repeat:=true``. Once a second this process samples each node's resident set size
(``/proc/<pid>/status`` VmRSS) and the latest counters on ``/diagnostics`` (a monitor node of
its own). At the end the controller and trajectory node are stopped first, then the simulator,
and their closing log lines give the final counters.

* **RSS growth** per node: (largest RSS after the warm-up - RSS at the end of the warm-up) /
  RSS at the end of the warm-up; the warm-up is the first repetition or 10 % of the run,
  whichever is longer. Must be <= 5 %.
* **Missed-deadline bursts**: one-second windows after the warm-up in which the controller's
  missed-deadline counter rose by :data:`BURST` or more (2.5 % of the window's 200 cycles).
  Must be none. (Start-up, while the nodes import and load the cell, is reported apart.)
* **Accounting**: every command the controller published (``cycles + safe_commands``) after
  the start-up was received by the simulator. Start-up loses a few: those published while no
  subscriber was matched (``unmatched_commands``) and those sent while discovery was matched on
  the writer's side only. So the *shortfall* ``cycles + safe_commands - unmatched_commands -
  commands_received`` is measured at each ``sim_node`` status (its stamp T against the
  controller's count for the states stamped up to T - 10 ms, so at most
  :data:`IN_FLIGHT` commands are in doubt) and exactly at the end (the controller and
  trajectory node are stopped first, the simulator a second later). The final shortfall must
  equal the one at the end of the warm-up within :data:`IN_FLIGHT`: no command lost after it.

RSS growth and the accounting are properties of the code; whether a second holds a burst of
missed deadlines is also the machine's (its load, its other real-time tasks). The document keeps
them apart: ``load_independent_ok`` is RSS growth and accounting, ``bursts_ok`` the deadline
criterion, ``passed`` both (the verdict of ``dualarm soak``).
"""

from __future__ import annotations

import itertools
import json
import os
import re
import signal
import subprocess
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from dualarm_control.app.run.launcher import Launch, Process, node_command
from dualarm_control.ros.convert import stamp_ns
from dualarm_control.ros.listen import Topic, listen

NODES = ("sim_node", "controller_node", "trajectory_node")
SAMPLE_S = 1.0
BURST = 5
MAX_RSS_GROWTH = 0.05
WARMUP_SHARE = 0.1
IN_FLIGHT = 2
MATCH_NS = 10_000_000
STOP_WAIT_S = 15.0


def rss_bytes(pid: int) -> int:
    """Resident set size of ``pid`` [bytes] (0 if it is gone)."""
    try:
        text = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return 0
    found = re.search(r"^VmRSS:\s+(\d+) kB", text, re.MULTILINE)
    return int(found.group(1)) * 1024 if found else 0


@dataclass
class Counters:
    """The latest /diagnostics values of the controller, the simulator and the trajectory node, and the
    command shortfall at each simulator status (module docstring)."""

    controller: dict[str, str] = field(default_factory=dict)
    sim: dict[str, str] = field(default_factory=dict)
    repetitions: int = 0
    shortfall: int | None = None
    published: deque[tuple[int, int]] = field(default_factory=lambda: deque(maxlen=1000))  # (stamp, net count)

    def on_message(self, msg: Any) -> None:
        stamp = stamp_ns(msg.header.stamp)
        for status in msg.status:
            values = {kv.key: kv.value for kv in status.values}
            if status.name == "controller_node" and "cycles" in values:
                self.controller = values
                net = _int(values, "cycles") + _int(values, "safe_commands") - _int(values, "unmatched_commands")
                self.published.append((stamp, net))
            elif status.name == "sim_node":
                self.sim = values
                sent = [n for t, n in self.published if t <= stamp - MATCH_NS]
                if sent:
                    self.shortfall = sent[-1] - _int(values, "commands_received")
            elif status.name == "trajectory_node" and status.message == "complete":
                self.repetitions = int(values.get("repetitions", self.repetitions + 1))


def _int(values: dict[str, str], key: str) -> int:
    return int(values.get(key, 0))


def _final(lines: list[str], pattern: str) -> dict[str, int]:
    """Named integer groups of the last line matching ``pattern`` (a node's closing summary)."""
    for line in reversed(lines):
        found = re.search(pattern, line)
        if found:
            return {k: int(v) for k, v in found.groupdict().items()}
    return {}


CONTROLLER_SUMMARY = (r"(?P<cycles>\d+) cycles, (?P<missed>\d+) missed deadlines, (?P<failures>\d+) solver failures, "
                      r"(?P<fallbacks>\d+) solver fallbacks, (?P<rejected>\d+) rejected inputs, "
                      r"(?P<safe>\d+) safe commands, (?P<unmatched>\d+) unmatched commands, (?P<trips>\d+) watchdog trips")
SIM_SUMMARY = r"(?P<received>\d+) commands received, (?P<rejected>\d+) rejected, (?P<timeouts>\d+) command timeouts"


def _stop(proc: Process) -> None:
    if proc.popen.poll() is None:
        os.killpg(proc.popen.pid, signal.SIGINT)
        try:
            proc.popen.wait(STOP_WAIT_S)
        except subprocess.TimeoutExpired:
            pass  # Launch.stop escalates


def run_soak(minutes: float, scenario: str = "assembly", say: Callable[[str], None] = print) -> dict[str, Any]:
    """Run the soak; the result document (samples, per-node RSS, bursts, accounting, pass flags)."""
    duration = minutes * 60.0
    launch = Launch(echo=False)
    counters = Counters()
    samples: list[dict[str, Any]] = []
    procs: dict[str, Process] = {}
    try:
        diagnostics = {"/diagnostics": Topic("diagnostic_msgs/msg/DiagnosticArray", counters.on_message, 100)}
        with listen("_dualarm_soak_monitor", diagnostics) as listener:
            procs["sim_node"] = launch.start("sim_node", node_command("sim_node", ["-p", f"scenario:={scenario}"]))
            procs["controller_node"] = launch.start("controller_node", node_command("controller_node", []))
            procs["trajectory_node"] = launch.start("trajectory_node", node_command(
                "trajectory_node", ["-p", f"scenario:={scenario}", "-p", "repeat:=true"]))
            start = time.monotonic()
            next_sample = start
            next_report = start + 30.0
            while not listener.signalled and time.monotonic() - start < duration:
                listener.spin_once(0.05)
                now = time.monotonic()
                if now < next_sample:
                    continue
                next_sample += SAMPLE_S
                dead = [n for n, p in procs.items() if p.popen.poll() is not None]
                if dead:
                    raise RuntimeError(f"{', '.join(dead)} exited during the soak:\n"
                                       + "\n".join(procs[dead[0]].lines[-10:]))
                samples.append({"t_s": round(now - start, 2), "repetitions": counters.repetitions,
                                "cycles": _int(counters.controller, "cycles"),
                                "missed_deadlines": _int(counters.controller, "missed_deadlines"),
                                "safe_commands": _int(counters.controller, "safe_commands"),
                                "watchdog_trips": _int(counters.controller, "watchdog_trips"),
                                "commands_received": _int(counters.sim, "commands_received"),
                                "shortfall": counters.shortfall,
                                "rss": {n: rss_bytes(p.popen.pid) for n, p in procs.items()}})
                if now >= next_report:
                    next_report += 30.0
                    last = samples[-1]
                    say(f"{now - start:.0f}/{duration:.0f} s: {last['repetitions']} repetitions, {last['cycles']} "
                        f"cycles, {last['missed_deadlines']} missed deadlines, RSS " + ", ".join(
                            f"{n} {v / 2**20:.0f} MiB" for n, v in last["rss"].items()))
            for name in ("trajectory_node", "controller_node"):
                _stop(procs[name])
            time.sleep(1.0)  # commands in flight reach the simulator
            _stop(procs["sim_node"])
    finally:
        launch.stop()
    controller = _final(procs["controller_node"].lines, CONTROLLER_SUMMARY)
    sim = _final(procs["sim_node"].lines, SIM_SUMMARY)
    return summarize(samples, controller, sim, duration, scenario)


def summarize(samples: list[dict[str, Any]], controller: dict[str, int], sim: dict[str, int], duration: float,
              scenario: str) -> dict[str, Any]:
    """The soak's figures and pass flags from the samples and the closing counters."""
    warm = next((i for i, s in enumerate(samples) if s["repetitions"] >= 1 and s["t_s"] >= WARMUP_SHARE * duration),
                None)
    rss: dict[str, dict[str, float]] = {}
    for name in NODES:
        series = [s["rss"][name] for s in samples]
        if warm is None or not series[warm]:
            rss[name] = {"baseline_mib": float("nan"), "max_after_mib": float("nan"), "growth": float("nan")}
            continue
        base, top = series[warm], max(series[warm:])
        rss[name] = {"baseline_mib": base / 2**20, "max_after_mib": top / 2**20, "final_mib": series[-1] / 2**20,
                     "growth": (top - base) / base}
    per_window = [b["missed_deadlines"] - a["missed_deadlines"] for a, b in itertools.pairwise(samples)]
    steady = per_window[warm:] if warm is not None else per_window
    bursts = sum(1 for d in steady if d >= BURST)
    startup_missed = samples[warm]["missed_deadlines"] if warm is not None else None
    published = controller.get("cycles", 0) + controller.get("safe", 0)
    expected = published - controller.get("unmatched", 0)
    final_shortfall = expected - sim["received"] if controller and sim else None
    at_warmup = samples[warm]["shortfall"] if warm is not None else None
    lost = final_shortfall - at_warmup if final_shortfall is not None and at_warmup is not None else None
    accounted = lost is not None and abs(lost) <= IN_FLIGHT
    growth_ok = all(v["growth"] <= MAX_RSS_GROWTH for v in rss.values())  # nan (no warm-up) fails
    return {
        "scenario": scenario, "minutes": duration / 60.0, "samples": samples,
        "repetitions": samples[-1]["repetitions"] if samples else 0,
        "rss": rss, "rss_growth_ok": growth_ok,
        "missed_deadlines": controller.get("missed", 0), "max_missed_per_s": max(per_window, default=0),
        "seconds_with_missed": sum(1 for d in per_window if d > 0), "bursts": bursts, "bursts_ok": bursts == 0,
        "startup_missed": startup_missed, "max_missed_per_s_after_warmup": max(steady, default=0),
        "controller": controller, "sim": sim, "commands_published": published, "commands_expected": expected,
        "startup_shortfall": at_warmup, "final_shortfall": final_shortfall,
        "lost_after_startup": lost, "accounted": accounted,
        "load_independent_ok": growth_ok and accounted,
        "passed": growth_ok and bursts == 0 and accounted,
    }


def format_soak(doc: dict[str, Any]) -> str:
    c, s = doc["controller"], doc["sim"]
    lines = [f"# Soak: '{doc['scenario']}' on repeat for {doc['minutes']:.1f} min at 200 Hz over ROS", "",
             (f"{doc['repetitions']} repetitions; {'PASS' if doc['passed'] else 'FAIL'} (RSS growth and "
              f"accounting: {'pass' if doc['load_independent_ok'] else 'FAIL'}; deadline bursts: "
              f"{'pass' if doc['bursts_ok'] else 'FAIL'})"), "",
             "| node | RSS after warm-up [MiB] | largest after [MiB] | growth | ", "|---|---|---|---|"]
    for name, r in doc["rss"].items():
        lines.append(f"| {name} | {r['baseline_mib']:.1f} | {r['max_after_mib']:.1f} | {r['growth']:+.2%} |")
    lines += ["", f"- RSS growth <= {MAX_RSS_GROWTH:.0%}: {'yes' if doc['rss_growth_ok'] else 'NO'}",
              (f"- missed deadlines: {doc['missed_deadlines']} in {c.get('cycles', 0)} cycles, {doc['startup_missed']} "
               f"of them during the warm-up; {doc['seconds_with_missed']} one-second windows with any; at most "
               f"{doc['max_missed_per_s_after_warmup']} in one after the warm-up; bursts after the warm-up (>= {BURST} "
               f"in a second): {doc['bursts']}"),
              (f"- accounting: {c.get('cycles', 0)} cycles + {c.get('safe', 0)} safe commands = "
              f"{doc['commands_published']} published, {c.get('unmatched', 0)} while no subscriber was matched; "
              f"the simulator received {s.get('received', 'n/a')}; shortfall {doc['startup_shortfall']} at the end "
              f"of the warm-up (start-up discovery), {doc['final_shortfall']} at the end "
              f"({'no command lost after the start-up' if doc['accounted'] else 'COMMANDS LOST'}); "
              f"watchdog trips {c.get('trips', 0)}, solver failures {c.get('failures', 0)}, "
              f"solver fallbacks {c.get('fallbacks', 0)}, rejected inputs {c.get('rejected', 0)}, "
              f"command timeouts {s.get('timeouts', 'n/a')}")]
    return "\n".join(lines)


def write_soak(out: Path, doc: dict[str, Any]) -> None:
    out.mkdir(parents=True, exist_ok=True)
    (out / "soak.json").write_text(json.dumps(doc, indent=1) + "\n")
    (out / "soak.md").write_text(format_soak(doc) + "\n")
