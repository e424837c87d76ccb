"""The machine's floor for a periodic loop (``dualarm bench --realtime --floor``).

A process that does nothing but the shape of a control cycle: it sleeps until each period is due
(drift-free, as :class:`dualarm_control.ros.node.Ticker`), then spins for the CPU time one cycle of
the cell takes, and counts its missed deadlines exactly as the controller does
(:class:`dualarm_control.ros.inputs.CycleTiming`: an interval over 1.5 periods misses the periods
lost, a cycle finished more than a period after it was due misses one). No ROS, no Python work but
the spin: what it misses, any loop with that period and that CPU per cycle misses on this machine
with the same load and scheduling. The cell's missed deadlines are then read against it.

Why it is needed here: on the project's 2-core machine other tasks hold a core for 1.5-2.2 ms
bursts a few times a second (the sandbox's agent at nice -10, the kernel's kdamond; the kernel is
built without preemption of kernel code), and a thread under normal scheduling that wakes during
one waits for it (docs/bench.md, "The machine's floor").
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from dualarm_control.app.bench.load import busy_core
from dualarm_control.errors import DualArmError
from dualarm_control.metrics import percentiles
from dualarm_control.ros.inputs import CycleTiming

PRIORITY = 50
"""SCHED_FIFO priority of the probe under ``rt`` scheduling: the controller's default ``thread_priority``."""
SECONDS = 25.0
"""Length of one probe [s]: about the steady window of an assembly launch."""


def spin_cpu(seconds: float) -> None:
    """Busy for ``seconds`` of this thread's CPU time (time preempted by other tasks does not count)."""
    end = time.thread_time() + seconds
    while time.thread_time() < end:
        pass


def probe(period: float, work: float, seconds: float) -> dict[str, Any]:
    """Run the loop for ``seconds``: each ``period`` [s] wake when due, spin ``work`` [s] of CPU.

    Returns cycles, missed deadlines (CycleTiming's count and share of the cycles) and the wake-up
    lateness p50/p99/max [ms]. A wake-up more than a period late skips to the next due time, as the
    nodes' ticks do.
    """
    timing = CycleTiming(realtime=True)
    late: list[float] = []
    due = time.monotonic() + period
    end = due + seconds
    while due < end:
        delay = due - time.monotonic()
        if delay > 0.0:
            time.sleep(delay)
        woke, stamp = time.monotonic_ns(), time.time_ns()
        timing.arrival(woke, period)
        late.append(woke / 1e9 - due)
        spin_cpu(work)
        timing.command(stamp, woke, period)
        due += period
        if time.monotonic() - due > period:
            due = time.monotonic() + period
    cycles = len(late)
    p50, p99 = percentiles(np.array(late) * 1e3)
    return {"cycles": cycles, "missed_deadlines": timing.missed, "missed_share": timing.missed / max(cycles, 1),
            "late_p50_ms": p50, "late_p99_ms": p99, "late_max_ms": max(late) * 1e3 if late else float("nan")}


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m dualarm_control.app.bench.floor PERIOD_S WORK_S SECONDS PRIORITY``: one probe, a JSON line.

    PRIORITY > 0 runs it under SCHED_FIFO (``priority_granted`` false, and normal scheduling, where
    that is not permitted)."""
    period, work, seconds, priority = (float(a) for a in (sys.argv[1:] if argv is None else argv))
    granted = False
    if priority > 0:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(int(priority)))
            granted = True
        except (AttributeError, PermissionError, OSError):
            pass
    print(json.dumps({**probe(period, work, seconds), "priority_granted": granted}), flush=True)
    return 0


def run_floor(rate_hz: float, work_ms: float, load: str, scheduling: str, seconds: float = SECONDS) -> dict[str, Any]:
    """One probe in its own process at ``rate_hz`` with ``work_ms`` of CPU per cycle, one core kept busy
    when ``load`` is "busy", under SCHED_FIFO when ``scheduling`` is "rt"; its row."""
    command = [sys.executable, "-m", __name__, repr(1.0 / rate_hz), repr(work_ms / 1e3), repr(seconds),
               str(PRIORITY if scheduling == "rt" else 0)]
    with busy_core(load == "busy"):
        out = subprocess.run(command, check=False, capture_output=True, text=True, timeout=seconds + 60.0)
    if out.returncode != 0:
        raise DualArmError(f"floor probe at {rate_hz:g} Hz exited {out.returncode}: {out.stderr.strip()[-500:]}")
    return {"rate_hz": rate_hz, "load": load, "scheduling": scheduling, "work_ms": work_ms,
            **json.loads(out.stdout.splitlines()[-1])}


def floor_rows(rows: Sequence[dict[str, Any]], seconds: float = SECONDS) -> list[dict[str, Any]]:
    """A probe per (rate, load, scheduling) of the launch ``rows`` (of :func:`realtime.run_realtime`), with
    the CPU per cycle of the leanest launch of that group (its all-nodes CPU per control cycle)."""
    groups: dict[tuple[float, str, str], float] = {}
    for r in rows:
        cpu = (r.get("cpu") or {}).get("all_nodes_ms_per_cycle")
        if cpu is None:
            continue
        key = (r["rate_hz"], r.get("load", "none"), r.get("scheduling", "rt"))
        groups[key] = min(groups.get(key, cpu), cpu)
    out = []
    for k, ((rate, load, scheduling), work) in enumerate(groups.items(), 1):
        print(f"=== floor [{k}/{len(groups)}] {rate:g} Hz, load {load}, {scheduling}: {work:.3f} ms CPU per cycle, "
              f"{seconds:g} s", flush=True)
        out.append(run_floor(rate, work, load, scheduling, seconds))
    return out


def format_floor(rows: Sequence[dict[str, Any]]) -> str:
    """Markdown table of :func:`floor_rows`."""
    lines = [("| rate [Hz] | load | scheduling | CPU per cycle [ms] | cycles | missed deadlines | "
              "wake-up late p50 / p99 / max [ms] |"), "|" + "---|" * 7]
    for r in rows:
        sched = r["scheduling"] if r["priority_granted"] or r["scheduling"] != "rt" else "rt (not permitted)"
        lines.append(f"| {r['rate_hz']:g} | {r['load']} | {sched} | {r['work_ms']:.3f} | {r['cycles']} | "
                     f"{r['missed_deadlines']} ({r['missed_share']:.2%}) | {r['late_p50_ms']:.3f} / "
                     f"{r['late_p99_ms']:.3f} / {r['late_max_ms']:.2f} |")
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(main())
