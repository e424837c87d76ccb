"""CPU of the node processes, read from /proc while a real-time launch runs (``dualarm bench --realtime``).

A sampler thread of the bench process reads, every :data:`SAMPLE_PERIOD_S`, each node process's
utime + stime (``/proc/PID/stat``, fields 14 and 15, in clock ticks) and each of its threads'
(``/proc/PID/task/TID/stat``). The node processes are the bench's own children, named by the
module they run (``python -m MODULE``); the recorder (``dualarm bag record``) and the live view
(``dualarm view``) are tools, not nodes, and are left out.

The figures cover a window of steady motion (:func:`steady_window`): from :data:`SETTLE_S` after
every node process is up and the controller cycles, to the last sample before any node exits.
Per node: the process's CPU seconds (its own counter, which keeps the time of exited threads),
split into the main thread (tid == pid: Python, the executor, the callbacks) and the other
threads (the middleware: Fast DDS's ``dds.*`` threads, rclpy's). Cycles come from the
controller's ``/diagnostics`` (cumulative ``cycles`` at header stamps, wall clock in real time).

The parsing and the arithmetic are pure functions of the /proc text and of the samples.
"""

from __future__ import annotations

import os
import re
import threading
import time
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

CLOCK_TICKS = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100
"""Unit of utime and stime in /proc [ticks per second] (100 on Linux)."""
SAMPLE_PERIOD_S = 0.25
"""Time between two samples [s]."""
SETTLE_S = 2.0
"""The window starts this long after every node is up and the controller cycles [s]."""
NODE_MODULES = {
    "dualarm_control.nodes.controller_node": "controller_node",
    "dualarm_sim.sim_node": "sim_node",
    "dualarm_control.nodes.trajectory_node": "trajectory_node",
}
"""Module run by a node process -> the node's name (table order)."""
CLI_MODULE = "dualarm_control.app.cli"
CONTAINER_MODULE = "dualarm_control.nodes.container"
TOOL_VERBS = ("bag", "view")
"""``dualarm`` verbs run beside the nodes that are not nodes: the recorder and the live view."""


# --- /proc text (pure) ----------------------------------------------------------------------


def stat_fields(text: str) -> list[str]:
    """The fields of a ``/proc/PID/stat`` (or ``task/TID/stat``) line after ``pid (comm)``:
    element 0 is field 3 (state) of proc(5); ``comm`` may hold spaces and parentheses."""
    return text[text.rindex(")") + 1:].split()


def stat_ticks(text: str) -> int:
    """utime + stime of a stat line (proc(5) fields 14 and 15) [clock ticks]."""
    fields = stat_fields(text)
    return int(fields[11]) + int(fields[12])


def stat_ppid(text: str) -> int:
    """The parent's pid (proc(5) field 4)."""
    return int(stat_fields(text)[1])


def stat_running(text: str) -> bool:
    """False for a zombie or dead task (state Z, X or x): it has exited."""
    return stat_fields(text)[0] not in ("Z", "X", "x")


def module_of(argv: Sequence[str]) -> str | None:
    """The node a command line runs: its name for a node module (:data:`NODE_MODULES`), the nodes of a
    ``cell_container`` joined by ``+``, the module for any other ``python -m MODULE``; None for other command lines and for the tools
    (``dualarm_control.app.cli bag ...`` and ``... view``)."""
    if "-m" not in argv[:-1]:
        return None
    i = list(argv).index("-m")
    module = argv[i + 1]
    if module == CLI_MODULE and (len(argv) < i + 3 or argv[i + 2] in TOOL_VERBS):
        return None
    if module == CONTAINER_MODULE and "--nodes" in argv[:-1]:  # nodes sharing a process: "controller+trajectory"
        return "+".join(n.removesuffix("_node") for n in argv[list(argv).index("--nodes") + 1].split(","))
    return NODE_MODULES.get(module, module)


def scheduling_name(policy: int, priority: int) -> str:
    """``fifo 50``, ``rr 50``, ``other``... for ``os.sched_getscheduler`` / ``sched_getparam`` values."""
    names = {getattr(os, f"SCHED_{n.upper()}", -1): n for n in ("other", "fifo", "rr", "batch", "idle")}
    name = names.get(policy, str(policy))
    return f"{name} {priority}" if name in ("fifo", "rr") else name


def thread_kind(name: str) -> str:
    """A thread's name without its trailing number (``dds.udp.7412`` -> ``dds.udp``), to add up
    threads of one kind."""
    return re.sub(r"[.\-_ ]?\d+$", "", name) or name


# --- samples ----------------------------------------------------------------------------------


@dataclass(frozen=True)
class ProcessSample:
    """One reading of a process: its utime + stime and each live thread's [clock ticks]."""

    pid: int
    ticks: int
    threads: Mapping[int, int]
    names: Mapping[int, str] = field(default_factory=dict)
    """Thread id -> thread name (``/proc/PID/task/TID/comm``)."""
    scheduling: str = ""
    """The main thread's scheduling (:func:`scheduling_name`)."""


@dataclass(frozen=True)
class Sample:
    """The node processes alive at wall-clock time ``wall`` [s, ``time.time()``], by node name."""

    wall: float
    nodes: Mapping[str, ProcessSample]


@dataclass(frozen=True)
class CpuSplit:
    """CPU seconds of one process over a window, and its split by thread."""

    total_s: float
    main_s: float
    other_s: float
    kinds: dict[str, float]
    """CPU seconds of the other threads by :func:`thread_kind`."""
    threads: int
    """Threads seen in the window (the kernel truncates each thread's counter to a tick, so main +
    other may fall short of total by up to this many ticks)."""


def cpu_split(samples: Sequence[ProcessSample]) -> CpuSplit:
    """CPU of one process from its first to its last sample in ``samples`` (same pid).

    total = the process counter's difference; main = thread ``pid``'s; other = every other
    thread's last reading minus its first-sample reading (0 for a thread started in the window).
    main + other equals total within rounding: each counter is truncated to a tick, and a file is read
    after the other; a thread that exited in the window leaves its ticks after its last sample in
    total only."""
    first, last = samples[0], samples[-1]
    latest: dict[int, int] = {}
    names: dict[int, str] = {}
    for s in samples:
        latest.update(s.threads)
        names.update(s.names)
    delta = {tid: ticks - first.threads.get(tid, 0) for tid, ticks in latest.items()}
    kinds: dict[str, float] = {}
    for tid, ticks in delta.items():
        if tid != first.pid:
            kind = thread_kind(names.get(tid, "?"))
            kinds[kind] = kinds.get(kind, 0.0) + ticks / CLOCK_TICKS
    return CpuSplit(total_s=(last.ticks - first.ticks) / CLOCK_TICKS, main_s=delta.get(first.pid, 0) / CLOCK_TICKS,
                    other_s=sum(v for tid, v in delta.items() if tid != first.pid) / CLOCK_TICKS,
                    kinds=dict(sorted(kinds.items(), key=lambda kv: -kv[1])), threads=len(latest))


def steady_window(samples: Sequence[Sample], first_cycle: float, settle: float = SETTLE_S) -> tuple[int, int] | None:
    """Indices (first, last) of the steady window in ``samples``: from the first sample ``settle``
    [s] after every node seen in the run is up and ``first_cycle`` (wall time of the controller's
    first cycle [s]), to the last sample before any node is missing; None if that is empty."""
    every = set().union(*(s.nodes for s in samples)) if samples else set()
    complete = [bool(every) and every <= set(s.nodes) for s in samples]
    if not any(complete):
        return None
    up = samples[complete.index(True)].wall
    start = max(up, first_cycle) + settle
    first = next((i for i, s in enumerate(samples) if complete[i] and s.wall >= start), None)
    if first is None:
        return None
    last = first
    while last + 1 < len(samples) and complete[last + 1]:
        last += 1
    return (first, last) if last > first else None


def value_at(stamps: np.ndarray, values: np.ndarray, t: float) -> float:
    """``values`` of the last entry stamped at or before ``t`` (stamps ascending); 0 before the first."""
    i = int(np.searchsorted(stamps, t, side="right"))
    return float(values[i - 1]) if i else 0.0


def cpu_figures(samples: Sequence[Sample], stamps: np.ndarray, cycles: np.ndarray, cycle_time: np.ndarray,
                settle: float = SETTLE_S) -> dict[str, Any]:
    """The CPU figures of one launch over its steady window ({} when there is none).

    ``stamps`` [s, wall clock], ``cycles`` (cumulative count) and ``cycle_time`` [s] are the
    controller's per-cycle /diagnostics. Per node: cores = CPU s / wall s; CPU per cycle [ms] =
    CPU s / cycles in the window, in total, main thread and other threads; the main thread's
    scheduling at the window's end (e.g. ``fifo 50``, ``other``). Control math per cycle
    [ms]: the mean of the controller's ``cycle_time_s`` (a wall time: kinematics and solve,
    preemption included) over the cycles reported in the window (their sum: ``control_math_s``;
    the mean stays right if the controller reports only some cycles)."""
    if not len(stamps):
        return {}
    window = steady_window(samples, float(stamps[0]), settle)
    if window is None:
        return {}
    a, b = window
    t0, t1 = samples[a].wall, samples[b].wall
    wall = t1 - t0
    n = value_at(stamps, cycles, t1) - value_at(stamps, cycles, t0)
    if n <= 0:
        return {}
    inside = (stamps > t0) & (stamps <= t1)
    names = sorted(samples[a].nodes, key=node_order)
    nodes: dict[str, dict[str, Any]] = {}
    for name in names:
        split = cpu_split([s.nodes[name] for s in samples[a:b + 1] if s.nodes[name].pid == samples[a].nodes[name].pid])
        nodes[name] = {"cores": split.total_s / wall, "cpu_ms_per_cycle": split.total_s / n * 1e3,
                       "main_ms_per_cycle": split.main_s / n * 1e3, "other_ms_per_cycle": split.other_s / n * 1e3,
                       "cpu_s": split.total_s, "main_s": split.main_s, "other_s": split.other_s,
                       "other_threads_s": split.kinds, "threads": split.threads,
                       "scheduling": samples[b].nodes[name].scheduling}
    total = sum(float(v["cpu_s"]) for v in nodes.values())
    return {"window_s": wall, "window_cycles": int(n), "nodes": nodes, "all_nodes_cores": total / wall,
            "all_nodes_ms_per_cycle": total / n * 1e3,
            "control_math_ms_per_cycle": float(np.mean(cycle_time[inside])) * 1e3 if inside.any() else float("nan"),
            "control_math_s": float(np.sum(cycle_time[inside])), "control_math_reports": int(inside.sum())}


def node_order(name: str) -> tuple[int, str]:
    """Table order: the three nodes as in :data:`NODE_MODULES`, then any other module by name."""
    order = list(NODE_MODULES.values())
    return (order.index(name), "") if name in order else (len(order), name)


# --- reading /proc ----------------------------------------------------------------------------


def child_pids(pid: int) -> list[int]:
    """Children of process ``pid`` (``/proc/PID/task/*/children``)."""
    out: list[int] = []
    for children in Path(f"/proc/{pid}/task").glob("*/children"):
        try:
            out += [int(p) for p in children.read_text().split()]
        except OSError:
            continue
    return out


def read_process(pid: int) -> ProcessSample | None:
    """One reading of process ``pid`` and its threads; None once it has exited."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
        threads: dict[int, int] = {}
        names: dict[int, str] = {}
        for task in Path(f"/proc/{pid}/task").iterdir():
            try:
                threads[int(task.name)] = stat_ticks((task / "stat").read_text())
                names[int(task.name)] = (task / "comm").read_text().strip()
            except OSError:  # the thread exited between listing and reading
                continue
    except OSError:
        return None
    if not stat_running(stat):
        return None
    try:
        scheduling = scheduling_name(os.sched_getscheduler(pid), os.sched_getparam(pid).sched_priority)
    except OSError:
        scheduling = "?"
    return ProcessSample(pid, stat_ticks(stat), threads, names, scheduling)


class CpuSampler:
    """Samples the CPU of this process's node children in a thread, between :meth:`start` and
    :meth:`stop` (or in ``with sampling() as sampler:``)."""

    def __init__(self, period: float = SAMPLE_PERIOD_S) -> None:
        self.period = period
        self.samples: list[Sample] = []
        self._names: dict[int, str | None] = {}
        self._own = Path("/proc/self/cmdline").read_bytes()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="cpu-sampler", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        self._thread.join()

    def _run(self) -> None:
        while not self._stop.is_set():
            self.samples.append(self.sample())
            self._stop.wait(self.period)

    def _name(self, pid: int) -> str | None:
        """The node name of child ``pid``, cached once its command line is the node's (a child
        between fork and exec still shows this process's command line)."""
        if pid in self._names:
            return self._names[pid]
        try:
            raw = Path(f"/proc/{pid}/cmdline").read_bytes()
        except OSError:
            return None
        if raw == self._own:
            return None
        name = module_of([a.decode(errors="replace") for a in raw.split(b"\0") if a])
        self._names[pid] = name
        return name

    def sample(self) -> Sample:
        wall = time.time()
        nodes: dict[str, ProcessSample] = {}
        for pid in child_pids(os.getpid()):
            name = self._name(pid)
            reading = read_process(pid) if name is not None else None
            if name is not None and reading is not None:
                nodes[name] = reading
        return Sample(wall, nodes)


@contextmanager
def sampling(period: float = SAMPLE_PERIOD_S) -> Iterator[CpuSampler]:
    """A :class:`CpuSampler` running while in the block."""
    sampler = CpuSampler(period)
    sampler.start()
    try:
        yield sampler
    finally:
        sampler.stop()
