"""``dualarm soak`` works: a 20 s soak of the short scenario (the 10-minute soak is a benchmark, docs/safety.md)."""

from __future__ import annotations

from pathlib import Path

from dualarm_control.app.faults.soak import format_soak, run_soak, write_soak

SHORT = Path(__file__).parent / "data" / "short.yaml"


def test_short_soak_accounts_for_every_command(tmp_path: Path) -> None:
    doc = run_soak(20.0 / 60.0, str(SHORT), lambda _: None)
    write_soak(tmp_path, doc)
    assert doc["repetitions"] >= 3
    assert doc["accounted"], format_soak(doc)
    assert doc["controller"]["cycles"] > 2000
    assert set(doc["rss"]) == {"sim_node", "controller_node", "trajectory_node"}
    assert all(r["baseline_mib"] > 10 for r in doc["rss"].values())
    assert len(doc["samples"]) >= 15
    assert "| controller_node |" in (tmp_path / "soak.md").read_text()
