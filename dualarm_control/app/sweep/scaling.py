"""``dualarm sweep scaling SPEC.yaml``: the same runs back to back in this process, on one local
worker and on two, one after the other in one call (issue 28, docs/sweep.md "Workers").

Per layout: the wall time, the rate from the first row to the last (the local cluster's start
left out) and the sum of the runs' own wall times; then the two-worker rate over the one-worker
rate and each layout's run time over the runs in this process. Timings are of this machine at
this moment: ratios from one call, never a pass/fail verdict.

With ``rounds`` > 0 (``--interleave ROUNDS``), also the one-worker overhead measured fairly
(:func:`interleaved_overhead`): the layouts one after the other compare a fresh worker process
with this warm one, and the machine's speed drifts over minutes.
"""

from __future__ import annotations

import json
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
                         progress: Callable[[str], None] | None = None) -> dict[str, Any]:
    """One warm worker against this process: the whole of ``spec`` on a one-worker local cluster kept
    for every round, and back to back in this process, alternately (worker, this process; then this
    process, worker; ...: a drift of the machine's speed falls on both), ``rounds`` times each after
    one round each that is left out (each process's start: imports, models, memory). Returns the run
    times [s] of the measured rounds and ``overhead``, the worker's sum over this process's, minus 1."""
    from contextlib import ExitStack

    from dualarm_control.app.sweep.execute import local_cluster

    times: dict[int, list[float]] = {0: [], 1: []}
    with ExitStack() as stack:
        address = local_cluster(stack, 1).scheduler_address
        order = [1, 0] + [w for r in range(rounds) for w in ((0, 1) if r % 2 == 0 else (1, 0))]
        for i, workers in enumerate(order):
            if progress is not None:
                progress(f"scaling: interleaved {i + 1}/{len(order)}, {'one worker' if workers else 'this process'}")
            segment = out / f"interleaved_{i}"
            shutil.rmtree(segment, ignore_errors=True)
            run_sweep(spec, segment, scheduler=address if workers else None, workers=0, show_progress=False)
            times[workers].append(float(sum(r["wall_time_s"] for r in read_table(segment).to_pylist())))
    worker, here = times[1][1:], times[0][1:]
    return {"rounds": rounds, "worker_run_time_s": times[1], "process_run_time_s": times[0],
            "overhead": sum(worker) / sum(here) - 1.0}


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
        lines += [(f"One warm worker against this process, interleaved ({rounds} rounds each after one left out; "
                   f"run times [s] worker {', '.join(f'{t:.1f}' for t in fair['worker_run_time_s'])}, this process "
                   f"{', '.join(f'{t:.1f}' for t in fair['process_run_time_s'])}): {100 * fair['overhead']:+.1f} %.")]
    text = "\n".join(lines) + "\n"
    md, js = out / "scaling.md", out / "scaling.json"
    md.write_text(text)
    js.write_text(json.dumps({"spec": spec.name, "layouts": rows, **summary}, indent=2) + "\n")
    return text, [md, js]
