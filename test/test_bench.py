"""`dualarm bench` end to end on a tiny random set (no timing asserts: speed goes into the bench)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from dualarm_control.app.bench.suite import run_bench, solver_configs
from dualarm_control.app.cli import main
from dualarm_control.controller import ControllerParams
from dualarm_control.solvers import make_solver


def test_bench_writes_every_part(tmp_path: Path) -> None:
    """bench.json has the random set (every accepted solver x back-end), refusals, exactness and scaling."""
    argv = ["bench", "--scenario", "none", "--cases", "6", "--solver", "standard_qp,sparse_qp",
            "--backend", "daqp,quadprog", "--output", str(tmp_path)]
    assert main(argv) == 0
    record = json.loads((tmp_path / "bench.json").read_text())
    rows = record["random"]["rows"]
    assert {"standard_qp | daqp", "standard_qp | quadprog", "sparse_qp | daqp"} <= set(rows)
    assert "sparse_qp | quadprog" in record["refused"] and "semi-definite" in record["refused"]["sparse_qp | quadprog"]
    for name in ("standard_qp | daqp", "sparse_qp | daqp"):
        row = rows[name]
        assert row["failures"] == 0 and row["samples"] == 6
        assert 0 <= row["max_bound_excess"] <= make_solver(name.split(" | ")[0]).bound_tolerance
        assert 0 < row["cycle_p50_ms"] <= row["cycle_p99_ms"]
        assert row[record["random"]["ratio_columns"][0]] > 0
    assert rows["sparse_qp | daqp"]["active_joints_max"] <= 6
    assert record["exactness"]["cases"] == 6
    assert {r["arms"] for r in record["scaling"].values()} == {2, 3, 4}
    text = (tmp_path / "bench.md").read_text()
    assert "| sparse_qp | daqp |" in text and "Exactness" in text and "Scaling" in text


def test_pseudo_inverse_is_listed_once() -> None:
    """A solver without a QP does not depend on the back-end: one row, back-end '-'."""
    configs, refused = solver_configs(ControllerParams(), ["pseudo_inverse"], ["daqp", "proxsuite"])
    assert list(configs) == ["pseudo_inverse | -"] and not refused


def test_unknown_backend_exits_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "--scenario", "none", "--backend", "nope", "--output", str(tmp_path)]) == 2
    assert "nope" in capsys.readouterr().err


def test_run_bench_without_scenario_has_no_scenario_part() -> None:
    record = run_bench(None, ["standard_qp"], ["daqp"], count=4, scaling_arms=(2,))
    assert "scenario" not in record and record["random"]["cases"] == 4


def test_realtime_bench_refuses_a_missing_params_file(tmp_path: Path) -> None:
    """`dualarm bench --realtime --params F`: a missing file exits 2 before any node starts."""
    import subprocess
    import sys

    out = subprocess.run([sys.executable, "-m", "dualarm_control.app.cli", "bench", "--realtime", "--rates", "1000",
                          "--params", str(tmp_path / "missing.yaml"), "--output", str(tmp_path)],
                         check=False, capture_output=True, text=True, timeout=120)
    assert out.returncode == 2 and "file not found" in out.stderr
    assert not (tmp_path / "realtime.md").exists()


def test_the_1khz_realtime_params_file_sets_only_the_trajectory_nodes_scheduling() -> None:
    from dualarm_control.paths import config_path
    from dualarm_control.ros.node import priority_from_args

    path = str(config_path("realtime_1khz.yaml"))
    args = ["x", "--ros-args", "--params-file", path]
    assert priority_from_args(args, 40, "trajectory_node") == 0
    assert priority_from_args(args, 50, "controller_node") == 50 and priority_from_args(args, 50, "sim_node") == 50


def test_message_bench_times_both_paths(tmp_path: Path) -> None:
    """`dualarm bench --messages`: every per-period message timed through rclpy objects and as CDR
    bytes in one run (no timing asserts), written as messages.md/json."""
    from dualarm_control.ros.message_bench import (
        format_message_bench,
        run_message_bench,
        write_message_bench,
    )

    rows = run_message_bench(number=20, repeat=1)
    assert [r["message"].split()[0] for r in rows] == ["/joint_states", "/relative_target", "/diagnostics",
                                                       "/velocity_controller/commands", "/joint_states"]
    assert all(r["rclpy_us"] > 0 and r["cdr_us"] > 0 and r["ratio"] == r["cdr_us"] / r["rclpy_us"] for r in rows)
    write_message_bench(tmp_path, rows)
    assert json.loads((tmp_path / "messages.json").read_text()) == rows
    assert format_message_bench(rows) in (tmp_path / "messages.md").read_text()


def test_realtime_and_messages_are_separate(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "--realtime", "--messages", "--output", str(tmp_path)]) == 2
    assert "choose one" in capsys.readouterr().err


def test_with_view_belongs_to_realtime(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "--with-view", "--output", str(tmp_path)]) == 2
    assert "--with-view belongs to --realtime" in capsys.readouterr().err


def test_realtime_table_has_a_view_column_only_with_view() -> None:
    """`dualarm bench --realtime --with-view` rows carry "view"; the table then says which run had it."""
    from dualarm_control.app.bench.realtime import format_realtime

    row = {"solver": "sparse_qp", "rate_hz": 500.0, "exit": 0, "cycles": 100, "missed_deadlines": 2,
           "missed_share": 0.02, "jitter_p50_ms": 0.1, "jitter_p99_ms": 1.0, "latency_p50_ms": 0.5,
           "latency_p99_ms": 2.0, "solver_failures": 0}
    plain = format_realtime([row])
    assert "view" not in plain and "| sparse_qp | 500 | 100 | 2 (2.00%) |" in plain
    table = format_realtime([{**row, "view": "none"}, {**row, "view": "rerun", "missed_deadlines": 5}])
    assert "| view |" in table.splitlines()[0]
    assert "| sparse_qp | 500 | none | 100 | 2 (2.00%) |" in table
    assert "| sparse_qp | 500 | rerun | 100 | 5 (2.00%) |" in table
