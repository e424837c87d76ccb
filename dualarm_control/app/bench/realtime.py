"""Real-time runs over ROS: missed deadlines, period jitter and state-to-command latency.

For each (solver, rate) the three nodes run the scenario in real time (``dualarm launch``)
while only ``/diagnostics`` is recorded; the figures are computed from every controller cycle
of the run (not a window): the controller publishes, per cycle, the joint-state inter-arrival
time and the state-to-command latency (state stamp to command publication, wall clock,
transport included), and its cumulative missed-deadline count. Percentiles only: the machine
is shared and noisy.

With ``--with-view`` each (solver, rate) runs twice in a row, without and then with ``dualarm view
--save`` (the Rerun live view, its own process) subscribed to the running cell: what the view costs
the control loop.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from dualarm_control.metrics import percentiles


def controller_cycles(bag: Path) -> dict[str, np.ndarray]:
    """Per-cycle controller figures from a bag's /diagnostics (status ``controller_node`` with a solver status)."""
    from dualarm_control.app.record.bag import open_reader

    rows: dict[str, list[float]] = {"interval": [], "latency": [], "missed": [], "cycles": [], "failures": []}
    reader = open_reader(bag)
    try:
        conns = [c for c in reader.connections if c.topic == "/diagnostics"]
        for conn, _, raw in reader.messages(connections=conns):
            msg: Any = reader.deserialize(raw, conn.msgtype)
            for status in msg.status:
                values = {kv.key: kv.value for kv in status.values}
                if status.name != "controller_node" or "state_interval_s" not in values:
                    continue
                rows["interval"].append(float(values["state_interval_s"]))
                rows["latency"].append(float(values["state_to_command_latency_s"]))
                rows["missed"].append(float(values["missed_deadlines"]))
                rows["cycles"].append(float(values["cycles"]))
                rows["failures"].append(float(values["solver_failures"]))
    finally:
        reader.close()
    return {k: np.array(v) for k, v in rows.items()}


def summarize_cycles(cycles: dict[str, np.ndarray], period: float) -> dict[str, Any]:
    """Missed deadlines (count and share), jitter |interval - T| and latency p50/p99 [ms]."""
    if not len(cycles["cycles"]):
        return {"cycles": 0}
    interval = cycles["interval"][np.isfinite(cycles["interval"])]
    jitter = np.abs(interval - period)
    n = int(cycles["cycles"][-1])
    missed = int(cycles["missed"][-1])
    j50, j99 = percentiles(jitter)
    l50, l99 = percentiles(cycles["latency"])
    return {
        "cycles": n,
        "missed_deadlines": missed,
        "missed_share": missed / max(n, 1),
        "jitter_p50_ms": j50 * 1e3,
        "jitter_p99_ms": j99 * 1e3,
        "latency_p50_ms": l50 * 1e3,
        "latency_p99_ms": l99 * 1e3,
        "solver_failures": int(cycles["failures"][-1]),
    }


VIEW_STOP_TIMEOUT_S = 60.0
"""How long the live view gets to flush and close its recording after SIGTERM [s]."""


def start_live_view(rrd: Path) -> subprocess.Popen[bytes]:
    """``dualarm view --save rrd`` on the running cell, in its own process (stop with :func:`stop_live_view`)."""
    return subprocess.Popen([sys.executable, "-m", "dualarm_control.app.cli", "view", "--save", str(rrd)],
                            stdout=subprocess.DEVNULL)


def stop_live_view(view: subprocess.Popen[bytes]) -> int:
    """SIGTERM (the view ends as on Ctrl-C, closing its recording); its exit code (killed after a timeout)."""
    view.send_signal(signal.SIGTERM)
    try:
        return view.wait(VIEW_STOP_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        view.kill()
        return view.wait()


def run_realtime(scenario: str, solvers: Sequence[str], rates: Sequence[float],
                 timeout: float = 300.0, params: Sequence[str] = (), with_view: bool = False) -> list[dict[str, Any]]:
    """One real-time launch per (solver, rate), ``params`` files passed to every node; the rows of the table.
    ``with_view``: each launch twice in a row, without and with the live Rerun view beside it (row key "view")."""
    from dualarm_control.app.run.launcher import launch_scenario

    rows = []
    for solver in solvers:
        for rate in rates:
            for view_on in ((False, True) if with_view else (False,)):
                with tempfile.TemporaryDirectory() as tmp:
                    bag = Path(tmp) / "diagnostics"
                    label = " with dualarm view --save" if view_on else ""
                    print(f"=== {solver} at {rate:g} Hz, real time{label}", flush=True)
                    view = start_live_view(Path(tmp) / "view.rrd") if view_on else None
                    try:
                        code = launch_scenario(scenario, list(params), ["-p", f"solver:={solver}"], False, bag,
                                               timeout, rate_hz=rate, record_topics=("/diagnostics",))
                    finally:
                        view_exit = stop_live_view(view) if view is not None else None
                    row = {"solver": solver, "rate_hz": rate, "exit": code,
                           **summarize_cycles(controller_cycles(bag), 1.0 / rate)}
                    if with_view:
                        rrd = Path(tmp) / "view.rrd"
                        row.update(view="rerun" if view_on else "none", view_exit=view_exit,
                                   view_rrd_bytes=rrd.stat().st_size if view_on and rrd.exists() else None)
                rows.append(row)
    return rows


def format_realtime(rows: Sequence[dict[str, Any]]) -> str:
    """Markdown table of :func:`run_realtime` rows (a "view" column when they were run ``with_view``)."""
    view = any("view" in r for r in rows)
    lines = [("| solver | rate [Hz] | " + ("view | " if view else "") + "cycles | missed deadlines | "
              "jitter p50 / p99 [ms] | state-to-command latency p50 / p99 [ms] | solver failures |"),
             "|" + "---|" * (8 if view else 7)]
    for r in rows:
        head = f"| {r['solver']} | {r['rate_hz']:g} | " + (f"{r.get('view', '')} | " if view else "")
        if not r.get("cycles"):
            lines.append(f"{head}0 (exit {r['exit']}) | | | | |")
            continue
        lines.append(f"{head}{r['cycles']} | {r['missed_deadlines']} "
                     f"({r['missed_share']:.2%}) | {r['jitter_p50_ms']:.3f} / {r['jitter_p99_ms']:.3f} | "
                     f"{r['latency_p50_ms']:.3f} / {r['latency_p99_ms']:.3f} | {r['solver_failures']} |")
    return "\n".join(lines)


def write_realtime(out: Path, rows: Sequence[dict[str, Any]], scenario: str) -> None:
    out.mkdir(parents=True, exist_ok=True)
    (out / "realtime.json").write_text(json.dumps(list(rows), indent=2) + "\n")
    (out / "realtime.md").write_text(f"# Real-time runs over ROS ({scenario})\n\n{format_realtime(rows)}\n")
