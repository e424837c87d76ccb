"""``dualarm sweep scaling SPEC.yaml``: the same runs back to back in this process, on one local
worker and on two, one after the other in one call (issue 28, docs/sweep.md "Workers").

Per layout: the wall time, the rate from the first row to the last (the local cluster's start
left out) and the sum of the runs' own wall times; then the two-worker rate over the one-worker
rate and each layout's run time over the runs in this process. Timings are of this machine at
this moment: ratios from one call, never a pass/fail verdict.

With ``rounds`` > 0 (``--interleave ROUNDS``), also the one-worker overhead measured fairly
(:func:`interleaved_overhead`, task by task): the layouts one after the other compare a fresh
worker process with this warm one, and the machine's speed drifts over minutes.
"""

from __future__ import annotations

import json
import os
import shutil
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from dualarm_control.app.sweep.execute import run_sweep
from dualarm_control.app.sweep.spec import SweepSpec
from dualarm_control.app.sweep.store import read_table

LAYOUTS = (0, 1, 2)
"""Workers per layout: 0 is every run back to back in this process (no Dask)."""


def measure_layout(spec: SweepSpec, out: Path, workers: int) -> dict[str, Any]:
    """Run the whole of ``spec`` into a fresh ``out`` with ``workers`` (0: this process); its timings."""
    shutil.rmtree(out, ignore_errors=True)
    stamps: list[float] = []
    start = time.perf_counter()
    result = run_sweep(spec, out, workers=workers, show_progress=False, on_row=lambda _: stamps.append(time.perf_counter()))
    wall = time.perf_counter() - start
    rows = read_table(out).to_pylist()
    steady = stamps[-1] - stamps[0] if len(stamps) > 1 else float("nan")
    return {"workers": workers, "runs": result.ran, "failed": result.failed, "wall_s": wall,
            "rate_per_s": result.ran / wall, "steady_rate_per_s": (len(stamps) - 1) / steady,
            "run_time_s": float(sum(r["wall_time_s"] for r in rows))}


def interleaved_overhead(spec: SweepSpec, out: Path, rounds: int,
                         progress: Callable[[str], None] | None = None, seed: int = 0,
                         cpu: int | None = None) -> dict[str, Any]:
    """One warm worker against this process, task by task: each task's runs (one Dask task) in this
    process and on a one-worker local cluster kept for the whole measurement, one right after the
    other, the order alternating from task to task (this process first, then the worker first: a
    drift of the machine's speed over seconds falls on both sides of every pair), ``rounds`` passes
    over the tasks after one pass on each side left out: a process runs the same runs faster once it
    has run many (measured: a process that had run the 90 runs before ran them 12-19 % faster than a
    fresh worker, and 3-5 % slower when it had not), and the two must be as warm.
    Both sides run on one CPU (this process's affinity set to it before the cluster starts, which
    its worker inherits; restored after): unpinned, each process keeps to the CPU it started on, and
    this machine's two CPUs differ in speed by up to 10 % for minutes, which the pairs cannot cancel
    (docs/sweep.md, "Workers"). ``cpu``: that CPU (default: the first this process may use).

    Returns per task the runs' own times [s] on each side (``process_run_time_s``,
    ``worker_run_time_s``), ``overhead`` (the worker's sum over this process's, minus 1), its 95 %
    bootstrap interval over the tasks (``overhead_ci``, 2000 resamples of the pairs, ``seed``), the
    median of the per-task ratios minus 1, and the worker's round trip per task beyond its runs'
    times (``dispatch_s``: submitting, the result's transfer; a sweep overlaps it with the next
    task). Every row is also written to ``out/interleaved_process`` and ``out/interleaved_worker``."""
    from contextlib import ExitStack

    import numpy as np
    from distributed import Client

    from dualarm_control.app.sweep.execute import local_cluster
    from dualarm_control.app.sweep.run import grid, run_runs, task_groups
    from dualarm_control.app.sweep.store import write_part

    groups = task_groups(grid(spec))
    here: list[float] = []
    worker: list[float] = []
    dispatch: list[float] = []
    rows: dict[str, list[dict[str, Any]]] = {"process": [], "worker": []}
    allowed = os.sched_getaffinity(0)
    cpu = min(allowed) if cpu is None else cpu
    with ExitStack() as stack:
        os.sched_setaffinity(0, {cpu})
        stack.callback(os.sched_setaffinity, 0, allowed)
        client = stack.enter_context(Client(local_cluster(stack, 1)))

        def on_worker(group: list[Any]) -> tuple[list[dict[str, Any]], float]:
            start = time.perf_counter()
            result = client.submit(run_runs, spec, group, pure=False).result()
            return result, time.perf_counter() - start

        for n, group in enumerate(groups):  # one pass on each side, left out: both as warm
            if progress is not None and (n % 10 == 0 or n == len(groups) - 1):
                progress(f"scaling: interleaved, warming both sides, task {n + 1}/{len(groups)}")
            run_runs(spec, group)
            on_worker(group)
        pairs = [(r, i, g) for r in range(rounds) for i, g in enumerate(groups)]
        for n, (r, i, group) in enumerate(pairs):
            if progress is not None and (n % 10 == 0 or n == len(pairs) - 1):
                progress(f"scaling: interleaved, task {n + 1}/{len(pairs)}")
            for side in (("process", "worker") if n % 2 == 0 else ("worker", "process")):
                if side == "process":
                    got = run_runs(spec, group)
                    here.append(sum(row["wall_time_s"] for row in got))
                else:
                    got, trip = on_worker(group)
                    worker.append(sum(row["wall_time_s"] for row in got))
                    dispatch.append(trip - worker[-1])
                if r == 0:
                    rows[side] += got
    for side, side_rows in rows.items():
        shutil.rmtree(out / f"interleaved_{side}", ignore_errors=True)
        write_part(out / f"interleaved_{side}", side_rows)
    a, b = np.array(worker), np.array(here)
    rng = np.random.default_rng(seed)
    picks = rng.integers(0, len(a), size=(2000, len(a)))
    boot = a[picks].sum(axis=1) / b[picks].sum(axis=1) - 1.0
    return {"rounds": rounds, "tasks": len(a), "cpu": cpu, "worker_run_time_s": worker, "process_run_time_s": here,
            "overhead": float(a.sum() / b.sum() - 1.0),
            "overhead_ci": [float(np.percentile(boot, 2.5)), float(np.percentile(boot, 97.5))],
            "median_task_overhead": float(np.median(a / b) - 1.0),
            "dispatch_s": [float(np.percentile(dispatch, 50)), float(np.percentile(dispatch, 99))]}


def scaling(spec: SweepSpec, out: Path, layouts: Sequence[int] = LAYOUTS,
            progress: Callable[[str], None] | None = None, rounds: int = 0) -> tuple[str, list[Path]]:
    """Measure ``layouts`` one after the other (module docstring); write scaling.md and scaling.json to ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    for workers in layouts:
        if progress is not None:
            progress(f"scaling: {spec.name}, {'this process' if workers == 0 else f'{workers} workers'}")
        rows.append(measure_layout(spec, out / f"rows_{workers}", workers))
    by = {r["workers"]: r for r in rows}
    lines = [f"# Sweep scaling: {spec.name}, {rows[0]['runs']} runs per layout", "",
             "| layout | runs | failed | wall [s] | runs/s | runs/s first to last row | run time [s] | run time / in this process |",
             "|---|---:|---:|---:|---:|---:|---:|---:|"]
    base = by.get(0, {}).get("run_time_s")
    for r in rows:
        name = "this process" if r["workers"] == 0 else f"{r['workers']} worker{'s' if r['workers'] > 1 else ''}"
        ratio = f"{r['run_time_s'] / base:.3f}" if base else "-"
        lines.append(f"| {name} | {r['runs']} | {r['failed']} | {r['wall_s']:.1f} | {r['rate_per_s']:.3f} | "
                     f"{r['steady_rate_per_s']:.3f} | {r['run_time_s']:.1f} | {ratio} |")
    summary: dict[str, Any] = {}
    if 1 in by and 2 in by:
        summary["two_over_one_wall"] = by[2]["rate_per_s"] / by[1]["rate_per_s"]
        summary["two_over_one_steady"] = by[2]["steady_rate_per_s"] / by[1]["steady_rate_per_s"]
        lines += ["", (f"Two workers / one: {summary['two_over_one_steady']:.3f}x the rate first to last row "
                       f"({summary['two_over_one_wall']:.3f}x in wall time).")]
    if 0 in by and 1 in by:
        summary["one_worker_overhead"] = by[1]["run_time_s"] / by[0]["run_time_s"] - 1.0
        lines += [(f"One worker's run time against the same runs in this process: "
                   f"{100 * summary['one_worker_overhead']:+.1f} %.")]
    if rounds > 0:
        fair = interleaved_overhead(spec, out, rounds, progress)
        summary["interleaved_overhead"] = fair["overhead"]
        summary["interleaved"] = fair
        low, high = fair["overhead_ci"]
        lines += [(f"One warm worker against this process, task by task ({fair['tasks']} pairs, {rounds} "
                   f"pass{'es' if rounds > 1 else ''}, both on CPU {fair['cpu']}; run time {sum(fair['worker_run_time_s']):.1f} s against "
                   f"{sum(fair['process_run_time_s']):.1f} s): {100 * fair['overhead']:+.1f} % "
                   f"[{100 * low:+.1f}, {100 * high:+.1f}] (95 % bootstrap over the tasks), median per task "
                   f"{100 * fair['median_task_overhead']:+.1f} %; the worker's round trip beyond its runs "
                   f"{1e3 * fair['dispatch_s'][0]:.1f} ms p50, {1e3 * fair['dispatch_s'][1]:.1f} ms p99 per task.")]
    text = "\n".join(lines) + "\n"
    md, js = out / "scaling.md", out / "scaling.json"
    md.write_text(text)
    js.write_text(json.dumps({"spec": spec.name, "layouts": rows, **summary}, indent=2) + "\n")
    return text, [md, js]
