"""``dualarm sweep`` (issue 28): rows as in one process, on a cluster, after an interruption, with errors.

Every Dask server binds to 127.0.0.1. Rows are compared bitwise except the wall-clock columns
(cycle time percentiles, wall time), which no two runs share.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import psutil
import pytest

from dualarm_control.app.cli import main
from dualarm_control.app.sweep.execute import run_sweep
from dualarm_control.app.sweep.run import WALL_COLUMNS, grid, task_groups
from dualarm_control.app.sweep.spec import SweepSpec, load_spec
from dualarm_control.app.sweep.store import done_keys, parts, read_table
from dualarm_control.app.sweep.tasks import TaskSampling
from dualarm_control.errors import DualArmError

SMOKE = Path(__file__).resolve().parents[1] / "config" / "sweeps" / "smoke.yaml"


def smoke(tasks: int, **changes: Any) -> SweepSpec:
    return replace(load_spec(SMOKE).with_tasks(tasks), **changes)


def deterministic(out: Path) -> list[dict[str, Any]]:
    return read_table(out).drop_columns(list(WALL_COLUMNS)).to_pylist()


@pytest.fixture(scope="module")
def reference(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The smoke sweep's 4 tasks run back to back in this process."""
    out = tmp_path_factory.mktemp("reference")
    result = run_sweep(smoke(4), out, workers=0, show_progress=False)
    assert result.ran == result.total == 12 and result.failed == 0
    return out


def test_a_dask_task_is_the_missing_runs_of_one_sampled_task() -> None:
    """What one worker gets: every missing run of one task, and only those, in grid order."""
    spec = smoke(3)
    keys = grid(spec)
    groups = task_groups(keys)
    assert [k for g in groups for k in g] == keys
    for group in groups:
        assert len({(k.robot, k.variant, k.seed, k.task) for k in group}) == 1
        assert [k.solver for k in group] == list(spec.solvers)
    partly_done = [k for k in keys if not (k.task == 1 and k.solver == spec.solvers[0])]
    assert len(spec.robots) == len(spec.variants) == 1
    assert [len(g) for g in task_groups(partly_done)] == [len(spec.solvers) - (task == 1) for task in range(3)]


def test_rows_hold_the_metrics(reference: Path) -> None:
    rows = read_table(reference).to_pylist()
    assert [r["key"] for r in rows] == sorted(k.text for k in grid(smoke(4)))
    for row in rows:
        assert row["error"] is None and row["steps"] > 0 and row["l0_mean"] > 0
        # measured 2026-12 (deterministic, 12 rows): 2.1e-6 to 2.9e-6 m, 3.4e-7 to 1.15e-5 rad; bounds 10 x the largest
        assert row["final_position_error_m"] < 2.9e-5 and row["final_orientation_error_rad"] < 1.2e-4, row
        assert row["joint_position_limit_violations"] == 0
        assert row["cycle_time_p99_s"] >= row["cycle_time_p50_s"] > 0


def test_local_cluster_rows_equal_one_process(reference: Path, tmp_path: Path) -> None:
    """A LocalCluster of 2 workers on 127.0.0.1, interrupted after 4 rows (the cluster shut down, the rows
    kept) and started again: the same rows as one process, bitwise, each key once."""
    seen: list[str] = []

    def interrupt(row: dict[str, Any]) -> None:
        seen.append(row["key"])
        if len(seen) == 4:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_sweep(smoke(4), tmp_path, workers=2, show_progress=False, on_row=interrupt)
    assert done_keys(tmp_path) == set(seen)
    result = run_sweep(smoke(4), tmp_path, workers=2, show_progress=False)
    assert (result.skipped, result.ran) == (4, 8)
    assert sum(len(read_table_of(p)) for p in parts(tmp_path)) == 12
    assert deterministic(tmp_path) == deterministic(reference)


def test_interrupted_then_restarted_runs_only_the_missing(reference: Path, tmp_path: Path) -> None:
    """Ctrl-C after 5 rows keeps them (batch of 2: two parts and the flushed remainder); the restart runs the
    other 7 and nothing else; the rows equal the uninterrupted run's."""
    spec = smoke(4, batch_size=2)
    seen: list[str] = []

    def interrupt(row: dict[str, Any]) -> None:
        seen.append(row["key"])
        if len(seen) == 5:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_sweep(spec, tmp_path, workers=0, show_progress=False, on_row=interrupt)
    assert done_keys(tmp_path) == set(seen) and len(parts(tmp_path)) == 3
    again: list[str] = []
    result = run_sweep(spec, tmp_path, workers=0, show_progress=False, on_row=lambda r: again.append(r["key"]))
    assert (result.skipped, result.ran) == (5, 7)
    assert set(again) == {k.text for k in grid(spec)} - set(seen)
    assert deterministic(tmp_path) == deterministic(reference)
    assert run_sweep(spec, tmp_path, workers=0, show_progress=False).ran == 0


def test_a_raising_run_is_a_row_with_its_error(tmp_path: Path) -> None:
    """An infeasible task (a 10 m clearance) raises in the run: the row carries the error, the sweep goes on."""
    spec = smoke(1, solvers=("standard_qp",), sampling=TaskSampling(clearance=10.0, max_attempts=2))
    result = run_sweep(spec, tmp_path, workers=0, show_progress=False)
    assert (result.ran, result.failed) == (1, 1)
    (row,) = read_table(tmp_path).to_pylist()
    assert "no feasible draw in 2 attempts" in row["error"] and row["steps"] == 0


def test_another_spec_into_the_same_output_is_refused(reference: Path) -> None:
    with pytest.raises(DualArmError, match=r"sweep\.settle_time was 0\.2, is 0\.3"):
        run_sweep(smoke(4, settle_time=0.3), reference, workers=0, show_progress=False)


def test_cli_sweep_and_report(reference: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sweep", str(SMOKE), "--tasks", "4", "--output", str(reference), "--no-progress"]) == 0
    assert "0 ran" in capsys.readouterr().out  # all 12 already there
    assert main(["sweep", "report", str(reference), "--output", str(tmp_path)]) == 0
    text = capsys.readouterr().out
    assert "l0(sparse_qp) / l0(standard_qp) | 4 |" in text
    for name in ("report.md", "l0_ratios.png", "final_errors.png", "tracking_errors.png", "cycle_times.png",
                 "joint_limit_margins.png", "repulsive_zone_time.png", "repulsive_zone_depth.png", "tradeoff.png"):
        assert (tmp_path / name).stat().st_size > 0
    assert "median depth-weighted zone time [joint s]" in text  # issue 43's columns
    assert "| lwr4_cell | default | sparse_qp | 4 |" in text.split("minus the hierarchical QP's")[1]  # paired, per task
    assert main(["sweep", "report"]) == 2


@pytest.mark.slow
def test_cli_scaling_runs_the_same_rows_three_ways(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``dualarm sweep scaling``: the same runs in this process, on one worker and on two, and with
    ``--interleave 1`` task by task on a kept worker and in this process; the table and the JSON hold
    every layout and every pair (timings are not judged), and every layout's rows are the same.
    ``slow`` (5-6 s, benchmark machinery): in the default run the rows on a two-worker local cluster
    equal one process's (``test_local_cluster_rows_equal_one_process``)."""
    import json

    allowed = os.sched_getaffinity(0)
    assert main(["sweep", "scaling", str(SMOKE), "--tasks", "2", "--output", str(tmp_path), "--interleave", "1"]) == 0
    assert os.sched_getaffinity(0) == allowed  # the pinning of the interleaved pairs is undone
    text = capsys.readouterr().out
    for layout in ("| this process | 6 | 0 |", "| 1 worker | 6 | 0 |", "| 2 workers | 6 | 0 |"):
        assert layout in text
    assert "One warm worker against this process, task by task (2 pairs, 1 pass, both on CPU " in text
    doc = json.loads((tmp_path / "scaling.json").read_text())
    assert [r["workers"] for r in doc["layouts"]] == [0, 1, 2]
    assert {"two_over_one_wall", "two_over_one_steady", "one_worker_overhead", "interleaved_overhead"} <= set(doc)
    fair = doc["interleaved"]
    assert len(fair["worker_run_time_s"]) == len(fair["process_run_time_s"]) == fair["tasks"] == 2
    assert fair["overhead_ci"][0] <= fair["overhead"] <= fair["overhead_ci"][1] and fair["cpu"] in allowed
    rows = [sorted(deterministic(tmp_path / f"rows_{w}"), key=lambda r: r["key"]) for w in (0, 1, 2)]
    rows += [sorted(deterministic(tmp_path / f"interleaved_{side}"), key=lambda r: r["key"])
             for side in ("process", "worker")]
    assert all(r == rows[0] for r in rows)
    assert main(["sweep", "scaling"]) == 2
    assert main(["sweep", "scaling", str(SMOKE), "--interleave", "-1"]) == 2


def test_the_local_cluster_listens_on_loopback_only(tmp_path: Path) -> None:
    """Every socket the local cluster listens on (scheduler, its HTTP server, workers, nannies: this
    process and its children) is on 127.0.0.1, and none on the dashboard's 8787."""

    seen: list[tuple[str, int]] = []

    def listening(_: dict[str, Any]) -> None:
        if not seen:
            me = psutil.Process()
            seen.extend(listening_sockets([me, *me.children(recursive=True)]))

    run_sweep(smoke(1), tmp_path, workers=2, show_progress=False, on_row=listening)
    assert len(seen) >= 5, seen  # the scheduler, its HTTP server, two workers, two nannies
    assert {ip for ip, _ in seen} == {"127.0.0.1"}, seen
    assert 8787 not in {port for _, port in seen}, seen


def listening_sockets(procs: list[psutil.Process]) -> list[tuple[str, int]]:
    """(address, port) of every socket ``procs`` listen on."""
    return [(c.laddr.ip, c.laddr.port) for proc in procs for c in proc.net_connections(kind="inet")
            if c.status == psutil.CONN_LISTEN]


def _wait_for(condition: Any, deadline_s: float, what: str) -> None:
    end = time.monotonic() + deadline_s
    while not condition():
        if time.monotonic() > end:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.2)


@pytest.mark.slow
def test_worker_killed_mid_sweep(tmp_path: Path) -> None:
    """A scheduler and two workers as processes on 127.0.0.1 (every socket they listen on, their HTTP
    servers' too); one worker SIGKILLed after 3 rows: the sweep completes, every key exactly once, the
    rows bitwise those of a one-process run."""
    dask = str(Path(sys.executable).with_name("dask"))
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(Path(__file__).resolve().parents[1]),
                                                                     os.environ.get("PYTHONPATH")]))}
    address_file = tmp_path / "scheduler.json"
    loopback = ["--host", "127.0.0.1", "--no-dashboard", "--dashboard-address", "127.0.0.1:0"]  # its HTTP server too
    procs = [subprocess.Popen([dask, "scheduler", *loopback, "--port", "0", "--scheduler-file", str(address_file)],
                              env=env, stderr=subprocess.DEVNULL)]
    try:
        _wait_for(address_file.exists, 60, "the scheduler's address")
        import json

        _wait_for(lambda: json.loads(address_file.read_text() or "{}").get("address"), 30, "the address")
        address = json.loads(address_file.read_text())["address"]
        assert address.startswith("tcp://127.0.0.1:")
        for _ in range(2):
            procs.append(subprocess.Popen([dask, "worker", address, *loopback, "--nthreads", "1", "--no-nanny"],
                                          env=env, stderr=subprocess.DEVNULL))
        from distributed import Client

        with Client(address) as client:
            _wait_for(lambda: len(client.scheduler_info()["workers"]) == 2, 60, "two workers")
        sockets = listening_sockets([psutil.Process(p.pid) for p in procs])
        assert len(sockets) >= 6 and {ip for ip, _ in sockets} == {"127.0.0.1"}, sockets
        spec = smoke(6, batch_size=2)
        rows: list[str] = []

        def kill_one(row: dict[str, Any]) -> None:
            rows.append(row["key"])
            if len(rows) == 3:
                procs[1].send_signal(signal.SIGKILL)

        result = run_sweep(spec, tmp_path / "cluster", scheduler=address, show_progress=False, on_row=kill_one)
        assert procs[1].wait(10) == -signal.SIGKILL
        keys = [k.text for k in grid(spec)]
        assert result.failed == 0 and sorted(rows) == sorted(keys)  # each once
        written = [r["key"] for f in parts(tmp_path / "cluster") for r in read_table_of(f)]
        assert sorted(written) == sorted(keys)
        run_sweep(spec, tmp_path / "one", workers=0, show_progress=False)
        assert deterministic(tmp_path / "cluster") == deterministic(tmp_path / "one")
    finally:
        for proc in reversed(procs):
            if proc.poll() is None:
                proc.terminate()
                try:
                    proc.wait(20)
                except subprocess.TimeoutExpired:
                    proc.kill()


def read_table_of(part: Path) -> list[dict[str, Any]]:
    import pyarrow.parquet as pq

    return pq.read_table(part, columns=["key"]).to_pylist()


def test_local_workers_run_without_dask_malloc_trim(tmp_path: Path) -> None:
    """The sweep's own workers start with one BLAS thread each, as dask's do, but without dask's
    MALLOC_TRIM_THRESHOLD_=65536 (glibc then trims the heap at every 64 KiB freed: the runs took 5-9 %
    longer, docs/sweep.md): read from the worker processes' own environment."""
    environments: list[dict[str, str]] = []
    ours = os.environ.get("MALLOC_TRIM_THRESHOLD_")  # before the cluster: dask's nanny writes into os.environ

    def read(_: dict[str, Any]) -> None:
        if not environments:
            children = psutil.Process().children(recursive=True)
            environments.extend(p.environ() for p in children if "OPENBLAS_NUM_THREADS" in p.environ())

    run_sweep(smoke(1), tmp_path, workers=1, show_progress=False, on_row=read)
    assert environments, "no worker process with dask's environment found"
    for env in environments:
        assert env["OPENBLAS_NUM_THREADS"] == env["OMP_NUM_THREADS"] == "1"
        assert env.get("MALLOC_TRIM_THRESHOLD_") == ours
