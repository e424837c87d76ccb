"""Every row of the fault matrix on real processes (``dualarm faults``, docs/safety.md), one test per row.

The six process faults share one loopback run of ``assembly`` in sequence, as ``dualarm faults``
runs them (a module fixture, started by the first row that needs it). The rows that run a
scenario to completion (10 % loss of best-effort streams; across hosts with the 1 s link cut;
netem on the link) run ``test/data/fault_move.yaml``, one 3.7 s move, instead of the 26 s
assembly. ``faults.py`` judges each row from the run's bag and logs. Where every criterion of a
row is functional the test asserts its verdict and figures; for the watchdog episodes it asserts
the functional part (tripped past the timeout, only zero commands while safe, recovered, one log
line each way) and prints how fast, which ``dualarm faults`` judges: wall-clock bounds do not
belong in a test. A row that cannot run on this machine (no root, no ``ip``, no netem in the
kernel) is a pytest *skip* with the row's reason, never a pass.
"""

from __future__ import annotations

import json
import math
import re
import subprocess
import sys
from pathlib import Path

import pytest

from dualarm_control.app.faults import matrix as faults
from dualarm_control.app.faults import rows as row_names
from dualarm_control.app.faults.episodes import SafeEpisode
from dualarm_control.app.faults.run_all import run_matrix

# real time against 15-100 ms watchdogs: run after the parallel tests, alone (a full parallel run made a
# row miss its "complete" and another trip 2 s late)
pytestmark = pytest.mark.realtime

FAULT_MOVE = str(Path(__file__).parent / "data" / "fault_move.yaml")
Runs = dict[str, tuple[Path, dict[str, faults.Row], list[str]]]


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> Runs:
    """Matrix runs by group, each made once by the first test that needs it."""
    return {}


def run_rows(runs: Runs, tmp_path_factory: pytest.TempPathFactory, group: str, scenario: str,
             names: tuple[str, ...]) -> tuple[Path, dict[str, faults.Row], list[str]]:
    if group not in runs:
        out = tmp_path_factory.mktemp(group)
        lines: list[str] = []
        rows = run_matrix(out, scenario, names, lines.append)
        faults.write_results(out, rows, 0.0)
        runs[group] = (out, {r.name: r for r in rows}, lines)
    return runs[group]


def judged(runs: Runs, tmp_path_factory: pytest.TempPathFactory, name: str) -> faults.Row:
    """Row ``name`` of its group's run, printed; skipped (with the reason) where it cannot run."""
    if name in row_names.LOOPBACK_ROWS:
        _, rows, lines = run_rows(runs, tmp_path_factory, "loopback", "assembly", row_names.LOOPBACK_ROWS)
    elif name in ("across_hosts", "link_cut"):
        _, rows, lines = run_rows(runs, tmp_path_factory, "link", FAULT_MOVE, ("across_hosts", "link_cut"))
    else:
        _, rows, lines = run_rows(runs, tmp_path_factory, name, FAULT_MOVE, (name,))
    row = rows[name]
    print(f"[{row.status}] {name}: {row.observed}")
    if row.status == "skipped":
        pytest.skip(f"{name}: {row.observed}")
    assert not row.observed.startswith("run failed"), f"{name}: {row.observed}\n" + "\n".join(lines)
    return row


def passed(runs: Runs, tmp_path_factory: pytest.TempPathFactory, name: str) -> faults.Row:
    """Row ``name``, which must pass: for these rows every criterion is functional (no wall-clock bound)."""
    row = judged(runs, tmp_path_factory, name)
    assert row.status == "pass", f"{name}: {row.observed}"
    return row


def assert_safe_episode(row: faults.Row, timeout_ms: float) -> None:
    """A watchdog episode: tripped by an input older than its timeout (never before it), only zero
    commands while safe, OK again once the input returned, one log line each way. How fast (trip
    within 2 periods of the timeout, OK again < 1 s) is wall-clock timing: ``dualarm faults``
    judges it and docs/safety.md reports it; here it is printed, not asserted."""
    f = row.figures
    # the age is read from the log line, printed to 0.1 ms: an age of 50.04 ms reads 50.0 ("none for
    # 50.0 ms" failed '> 50.0' on CI), so "older than the timeout" is checked at that resolution
    assert math.isfinite(f["detected_ms"]) and f["input_age_ms"] >= timeout_ms, row.observed
    assert f["zero_commands"] > 0 and f["other_commands"] == 0, row.observed
    assert math.isfinite(f["recovered_ms"]), row.observed
    logs = re.search(r"log: (\d+) 'safe state', (\d+) 'recovered'", row.observed)
    assert logs is not None and logs[1] == logs[2] == "1", row.observed


@pytest.mark.parametrize(("name", "timeout"), [("stale_states", faults.STALE_TIMEOUT),
                                               ("target_stopped", faults.TARGET_TIMEOUT),
                                               ("kill_sim", faults.STALE_TIMEOUT)])
def test_watchdog_rows(runs: Runs, tmp_path_factory: pytest.TempPathFactory, name: str, timeout: float) -> None:
    """sim_node paused, trajectory_node paused, sim_node killed and restarted: safe state, then recovery."""
    assert_safe_episode(judged(runs, tmp_path_factory, name), timeout * 1e3)


def test_kill_controller_row(runs: Runs, tmp_path_factory: pytest.TempPathFactory) -> None:
    """The controller killed mid-motion: the simulator's command timeout brings the arms to rest
    within command_timeout + 3 simulator steps (counted in steps, not wall-clock time)."""
    stop = passed(runs, tmp_path_factory, "kill_controller").figures
    assert stop["speed_at_kill"] > 0.01 and 0 <= stop["steps"] <= row_names.COMMAND_TIMEOUT_STEPS + 3


@pytest.mark.parametrize("name", list(row_names.PROFILE_KILLS))
def test_kill_controller_on_each_shipped_profile(runs: Runs, tmp_path_factory: pytest.TempPathFactory,
                                                 name: str) -> None:
    """Issue 40 item 5: the controller killed mid-motion on ros2_control_velocity.yaml (a trajectory controller
    with a 0.05 s cmd_timeout) and on lbr_dual_position.yaml (the last position holds): the arms at rest within
    the row's steps of the last command (counted in simulator steps), read from a bag of the profile's topics."""
    row = passed(runs, tmp_path_factory, name)
    stop = row.figures
    assert stop["speed_at_kill"] > 0.01 and 0 <= stop["steps"] <= row_names.PROFILE_KILLS[name][1], row.observed


def test_the_kill_row_fails_on_a_group_velocity_controller(tmp_path: Path) -> None:
    """The row can fail: on test/data/group_velocity.yaml (a JointGroupVelocityController, which keeps the last
    velocity: the simulator with no command timeout) the arms never come to rest after the kill."""
    from dualarm_control.app.faults.profile_kills import kill_row

    name = "kill_controller_velocity_profile"
    group = Path(__file__).parent / "data" / "group_velocity.yaml"
    row = kill_row(tmp_path, FAULT_MOVE, name, group, row_names.PROFILE_KILLS[name][1], print)
    print(f"[{row.status}] {row.observed}")
    assert not row.observed.startswith("run failed"), row.observed
    assert row.status == "FAIL" and row.figures["speed_at_kill"] > 0.01 and row.figures["steps"] == -1, row.observed


@pytest.mark.parametrize("name", ["recorder_sigint", "recorder_sigterm"])
def test_recorder_signal_rows(runs: Runs, tmp_path_factory: pytest.TempPathFactory, name: str) -> None:
    """A recorder stopped by a signal keeps every /joint_states received up to it."""
    figures = passed(runs, tmp_path_factory, name).figures
    assert figures["missing"] == 0 and figures["expected"] >= 50 and figures["messages"] > figures["expected"]


def test_loopback_results_are_written(runs: Runs, tmp_path_factory: pytest.TempPathFactory) -> None:
    out, rows, _ = run_rows(runs, tmp_path_factory, "loopback", "assembly", row_names.LOOPBACK_ROWS)
    doc = json.loads((out / "faults.json").read_text())
    assert [r["name"] for r in doc["rows"]] == list(row_names.LOOPBACK_ROWS)
    assert doc["passed"] == all(r.status != "FAIL" for r in rows.values())
    assert "| stale states |" in (out / "faults.md").read_text()
    assert (out / "loopback" / "controller_node.log").read_text().count("safe state:") >= 3


def test_best_effort_loss_row(runs: Runs, tmp_path_factory: pytest.TempPathFactory) -> None:
    """10 % of the best-effort messages lost (netem, or the lossy relay where the kernel has no netem):
    the scenario completes within 1 mm / 10 mrad."""
    row = passed(runs, tmp_path_factory, "best_effort_loss")
    assert row.figures["cycles"] > 0 and row.figures["position_error_m"] < faults.FINAL_POSITION_M
    if "; loss by relay: " in row.observed:  # the relay says what it dropped, per stream (seeded, about 10 %)
        dropped = [float(v) for v in re.findall(r"dropped \(([0-9.]+)%\)", row.observed)]
        assert len(dropped) == len(faults.RELAY_ROUTES) and all(v > 0.0 for v in dropped), row.observed
    else:
        assert "; loss by netem loss 10% on lo" in row.observed


def test_across_hosts_row(runs: Runs, tmp_path_factory: pytest.TempPathFactory) -> None:
    """Two namespaces joined by a veth pair: completes; traffic on the link, none on the simulator's lo."""
    f = passed(runs, tmp_path_factory, "across_hosts").figures
    assert f["link_packets"] > 0 and f["lo_packets"] == 0 and f["position_error_m"] < faults.FINAL_POSITION_M


def test_link_cut_row(runs: Runs, tmp_path_factory: pytest.TempPathFactory) -> None:
    """The link down for 1 s mid-motion: safe state (stale joint states), OK again once it is up."""
    assert_safe_episode(judged(runs, tmp_path_factory, "link_cut"), faults.STALE_TIMEOUT * 1e3)


def test_link_netem_row(runs: Runs, tmp_path_factory: pytest.TempPathFactory) -> None:
    """netem delay and loss on the link, best effort: completes (skipped where the kernel has no netem)."""
    f = passed(runs, tmp_path_factory, "link_netem").figures
    assert f["link_packets"] > 0 and f["position_error_m"] < faults.FINAL_POSITION_M


def test_a_row_that_cannot_run_is_skipped_with_the_reason(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(faults, "netem_unavailable", lambda: "no netem here (test)")
    rows = faults.loss_rows(tmp_path, "assembly", ["best_effort_loss"], lambda _: None, relay_loss=0.0)
    assert [(r.status, r.observed) for r in rows] == [("skipped", "skipped: no netem here (test)")]


def test_unknown_row_is_a_usage_error() -> None:
    out = subprocess.run([sys.executable, "-m", "dualarm_control.app.cli", "faults", "--only", "nope"],
                         capture_output=True, text=True, timeout=60, check=False)
    assert out.returncode == 2 and "stale_states" in out.stderr


@pytest.mark.slow
def test_goal_into_collision_stalls_with_the_pair_and_no_contact(runs: Runs, tmp_path_factory: pytest.TempPathFactory) -> None:
    """Issue 27's row (47 s; over ROS the same stall is judged in lockstep in test_collision_demo.py's
    default run, in real time in test_interactive_node.py's slow test)."""
    row = passed(runs, tmp_path_factory, "goal_into_collision")
    assert row.figures["contacts"] == 0 and row.figures["distance_m"] >= 0.029, row.observed


@pytest.mark.parametrize(("recovered_ms", "status"), [(15.0, "pass"), (1040.0, "pass"), (float("nan"), "FAIL")])
def test_link_cut_verdict_is_that_it_recovers(monkeypatch: pytest.MonkeyPatch, recovered_ms: float,
                                              status: str) -> None:
    """The link_cut row's verdict is that the cell recovers once the link is up (OK again 1040 ms after it,
    once, under load, failed a 1000 ms bound): the time is the row's figure; never recovering fails."""
    seen = SafeEpisode("joint_states stale by 16.0 ms", 20.0, 16.0, 195, 0, recovered_ms, 1)  # as from a bag
    monkeypatch.setattr(faults, "safe_episode", lambda *_args: seen)
    row = faults.link_cut_row(None, faults._Episode(0, 10**9, (1, 1)))  # type: ignore[arg-type]
    assert row.status == status, row.observed
    assert row.figures["recovered_ms"] == pytest.approx(recovered_ms, nan_ok=True)
