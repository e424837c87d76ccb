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
import os
import signal
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from dualarm_control.app.bench.load import busy_core
from dualarm_control.errors import DualArmError
from dualarm_control.metrics import percentiles


def controller_cycles(bag: Path) -> dict[str, np.ndarray]:
    """Per-cycle controller figures from a bag's /diagnostics (status ``controller_node`` with a solver status);
    ``stamp`` is the message's header stamp [s] (wall clock in real time)."""
    from dualarm_control.app.record.bag import open_reader

    rows: dict[str, list[float]] = {"interval": [], "latency": [], "missed": [], "cycles": [], "failures": [],
                                    "stamp": [], "cycle_time": []}
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
                rows["stamp"].append(msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9)
                rows["cycle_time"].append(float(values.get("cycle_time_s", "nan")))
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


LOADS = ("none", "busy")
"""``--load``: nothing else running, or one core kept busy by a normal-priority process."""
SCHEDULINGS = ("rt", "normal")
PROCESSES = ("3", "2", "1")
"""``--processes``: the process layouts of ``dualarm launch --processes`` (3: each node its own)."""
"""``--scheduling``: the nodes' SCHED_FIFO ``thread_priority`` defaults, or normal scheduling (0)."""
NORMAL_SCHEDULING = "".join(f"{key}:\n  ros__parameters:\n    thread_priority: 0\n"
                            for key in ("/**", "controller_node", "sim_node", "trajectory_node"))
"""The parameter file of ``--scheduling normal``, passed after the user's ``--params`` files. rclpy
applies a node's sections in the order they first appear over all files (later files overwrite the
values), so a ``/**`` section alone would lose to a node's own section in an earlier user file; the
node sections make it win in rclpy and in :func:`dualarm_control.params.read_params_files` alike."""


def split_choices(text: str, valid: Sequence[str], option: str) -> list[str]:
    """Comma-separated values of ``option``, each one of ``valid`` (DualArmError naming the first that is not)."""
    values = [v.strip() for v in text.split(",") if v.strip()]
    for value in values or [""]:
        if value not in valid:
            raise DualArmError(f"{option}: unknown value {value!r}; valid choices: {', '.join(valid)}")
    return values


def tree_label(path: Path) -> str | None:
    """``git rev-parse --short HEAD`` of the checkout at ``path``, "+" appended when tracked files
    differ from it; None when ``path`` is not a git checkout."""
    def git(*args: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run(["git", "-C", str(path), *args], capture_output=True, text=True, check=False)

    try:
        head = git("rev-parse", "--short", "HEAD")
    except OSError:  # no git
        return None
    if head.returncode != 0:
        return None
    modified = git("status", "--porcelain", "--untracked-files=no").stdout.strip()
    return head.stdout.strip() + ("+" if modified else "")


def baseline_tree(path: Path) -> str:
    """The label of ``--baseline`` ``path``: a git checkout holding the dualarm_control and dualarm_sim
    packages (DualArmError naming the path otherwise)."""
    label = tree_label(path) if path.is_dir() else None
    if label is None or not all((path / pkg / "__init__.py").is_file() for pkg in ("dualarm_control", "dualarm_sim")):
        raise DualArmError(f"--baseline {path}: not a source checkout of dualarm_control "
                           "(e.g. git worktree add --detach /tmp/base REV)")
    return label


def current_tree() -> str:
    """The label of the tree this package is imported from ("installed" outside a checkout)."""
    return tree_label(Path(__file__).resolve().parents[3]) or "installed"


def tree_environment(path: Path) -> dict[str, str]:
    """Environment that makes a node process import the packages of the checkout at ``path``:
    first on PYTHONPATH, and no current directory ahead of it (``python -m`` puts it first)."""
    rest = os.environ.get("PYTHONPATH", "")
    return {"PYTHONPATH": str(path.resolve()) + (os.pathsep + rest if rest else ""), "PYTHONSAFEPATH": "1"}


@dataclass(frozen=True)
class Variant:
    """The settings of one launch: one row of the tables."""

    solver: str
    rate_hz: float
    load: str = "none"
    scheduling: str = "rt"
    tree: str = "current"
    baseline: Path | None = None
    """The checkout the node processes import (None: this one)."""
    view: bool | None = None
    """With the live view beside it (None: not a ``--with-view`` run)."""
    processes: int = 3
    """The nodes' process layout (``dualarm launch --processes``)."""

    def describe(self) -> str:
        view = " with dualarm view --save" if self.view else ""
        return (f"{self.solver} at {self.rate_hz:g} Hz, real time, {self.processes} processes, load {self.load}, "
                f"scheduling {self.scheduling}, tree {self.tree}{' (baseline)' if self.baseline else ''}{view}")


CONTAINER_MODULE = Path("dualarm_control/nodes/container.py")
"""Where a checkout has the one-process container (``dualarm launch --processes 1``)."""


def variants(solvers: Sequence[str], rates: Sequence[float], loads: Sequence[str] = ("none",),
             schedulings: Sequence[str] = ("rt",), with_view: bool = False,
             baseline: tuple[str, Path] | None = None, current: str = "current",
             processes: Sequence[int] = (3,)) -> list[Variant]:
    """Every launch in run order: per (solver, rate, load, scheduling, view), in each of the ``processes``
    layouts, the baseline tree's launch right before the current tree's, so both meet the same machine state
    (a baseline without ``cell_container``, an older tree, runs in separate processes, once)."""
    trees: list[tuple[str, Path | None, int]]
    if baseline is not None and (baseline[1] / CONTAINER_MODULE).is_file():
        trees = [tree for n in processes for tree in ((*baseline, n), (current, None, n))]
    else:
        trees = [*([(*baseline, 3)] if baseline else []), *((current, None, n) for n in processes)]
    return [Variant(solver, rate, load, sched, tree, base, view, n)
            for solver in solvers for rate in rates for load in loads for sched in schedulings
            for view in ((False, True) if with_view else (None,)) for tree, base, n in trees]


def run_variant(scenario: str, v: Variant, params: Sequence[str], timeout: float) -> dict[str, Any]:
    """One real-time launch of ``v`` recording /diagnostics, its node processes' CPU sampled; its row."""
    from dualarm_control.app.bench.cpu import cpu_figures, sampling
    from dualarm_control.app.run.launcher import launch_scenario

    with tempfile.TemporaryDirectory() as tmp:
        bag = Path(tmp) / "diagnostics"
        files = list(params)
        if v.scheduling == "normal":
            (Path(tmp) / "normal_scheduling.yaml").write_text(NORMAL_SCHEDULING)
            files.append(str(Path(tmp) / "normal_scheduling.yaml"))
        env = tree_environment(v.baseline) if v.baseline is not None else None
        view = start_live_view(Path(tmp) / "view.rrd") if v.view else None
        try:
            with busy_core(v.load == "busy"), sampling() as sampler:
                code = launch_scenario(scenario, files, ["-p", f"solver:={v.solver}"], False, bag, timeout,
                                       rate_hz=v.rate_hz, record_topics=("/diagnostics",), env=env,
                                       processes=v.processes)
        finally:
            view_exit = stop_live_view(view) if view is not None else None
        cycles = controller_cycles(bag)
        samples = sampler.samples
        first_cycle = (float(cycles["stamp"][0]) - samples[0].wall) if len(cycles["stamp"]) and samples else None
        row = {"solver": v.solver, "rate_hz": v.rate_hz, "load": v.load, "scheduling": v.scheduling,
               "tree": v.tree, "baseline": v.baseline is not None, "processes": v.processes, "exit": code,
               **summarize_cycles(cycles, 1.0 / v.rate_hz),
               "cpu": cpu_figures(samples, cycles["stamp"], cycles["cycles"], cycles["cycle_time"]),
               "cpu_samples": len(samples), "first_cycle_s": first_cycle}
        if v.view is not None:
            rrd = Path(tmp) / "view.rrd"
            row.update(view="rerun" if v.view else "none", view_exit=view_exit,
                       view_rrd_bytes=rrd.stat().st_size if v.view and rrd.exists() else None)
    return row


def run_realtime(scenario: str, solvers: Sequence[str], rates: Sequence[float],
                 timeout: float = 300.0, params: Sequence[str] = (), with_view: bool = False,
                 loads: Sequence[str] = ("none",), schedulings: Sequence[str] = ("rt",),
                 baseline: Path | None = None, processes: Sequence[int] = (3,)) -> list[dict[str, Any]]:
    """One real-time launch per (solver, rate, load, scheduling), ``params`` files passed to every node;
    the rows of the tables. ``with_view``: each launch twice in a row, without and with the live Rerun
    view beside it (row key "view"). ``baseline``: each launch also with the node processes importing
    that checkout, right before the current tree's (row keys "tree", "baseline"). ``processes``: the
    layouts of ``dualarm launch --processes`` to run (row key "processes")."""
    runs = variants(solvers, rates, loads, schedulings, with_view,
                    (baseline_tree(baseline), baseline) if baseline is not None else None, current_tree(), processes)
    rows = []
    for k, v in enumerate(runs, 1):
        print(f"=== [{k}/{len(runs)}] {v.describe()}", flush=True)
        rows.append(run_variant(scenario, v, params, timeout))
    return rows


def label_keys(rows: Sequence[dict[str, Any]]) -> list[str]:
    """The label columns the rows need: load and scheduling when a row is not the default (none, rt),
    tree when a row ran a ``--baseline``, view when the rows ran ``--with-view``."""
    shown = {"processes": any(r.get("processes", 3) != 3 for r in rows),
             "load": any(r.get("load", "none") != "none" for r in rows),
             "scheduling": any(r.get("scheduling", "rt") != "rt" for r in rows),
             "tree": any(r.get("baseline") for r in rows), "view": any("view" in r for r in rows)}
    return [key for key, on in shown.items() if on]


def _head(r: dict[str, Any], keys: Sequence[str]) -> str:
    return f"| {r['solver']} | {r['rate_hz']:g} | " + "".join(f"{r.get(k, '')} | " for k in keys)


def format_realtime(rows: Sequence[dict[str, Any]]) -> str:
    """Markdown table of the timing figures of :func:`run_realtime` rows (label columns as :func:`label_keys`)."""
    keys = label_keys(rows)
    lines = [("| solver | rate [Hz] | " + "".join(f"{k} | " for k in keys) + "cycles | missed deadlines | "
              "jitter p50 / p99 [ms] | state-to-command latency p50 / p99 [ms] | solver failures |"),
             "|" + "---|" * (7 + len(keys))]
    for r in rows:
        head = _head(r, keys)
        if not r.get("cycles"):
            lines.append(f"{head}0 (exit {r['exit']}) | | | | |")
            continue
        lines.append(f"{head}{r['cycles']} | {r['missed_deadlines']} "
                     f"({r['missed_share']:.2%}) | {r['jitter_p50_ms']:.3f} / {r['jitter_p99_ms']:.3f} | "
                     f"{r['latency_p50_ms']:.3f} / {r['latency_p99_ms']:.3f} | {r['solver_failures']} |")
    return "\n".join(lines)


def format_cpu(rows: Sequence[dict[str, Any]]) -> str:
    """Markdown table of the CPU figures of :func:`run_realtime` rows: per node cores and CPU per
    control cycle (total = main thread + other threads), the controller's control math per cycle,
    all nodes together."""
    from dualarm_control.app.bench.cpu import node_order

    keys = label_keys(rows)
    names = sorted({n for r in rows for n in r.get("cpu", {}).get("nodes", {})}, key=node_order)
    header = ("| solver | rate [Hz] | " + "".join(f"{k} | " for k in keys) + "window [s] | cycles | "
              "control math / cycle [ms, wall] | ")
    for name in names:
        short = name.removesuffix("_node")
        header += f"{short} [core] | {short} CPU / cycle = main + other [ms] | "
    header += "all nodes [core] | all nodes CPU / cycle [ms] |"
    columns = header.count(" | ") + 1
    lines = [header, "|" + "---|" * columns]
    for r in rows:
        cpu = r.get("cpu") or {}
        if not cpu:
            lines.append(_head(r, keys) + "no steady window |" + " |" * (columns - 3 - len(keys)))
            continue
        line = (_head(r, keys) + f"{cpu['window_s']:.1f} | {cpu['window_cycles']} | "
                f"{cpu['control_math_ms_per_cycle']:.3f} | ")
        for name in names:
            n = cpu["nodes"].get(name)
            line += (f"{n['cores']:.3f} | {n['cpu_ms_per_cycle']:.3f} = {n['main_ms_per_cycle']:.3f} + "
                     f"{n['other_ms_per_cycle']:.3f} | " if n else " | | ")
        lines.append(line + f"{cpu['all_nodes_cores']:.3f} | {cpu['all_nodes_ms_per_cycle']:.3f} |")
    return "\n".join(lines)


def write_realtime(out: Path, rows: Sequence[dict[str, Any]], scenario: str,
                   floor: Sequence[dict[str, Any]] = ()) -> None:
    """realtime.md and realtime.json; with ``floor`` rows (``--floor``) also their table and floor.json."""
    from dualarm_control.app.bench.floor import format_floor

    out.mkdir(parents=True, exist_ok=True)
    (out / "realtime.json").write_text(json.dumps(list(rows), indent=2) + "\n")
    text = (f"# Real-time runs over ROS ({scenario})\n\n{format_realtime(rows)}\n\n"
            f"## CPU of the nodes (steady window)\n\n{format_cpu(rows)}\n")
    if floor:
        (out / "floor.json").write_text(json.dumps(list(floor), indent=2) + "\n")
        text += f"\n## The machine's floor (no ROS: sleep to each period, spin the CPU per cycle)\n\n{format_floor(floor)}\n"
    (out / "realtime.md").write_text(text)
