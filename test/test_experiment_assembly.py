"""The assembly experiment of paper 000 end to end through the `dualarm experiment` command.

Checks the acceptance figures of the core issue on the real pybullet cell: tracking,
limits, solver failures and Table I sparsity ratios (ours vs the paper's 0.357 and 0.471).
"""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from dualarm_control.app.cli import main
from dualarm_control.app.record.allowances import ALLOWANCE_KEYS
from dualarm_control.app.record.report import (
    JOINT_LIMIT_KEYS,
    METRIC_KEYS,
    SEGMENT_KEYS,
    TRACKING_KEYS,
)

# no ROS node, no wall-clock verdict: make test runs it at idle CPU priority beside the parallel tests (docs/testing.md)
pytestmark = pytest.mark.background

SOLVERS = ("standard_qp", "sparse_qp", "hierarchical_sparse_qp")
FINAL_ERRORS = {"standard_qp": (6.4e-12, 3.7e-9), "sparse_qp": (1.6e-7, 1.3e-7), "hierarchical_sparse_qp": (1.6e-7, 1.3e-7)}
"""docs/experiment.md: final position [m] / orientation [rad] error per solver since the cell holds its integrated
command; measured 2026-12 (deterministic): 6.36e-12 / 3.72e-9, 1.65e-7 / 1.33e-7, 1.64e-7 / 1.32e-7. Asserted within
FINAL_ERROR_FACTOR x these."""
FINAL_ERROR_FACTOR = 10.0
PAPER_RATIOS = (0.357, 0.471)
"""Paper 000, Table I: l0(sparse) / l0(standard), l0(hierarchical) / l0(standard)."""
RATIOS = {"l0_sparse": 0.319, "l0_hierarchical": 0.431, "l1_sparse": 0.661, "l2_sparse": 1.22}
"""docs/experiment.md, "ours": Table I ratios to the standard QP; asserted within RATIO_BAR."""
RATIO_BAR = 0.02
"""Allowed change of a documented ratio (absolute): the figures are deterministic (lockstep, seeded)
to far better than this; the bar leaves room for changes of the simulated cell (docs say what moved)."""


ACCELERATION_LIMIT_PARAMS = Path(__file__).resolve().parents[1] / "config" / "acceleration_limit.yaml"


@pytest.fixture(scope="module")
def bounded_process(request: pytest.FixtureRequest,
                    tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[subprocess.Popen[bytes], Path] | None]:
    """``dualarm experiment assembly`` with the joint acceleration bound of config/acceleration_limit.yaml,
    in a process of its own, started (when a selected test needs it) before this process runs the
    unbounded experiment: the two use both cores. Its process and output directory."""
    if not any("bounded" in item.fixturenames for item in request.session.items if item.module is request.module):
        yield None
        return
    out = tmp_path_factory.mktemp("bounded")
    with (out / "stderr.txt").open("wb") as err:
        proc = subprocess.Popen([sys.executable, "-m", "dualarm_control.app.cli", "experiment", "assembly", "--solver",
                                 ",".join(SOLVERS), "--params", str(ACCELERATION_LIMIT_PARAMS), "--output", str(out)],
                                stdout=subprocess.DEVNULL, stderr=err)
    try:
        yield proc, out
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.wait()


@pytest.fixture(scope="module")
def metrics(bounded_process: tuple[subprocess.Popen[bytes], Path] | None,
            tmp_path_factory: pytest.TempPathFactory) -> dict[str, dict[str, float]]:
    """The unbounded runs, in this process (the bounded ones run meanwhile: ``bounded_process``)."""
    out = tmp_path_factory.mktemp("experiment")
    assert main(["experiment", "assembly", "--solver", ",".join(SOLVERS), "--output", str(out)]) == 0
    assert (out / "velocity_norms.png").stat().st_size > 10_000
    return json.loads((out / "metrics.json").read_text())


def test_metrics_file_has_every_key(metrics: dict[str, dict[str, float]]) -> None:
    """metrics.json lists each solver with exactly the documented keys (the assembly allows its tools' contacts:
    the allowance keys too)."""
    assert list(metrics) == list(SOLVERS)
    for record in metrics.values():
        assert tuple(record) == METRIC_KEYS + JOINT_LIMIT_KEYS + TRACKING_KEYS + SEGMENT_KEYS + ALLOWANCE_KEYS


@pytest.mark.parametrize("solver", SOLVERS)
def test_every_segment_is_reached(metrics: dict[str, dict[str, float]], solver: str) -> None:
    """Issue 40: each segment's verdict; on the LWR4 cell every one is reached (within 0.5 mm / 5 mrad of its
    end pose at its end)."""
    m = metrics[solver]
    assert (m["segments_reached"], m["segments_stalled"]) == (3, 0), m["segment_outcomes"]
    assert [part.split(" (t = ")[0] for part in str(m["segment_outcomes"]).split(" | ")] == [
        "segment 1 'approach'", "segment 2 'insert'", "segment 3 'screw'"]


@pytest.mark.parametrize("solver", SOLVERS)
def test_task_is_tracked_within_limits(metrics: dict[str, dict[str, float]], solver: str) -> None:
    """Final relative error within 10 x the documented figures (FINAL_ERRORS, 6e-12 to 1.6e-7 m, 4e-9 to 1.3e-7
    rad; the core issue's done-when bound was 1 mm and 0.01 rad); no limit violation; no solver failure."""
    m = metrics[solver]
    position, orientation = FINAL_ERRORS[solver]
    assert m["final_position_error_m"] < FINAL_ERROR_FACTOR * position, m["final_position_error_m"]
    assert m["final_orientation_error_rad"] < FINAL_ERROR_FACTOR * orientation, m["final_orientation_error_rad"]
    assert m["joint_position_limit_violations"] == 0
    assert m["joint_velocity_limit_violations"] == 0
    assert m["solver_failures"] == 0


def test_sparsity_at_least_as_strong_as_the_paper(metrics: dict[str, dict[str, float]]) -> None:
    """Table I ratios at most the paper's (0.357, 0.471) and equal to the documented ones (RATIOS: 0.319,
    0.431, l1 0.661, l2 1.22) within RATIO_BAR (0.02)."""
    std, sparse, hier = (metrics[s] for s in SOLVERS)
    ratios = {"l0_sparse": sparse["l0_mean"] / std["l0_mean"], "l0_hierarchical": hier["l0_mean"] / std["l0_mean"],
              "l1_sparse": sparse["l1_mean"] / std["l1_mean"], "l2_sparse": sparse["l2_mean"] / std["l2_mean"]}
    assert ratios["l0_sparse"] <= PAPER_RATIOS[0] and ratios["l0_hierarchical"] <= PAPER_RATIOS[1]
    assert ratios["l1_sparse"] < 1.0
    for key, documented in RATIOS.items():
        assert ratios[key] == pytest.approx(documented, abs=RATIO_BAR), (key, ratios)
    for m in (std, sparse, hier):
        assert m["l0_integral"] == pytest.approx(m["l0_mean"] * m["duration_s"])


ACCELERATION_LIMIT = 10.0  # rad/s^2, config/acceleration_limit.yaml


@pytest.fixture(scope="module")
def bounded(bounded_process: tuple[subprocess.Popen[bytes], Path] | None) -> dict[str, dict[str, float]]:
    """The same runs with the joint acceleration bound of config/acceleration_limit.yaml."""
    assert bounded_process is not None
    proc, out = bounded_process
    assert proc.wait(timeout=1800) == 0, (out / "stderr.txt").read_text()[-3000:]
    return json.loads((out / "metrics.json").read_text())


@pytest.mark.parametrize("solver", SOLVERS)
def test_acceleration_bound_holds_with_tracking_and_limits_kept(
    bounded: dict[str, dict[str, float]], metrics: dict[str, dict[str, float]], solver: str
) -> None:
    """With the bound: max |dqd|/T <= 10 rad/s^2, final errors within 10 % of the unbounded run's, no violation."""
    m, free = bounded[solver], metrics[solver]
    assert m["max_joint_acceleration"] <= ACCELERATION_LIMIT + 1e-6
    assert m["final_position_error_m"] <= 1.1 * free["final_position_error_m"]
    assert m["final_orientation_error_rad"] <= 1.1 * free["final_orientation_error_rad"]
    assert m["joint_position_limit_violations"] == m["joint_velocity_limit_violations"] == m["solver_failures"] == 0


def test_acceleration_bound_keeps_the_sparsity(bounded: dict[str, dict[str, float]]) -> None:
    """Table I with the bound: l0 ratios 0.319 / 0.389 (docs/experiment.md) within RATIO_BAR, and at most
    the paper's."""
    std, sparse, hier = (bounded[s] for s in SOLVERS)
    assert sparse["l0_mean"] / std["l0_mean"] == pytest.approx(0.319, abs=RATIO_BAR)
    assert hier["l0_mean"] / std["l0_mean"] == pytest.approx(0.389, abs=RATIO_BAR)
    assert sparse["l0_mean"] / std["l0_mean"] <= PAPER_RATIOS[0]
    assert hier["l0_mean"] / std["l0_mean"] <= PAPER_RATIOS[1]


def test_sparse_commands_do_not_chatter(metrics: dict[str, dict[str, float]]) -> None:
    """Without the bound, the proximal tie-break keeps the sparse commands smooth.

    Before issue 8 (proxsuite, no tie-break): 2.6 (sparse) and 2.7 (hierarchical) active-set
    switches per s and 34 rad/s^2; the exact lasso alone (daqp): 34.6 and 21.0 switches per s.
    Most switches left are joints starting and stopping through the 1e-3 rad/s threshold.
    Documented (docs/experiment.md): 1.46 / 1.92 switches per s, 1.31 / 1.00 rad/s^2.
    """
    for solver, switches, acceleration in (("sparse_qp", 1.6, 1.31), ("hierarchical_sparse_qp", 2.1, 1.00)):
        assert metrics[solver]["active_set_switches_per_s"] <= switches
        assert metrics[solver]["max_joint_acceleration"] <= 2 * acceleration


def test_bad_solver_name_exits_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """An unknown solver exits with code 2 and names the valid choices."""
    assert main(["experiment", "assembly", "--solver", "nope", "--output", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "nope" in err and "sparse_qp" in err
