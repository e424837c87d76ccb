"""The fault matrix's short subset on real processes (``dualarm faults --only ...``, loopback).

stale joint states (sim paused), kill -9 of the controller (the simulator's command timeout stops
the arms, measured from /joint_states), SIGTERM to a bag recorder (whole bag). The full matrix
is ``dualarm faults`` (docs/safety.md).
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from dualarm_control.app.faults import matrix as faults


def test_quick_fault_rows_pass(tmp_path: Path) -> None:
    lines: list[str] = []
    rows = faults.run_matrix(tmp_path, "assembly", faults.QUICK, lines.append)
    faults.write_results(tmp_path, rows, 0.0)
    by_name = {r.name: r for r in rows}
    assert set(by_name) == set(faults.QUICK)
    for row in rows:
        assert row.status == "pass", f"{row.name}: {row.observed}\n" + "\n".join(lines)
    stale = by_name["stale_states"].figures
    assert stale["input_age_ms"] <= 25.0 and stale["other_commands"] == 0 and stale["zero_commands"] > 0
    stop = by_name["kill_controller"].figures
    assert stop["speed_at_kill"] > 0.01 and 0 <= stop["steps"] <= 13
    assert by_name["recorder_sigterm"].figures["missing"] == 0
    doc = json.loads((tmp_path / "faults.json").read_text())
    assert doc["passed"] and len(doc["rows"]) == 3
    assert "| stale states |" in (tmp_path / "faults.md").read_text()
    assert (tmp_path / "loopback" / "controller_node.log").read_text().count("safe state:") >= 1


def test_a_row_that_cannot_run_is_skipped_with_the_reason(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(faults, "netem_unavailable", lambda: "no netem here (test)")
    rows = faults.loss_rows(tmp_path, "assembly", ["best_effort_loss"], lambda _: None, relay_loss=0.0)
    assert [(r.status, r.observed) for r in rows] == [("skipped", "skipped: no netem here (test)")]


def test_unknown_row_is_a_usage_error() -> None:
    out = subprocess.run([sys.executable, "-m", "dualarm_control.app.cli", "faults", "--only", "nope"],
                         capture_output=True, text=True, timeout=60, check=False)
    assert out.returncode == 2 and "stale_states" in out.stderr
