"""``dualarm soak`` for 40 s on the short scenario: the pass criteria of the 10-minute soak
(docs/safety.md), asserted on a short run.

What 40 s can show: RSS growth after the warm-up <= 5 % catches a leak of more than about
12 MiB a minute (the 10-minute soak: about 0.9 MiB a minute); no one-second window after the
warm-up with 5 or more missed deadlines; every command published after the start-up received.
"""

from __future__ import annotations

from pathlib import Path

from dualarm_control.app.faults.soak import NODES, format_soak, run_soak, write_soak

SHORT = Path(__file__).parent / "data" / "short.yaml"
SECONDS = 40.0


def test_short_soak_passes(tmp_path: Path) -> None:
    doc = run_soak(SECONDS / 60.0, str(SHORT), lambda _: None)
    write_soak(tmp_path, doc)
    text = format_soak(doc)
    print(text)
    assert doc["rss_growth_ok"], text
    assert doc["bursts_ok"], text
    assert doc["accounted"], text
    assert doc["passed"], text
    assert set(doc["rss"]) == set(NODES)
    assert all(10 < r["baseline_mib"] <= r["max_after_mib"] for r in doc["rss"].values())
    assert doc["repetitions"] >= 3  # the warm-up is the first repetition: the criteria cover the ones after it
    assert doc["controller"]["cycles"] > 0 and doc["controller"]["failures"] == 0
    assert len(doc["samples"]) >= SECONDS / 2
    assert "| controller_node |" in (tmp_path / "soak.md").read_text()
