"""``dualarm soak`` on the short scenario: the pass criteria of the 10-minute soak (docs/safety.md),
asserted on short runs.

The default run soaks 15 s: every command published after the start-up received, the counters
adding up, the closing summaries read, RSS sampled for each node and its growth after the warm-up
within 5 % (5 % of ~170 MiB in the ~10 s after the warm-up: a leak of more than about 50 MiB a
minute). The ``slow`` tests soak 40 s: the same criteria, where RSS growth <= 5 % catches a
leak of more than about 12 MiB a minute (the 10-minute soak: about 0.9 MiB a minute), and whether
a second after the warm-up holds a burst of missed deadlines (5 or more), which is the machine's
load as much as the code's: the default tests print it, ``dualarm soak``'s report judges it, and
the ``slow`` test asserts it.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from dualarm_control.app.faults.soak import (
    BURST,
    IN_FLIGHT,
    NODES,
    format_soak,
    run_soak,
    summarize,
    write_soak,
)

SHORT = Path(__file__).parent / "data" / "short.yaml"
SECONDS = 40.0
"""The ``slow`` soak [s]."""
QUICK_SECONDS = 15.0
"""The default run's soak [s]: start-up (3-8 s on a busy 2-core machine) and at least 3 repetitions
of the 1.55 s scenario."""
Soak = tuple[dict[str, Any], str, Path]


def soak_for(seconds: float, tmp_path_factory: pytest.TempPathFactory) -> Soak:
    """One soak of ``seconds``: its document, report text and output directory."""
    out = tmp_path_factory.mktemp("soak")
    doc = run_soak(seconds / 60.0, str(SHORT), lambda _: None)
    write_soak(out, doc)
    text = format_soak(doc)
    print(text)
    return doc, text, out


@pytest.fixture(scope="module")
def quick_soak(tmp_path_factory: pytest.TempPathFactory) -> Soak:
    """One 15 s soak for the module (the default run's)."""
    return soak_for(QUICK_SECONDS, tmp_path_factory)


@pytest.fixture(scope="module")
def soak(tmp_path_factory: pytest.TempPathFactory) -> Soak:
    """One 40 s soak for the module (the ``slow`` tests')."""
    return soak_for(SECONDS, tmp_path_factory)


@pytest.mark.realtime  # 200 Hz over ROS in real time: under stress-ng --cpu 1 beside the parallel tests it missed
# 63 deadlines in bursts and lost 35 commands to watchdog trips; alone it is the soak's verdict
def test_quick_soak_keeps_memory_and_every_command(quick_soak: Soak) -> None:
    """15 s: the criteria of the 40 s soak below (RSS growth within 5 %, no command lost after the
    start-up, the counters add up, no solver failure); the deadline figures are printed, not judged."""
    assert_keeps_memory_and_every_command(quick_soak, QUICK_SECONDS)


@pytest.mark.slow
def test_short_soak_keeps_memory_and_every_command(soak: Soak) -> None:
    """40 s (``slow``; the 15 s soak above is the default run's): RSS growth within 5 %, no command
    lost after the start-up, the counters add up, no solver failure; the deadline figures are in the
    report (printed), not judged here."""
    assert_keeps_memory_and_every_command(soak, SECONDS)


def assert_keeps_memory_and_every_command(soak: Soak, seconds: float) -> None:
    doc, text, out = soak
    assert doc["rss_growth_ok"], text
    assert set(doc["rss"]) == set(NODES)
    assert all(10 < r["baseline_mib"] <= r["max_after_mib"] for r in doc["rss"].values()), doc["rss"]
    c, s = doc["controller"], doc["sim"]
    assert c and s, text  # both closing summaries were read
    assert doc["commands_published"] == c["cycles"] + c["safe"]
    assert doc["commands_expected"] == doc["commands_published"] - c["unmatched"]
    assert doc["final_shortfall"] == doc["commands_expected"] - s["received"] >= 0, text  # none received twice
    assert doc["lost_after_startup"] is not None and abs(doc["lost_after_startup"]) <= IN_FLIGHT, text
    assert doc["accounted"] and doc["load_independent_ok"], text
    assert doc["repetitions"] >= 3, text  # the warm-up is the first repetition: the criteria cover the ones after it
    assert c["cycles"] > 0 and c["failures"] == 0, text
    assert len(doc["samples"]) >= seconds / 2
    report = (out / "soak.md").read_text()
    assert "| controller_node |" in report and report == text + "\n"


@pytest.mark.slow
def test_short_soak_has_no_deadline_burst(soak: Soak) -> None:
    """No one-second window after the warm-up with 5 or more missed deadlines, so the soak's verdict is
    PASS: a wall-clock criterion (what a loaded machine misses is its business), hence ``slow``."""
    doc, text, _ = soak
    assert doc["bursts_ok"], text
    assert doc["passed"], text


def sample(t: float, missed: int, shortfall: int, repetitions: int = 1, rss: int = 100 * 2**20) -> dict[str, Any]:
    return {"t_s": t, "repetitions": repetitions, "missed_deadlines": missed, "shortfall": shortfall,
            "rss": dict.fromkeys(NODES, rss)}


FLAGS = ("rss_growth_ok", "accounted", "load_independent_ok", "bursts_ok", "passed")
CONTROLLER = {"cycles": 1000, "safe": 10, "unmatched": 4, "missed": 12, "failures": 0}


def test_soak_verdict_keeps_the_load_independent_criteria_apart() -> None:
    """``summarize`` on fixed samples: a burst of missed deadlines fails the burst criterion and the
    soak's verdict but not ``load_independent_ok``; a command lost after the warm-up fails ``accounted``."""
    samples = [sample(0.0, 0, 7, repetitions=0), sample(1.0, 2, 7), sample(2.0, 2 + BURST, 7),
               sample(3.0, 3 + BURST, 7)]
    lost = summarize(samples, CONTROLLER, {"received": 1000 - 8}, 3.0, "short")
    assert (lost["commands_published"], lost["commands_expected"], lost["final_shortfall"]) == (1010, 1006, 14)
    assert lost["lost_after_startup"] == 7 and not lost["accounted"] and not lost["load_independent_ok"]
    kept = summarize(samples, CONTROLLER, {"received": 1006 - 7}, 3.0, "short")
    assert kept["lost_after_startup"] == 0 and kept["bursts"] == 1
    assert {k: kept[k] for k in FLAGS} == {"rss_growth_ok": True, "accounted": True, "load_independent_ok": True,
                                           "bursts_ok": False, "passed": False}
    verdict = "1 repetitions; FAIL (RSS growth and accounting: pass; deadline bursts: FAIL)"
    assert format_soak(kept).splitlines()[2] == verdict
    quiet = summarize([{**s, "missed_deadlines": 2} for s in samples], CONTROLLER, {"received": 999}, 3.0, "short")
    assert all(quiet[k] for k in FLAGS) and quiet["bursts"] == 0
