"""Benchmark of the solvers on a scenario: solve and cycle time percentiles, as ratios.

Machines are shared and noisy, so the table reports percentiles (p50/p99) and the ratio
of each solver's p50 to the reference solver's p50 measured in the same run, never a
single absolute figure on its own.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from dualarm_control.app.experiment import run_scenario
from dualarm_control.controller import controller_params
from dualarm_control.kinematics import DualArmModel
from dualarm_control.metrics import percentiles
from dualarm_control.scenario import Scenario


def bench_solvers(
    scenario: Scenario,
    solvers: Sequence[str],
    reference: str,
    progress: Callable[[str], Callable[[float, str], None]] | None = None,
) -> dict[str, dict[str, Any]]:
    """Run ``scenario`` per solver; return per-solver timing percentiles and ratios to ``reference``."""
    model = DualArmModel()
    rows: dict[str, dict[str, Any]] = {}
    for name in solvers:
        log = run_scenario(scenario, controller_params({"solver": name}), model,
                           progress=None if progress is None else progress(name))
        solve50, solve99 = percentiles(log.solve_time)
        cycle50, cycle99 = percentiles(log.cycle_time)
        rows[name] = {
            "cycles": len(log.time),
            "solve_time_p50_ms": solve50 * 1e3,
            "solve_time_p99_ms": solve99 * 1e3,
            "cycle_time_p50_ms": cycle50 * 1e3,
            "cycle_time_p99_ms": cycle99 * 1e3,
            "cycle_time_max_ms": float(np.max(log.cycle_time)) * 1e3,
            "share_of_period_p99": cycle99 / log.period,
        }
    ref = rows.get(reference) or next(iter(rows.values()))
    for row in rows.values():
        row["solve_p50_ratio"] = row["solve_time_p50_ms"] / ref["solve_time_p50_ms"]
    return rows


def format_bench(rows: dict[str, dict[str, Any]], reference: str) -> str:
    """Markdown table of :func:`bench_solvers` output."""
    head = (f"| solver | cycles | solve p50 [ms] | solve p99 [ms] | cycle p50 [ms] | cycle p99 [ms] | "
            f"cycle p99 / period | solve p50 / {reference} |")
    lines = [head, "|" + "---|" * 8]
    for name, r in rows.items():
        lines.append(
            f"| {name} | {r['cycles']} | {r['solve_time_p50_ms']:.3f} | {r['solve_time_p99_ms']:.3f} | "
            f"{r['cycle_time_p50_ms']:.3f} | {r['cycle_time_p99_ms']:.3f} | {r['share_of_period_p99']:.2f} | "
            f"{r['solve_p50_ratio']:.2f} |"
        )
    return "\n".join(lines)


def write_bench(out: Path, rows: dict[str, dict[str, Any]], reference: str, scenario: str) -> None:
    out.mkdir(parents=True, exist_ok=True)
    (out / "bench.json").write_text(json.dumps(rows, indent=2) + "\n")
    (out / "bench.md").write_text(f"# Solver benchmark ({scenario})\n\n{format_bench(rows, reference)}\n")
