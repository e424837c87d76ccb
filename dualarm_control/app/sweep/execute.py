"""Running a sweep: the missing runs of the grid, on Dask (or in this process), rows to Parquet as they come.

* **Cluster**: ``scheduler`` (``tcp://HOST:PORT``, an existing ``dask scheduler``) or else a
  ``LocalCluster`` of ``workers`` processes (one thread each) on 127.0.0.1, no dashboard, no
  worker profiler, the workers' event loops woken seldom (:data:`LOCAL_WORKER_CONFIG`);
  ``workers=0`` runs every run back to back in this process (no Dask: the reference run).
* **Nothing twice**: the keys already in the output are skipped; the missing runs of one task (its
  solvers) are one Dask task, keyed by their run keys, with ``retries`` (a task lost with its
  worker is run again elsewhere): the task is sampled once, on one worker, as in one process.
* **Nothing lost**: rows are written every ``batch_size`` results and at the end, also on Ctrl-C
  (then the KeyboardInterrupt goes on); a run that raises is already a row (:func:`run_one`).
* **Nothing wrong**: ``DIR/spec.json`` holds the spec the rows were made with (all but the number of
  tasks); a sweep of a different spec into the same DIR is refused, naming the first key that differs.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Callable, Iterator
from contextlib import ExitStack
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

from tqdm import tqdm

from dualarm_control.app.sweep.run import RunKey, grid, run_one, run_runs, task_groups
from dualarm_control.app.sweep.spec import SweepSpec
from dualarm_control.app.sweep.store import done_keys, write_part
from dualarm_control.errors import DualArmError

LOCALHOST = "127.0.0.1"
LOCAL_WORKER_CONFIG = {
    "distributed.worker.profile.enabled": False,  # the statistical profiler samples the run's thread every 10 ms
    "distributed.admin.tick.interval": "10s",  # the event loop's blocking check (default 20 ms)
    "distributed.admin.system-monitor.interval": "60s",  # psutil's CPU/memory/network figures (default 0.5 s)
    "distributed.worker.memory.monitor-interval": "60s",  # the memory limits' check (default 0.1 s)
    # dask's environment for the worker processes without its MALLOC_TRIM_THRESHOLD_=65536: glibc then
    # gives memory back to the system at every 64 KiB freed, and the runs took 5-9 % longer (measured)
    "distributed.nanny.pre-spawn-environ": {"OMP_NUM_THREADS": 1, "MKL_NUM_THREADS": 1, "OPENBLAS_NUM_THREADS": 1},
}
"""The dask settings of a sweep's own LocalCluster: a run is CPU-bound Python in the worker's one
thread, and every wake-up of the worker's event loop takes the GIL from it. Measured here (16
LWR4 tasks, 45 runs, one worker against the same runs back to back in one process, each figure
one run): +58 % and +64 % with dask's defaults; +2.4 % to +10.7 % (median 4.4 %, 4 runs) with
these; +8.5 % to +19.8 % with the memory check every 5 s (docs/sweep.md). A run's memory is
flat (about 400 MB), so a minute between memory checks costs nothing, and nothing needs dask's
``MALLOC_TRIM_THRESHOLD_`` (paired task by task, the worker's runs +6.0 % and +8.1 % with it,
+0.4 % and -3.0 % without). An existing cluster (``--scheduler``) keeps its own settings."""


@dataclass(frozen=True)
class SweepResult:
    """What a sweep did: ``total`` runs in the grid, ``skipped`` (already in the output), ``ran``, ``failed``."""

    total: int
    skipped: int
    ran: int
    failed: int


SPEC_FILE = "spec.json"


def check_spec(spec: SweepSpec, out: Path) -> None:
    """Record ``spec`` in ``out`` or check it is the one recorded (DualArmError naming the key that differs)."""
    doc = json.loads(json.dumps(asdict(replace(spec, tasks=1))))
    doc.pop("tasks")
    path = out / SPEC_FILE
    if path.exists():
        old = json.loads(path.read_text())
        for key in sorted(set(doc) | set(old)):
            if doc.get(key) != old.get(key):
                raise DualArmError(f"{out} holds the rows of another sweep spec: sweep.{key} was {old.get(key)!r}, "
                                   f"is {doc.get(key)!r} (use another --output)")
        return
    out.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(doc, indent=2) + "\n")


def missing_runs(spec: SweepSpec, out: Path) -> tuple[list[RunKey], int]:
    """The grid's runs without a row in ``out``, and the grid's size."""
    keys = grid(spec)
    done = done_keys(out)
    return [k for k in keys if k.text not in done], len(keys)


def _in_process(spec: SweepSpec, keys: list[RunKey]) -> Iterator[dict[str, Any]]:
    for key in keys:
        yield run_one(spec, key)


def local_cluster(stack: ExitStack, workers: int) -> Any:
    """A sweep's own LocalCluster of ``workers`` one-thread worker processes on 127.0.0.1, with
    :data:`LOCAL_WORKER_CONFIG`, closed with ``stack``: no dashboard; the scheduler's HTTP server
    (health, metrics) on a free port of 127.0.0.1, not 8787."""
    import dask
    from distributed import LocalCluster

    stack.enter_context(dask.config.set(LOCAL_WORKER_CONFIG))
    return stack.enter_context(LocalCluster(host=LOCALHOST, n_workers=workers, threads_per_worker=1, processes=True,
                                            dashboard_address=None,
                                            scheduler_kwargs={"dashboard_address": f"{LOCALHOST}:0"}))


def _on_dask(spec: SweepSpec, keys: list[RunKey], stack: ExitStack, scheduler: str | None,
             workers: int) -> Iterator[dict[str, Any]]:
    from distributed import Client, as_completed

    if scheduler is None:
        client = stack.enter_context(Client(local_cluster(stack, workers)))
    else:
        client = stack.enter_context(Client(scheduler))
    futures = [client.submit(run_runs, spec, group, key=f"sweep-{spec.name}-{'+'.join(k.text for k in group)}",
                             retries=spec.retries, pure=False) for group in task_groups(keys)]
    for future in as_completed(futures):
        yield from future.result()
        future.release()


def run_sweep(spec: SweepSpec, out: Path, scheduler: str | None = None, workers: int = 2,
              show_progress: bool = True, on_row: Callable[[dict[str, Any]], None] | None = None) -> SweepResult:
    """Run the missing runs of ``spec`` into the Parquet dataset ``out`` (module docstring)."""
    check_spec(spec, out)
    keys, total = missing_runs(spec, out)
    failed, ran = 0, 0
    batch: list[dict[str, Any]] = []
    bar = tqdm(total=total, initial=total - len(keys), desc=f"sweep {spec.name}", unit="run", file=sys.stderr,
               disable=not show_progress, mininterval=0.5 if sys.stderr.isatty() else 10.0, smoothing=0.05)
    with ExitStack() as stack:
        rows = (_in_process(spec, keys) if workers == 0 and scheduler is None
                else _on_dask(spec, keys, stack, scheduler, workers)) if keys else iter(())
        try:
            for row in rows:
                batch.append(row)
                ran += 1
                failed += row["error"] is not None
                bar.update(1)
                bar.set_postfix(failures=failed, refresh=False)
                if on_row is not None:
                    on_row(row)
                if len(batch) >= spec.batch_size:
                    write_part(out, batch)
                    batch = []
        finally:  # Ctrl-C, a lost scheduler: what arrived is written
            write_part(out, batch)
            bar.close()
    return SweepResult(total, total - len(keys), ran, failed)
