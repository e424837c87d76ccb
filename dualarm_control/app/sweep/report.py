"""``dualarm sweep report TABLE``: Table I as a distribution, per robot (and variant).

Per task, the ratio l0(solver)/l0(standard_qp) of the time-averaged active-joint counts (Table I's
l0, metrics.json's ``l0_mean``), paired by task: only tasks whose runs of both solvers have no error.
The median of each ratio with a percentile-bootstrap 95 % confidence interval (``resamples``
resamples of the tasks, seeded: the same table gives the same interval), the final position error,
the largest tracking error, the closest joint-limit margin and the time in eq (24)'s repulsive zone (issue 43) and
the cycle times per solver (medians), as a Markdown table; box plots of the ratios, and of the final and tracking
errors, limit margins, zone times and cycle times per solver, and the trade-off of l0 against the depth-weighted
zone time per robot (PNG).
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from dualarm_control.app.sweep.store import read_table
from dualarm_control.kinematics import FloatArray

REFERENCE = "standard_qp"
COMPARED = ("sparse_qp", "hierarchical_sparse_qp")
RESAMPLES = 2000


@dataclass(frozen=True)
class RatioSummary:
    """The paired ratio of one solver to the reference on one robot and variant."""

    robot: str
    variant: str
    solver: str
    tasks: int
    median: float
    low: float
    high: float
    ratios: FloatArray


def bootstrap_median(values: FloatArray, resamples: int = RESAMPLES, seed: int = 0) -> tuple[float, float, float]:
    """Median of ``values`` and its percentile-bootstrap 95 % interval (NaN for no values)."""
    if values.size == 0:
        return float("nan"), float("nan"), float("nan")
    rng = np.random.default_rng(seed)
    medians = np.median(values[rng.integers(0, values.size, (resamples, values.size))], axis=1)
    low, high = np.percentile(medians, [2.5, 97.5])
    return float(np.median(values)), float(low), float(high)


def grouped(rows: Sequence[dict[str, Any]]) -> dict[tuple[str, str], dict[str, dict[int, dict[str, Any]]]]:
    """(robot, variant) -> solver -> task -> row, runs with an error left out."""
    out: dict[tuple[str, str], dict[str, dict[int, dict[str, Any]]]] = defaultdict(lambda: defaultdict(dict))
    for row in rows:
        if row["error"] is None:
            out[(row["robot"], row["variant"])][row["solver"]][row["task"]] = row
    return out


def _paired(rows: Sequence[dict[str, Any]], reference: str, order: Callable[[Sequence[str]], Sequence[str]],
            value: Callable[[dict[str, Any], dict[str, Any]], float | None], seed: int) -> list[RatioSummary]:
    """Per robot and variant, ``value(run, reference run)`` of each solver ``order`` lists, paired by task
    (tasks whose value is None or NaN left out), its median and bootstrap 95 % CI."""
    out = []
    for (robot, variant), solvers in sorted(grouped(rows).items()):
        base = solvers.get(reference, {})
        for solver in order(list(solvers)):
            runs = solvers.get(solver, {})
            values = [value(runs[t], base[t]) for t in sorted(set(base) & set(runs))]
            kept = np.array([v for v in values if _finite(v)], dtype=float)
            out.append(RatioSummary(robot, variant, solver, len(kept), *bootstrap_median(kept, seed=seed), kept))
    return out


def paired_ratios(rows: Sequence[dict[str, Any]], seed: int = 0) -> list[RatioSummary]:
    """The l0 ratios of :data:`COMPARED` (then any other solver present) to :data:`REFERENCE`, paired by task,
    per robot and variant."""
    def order(present: Sequence[str]) -> list[str]:
        return [*COMPARED, *sorted(s for s in present if s != REFERENCE and s not in COMPARED)]

    def ratio(run: dict[str, Any], base: dict[str, Any]) -> float | None:
        return run["l0_mean"] / base["l0_mean"] if base["l0_mean"] > 0 else None

    return _paired(rows, REFERENCE, order, ratio, seed)


ZONE_REFERENCE = "hierarchical_sparse_qp"
"""The solver whose depth-weighted zone time the others are paired with (eq (27), issue 43)."""


def paired_zone_differences(rows: Sequence[dict[str, Any]], seed: int = 0) -> list[RatioSummary]:
    """Per robot and variant, each solver's depth-weighted time in the repulsive zone minus
    :data:`ZONE_REFERENCE`'s, paired by task [joint s]; none where the table predates the column or has no
    such reference."""
    def order(present: Sequence[str]) -> list[str]:
        return sorted(s for s in present if s != ZONE_REFERENCE)

    def difference(run: dict[str, Any], base: dict[str, Any]) -> float | None:
        a, b = run.get("repulsive_zone_depth_s"), base.get("repulsive_zone_depth_s")
        return a - b if a is not None and b is not None else None

    return [z for z in _paired(rows, ZONE_REFERENCE, order, difference, seed) if z.tasks]


def _finite(value: Any) -> bool:
    """A number that is not NaN (None: a column the table predates)."""
    return value is not None and bool(np.isfinite(value))


def _column(rows: dict[int, dict[str, Any]], column: str, scale: float = 1.0) -> list[float]:
    """The finite values of ``column`` (times ``scale``); none where a table predates the column."""
    values = [r.get(column) for r in rows.values()]
    return [scale * float(v) for v in values if v is not None and _finite(v)]


def _median(rows: dict[int, dict[str, Any]], column: str) -> float:
    values = _column(rows, column)
    return float(np.median(values)) if values else float("nan")


def markdown(rows: Sequence[dict[str, Any]], seed: int = 0) -> str:
    """The report's Markdown: the ratio table and the per-solver table."""
    lines = ["| robot | variant | ratio | tasks | median | 95 % CI |", "|---|---|---|---:|---:|---:|"]
    for s in paired_ratios(rows, seed):
        lines.append(f"| {s.robot} | {s.variant} | l0({s.solver}) / l0({REFERENCE}) | {s.tasks} | {s.median:.3f} | "
                     f"[{s.low:.3f}, {s.high:.3f}] |")
    zone = paired_zone_differences(rows, seed)
    if zone:
        lines += ["", ("| robot | variant | depth-weighted zone time minus the hierarchical QP's (eq 27) [joint s] | tasks | "
                  "median | 95 % CI |"), "|---|---|---|---:|---:|---:|"]
        lines += [f"| {z.robot} | {z.variant} | {z.solver} | {z.tasks} | {z.median:.3f} | [{z.low:.3f}, {z.high:.3f}] |"
                  for z in zone]
    header = ("| robot | variant | solver | runs | errors | median l0 | median final error [m] | median max tracking error [m] | "
              "median closest limit margin [% of range] | median time in the repulsive zone [joint s] | "
              "median depth-weighted zone time [joint s] | "
              "median cycle p50 [ms] | median cycle p99 [ms] | solver failures |")
    lines += ["", header, "|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    errors: dict[tuple[str, str, str], int] = defaultdict(int)
    for row in rows:
        errors[(row["robot"], row["variant"], row["solver"])] += row["error"] is not None
    for (robot, variant), solvers in sorted(grouped(rows).items()):
        for solver, runs in sorted(solvers.items()):
            lines.append(f"| {robot} | {variant} | {solver} | {len(runs)} | {errors[(robot, variant, solver)]} | "
                         f"{_median(runs, 'l0_mean'):.3f} | {_median(runs, 'final_position_error_m'):.2e} | "
                         f"{_median(runs, 'max_tracking_error_m'):.2e} | "
                         f"{100 * _median(runs, 'joint_limit_min_margin'):.2f} | {_median(runs, 'repulsive_zone_joint_s'):.3f} | "
                         f"{_median(runs, 'repulsive_zone_depth_s'):.3f} | "
                         f"{1e3 * _median(runs, 'cycle_time_p50_s'):.3f} | {1e3 * _median(runs, 'cycle_time_p99_s'):.3f} | "
                         f"{int(sum(r['solver_failures'] for r in runs.values()))} |")
    return "\n".join(lines) + "\n"


def plot(rows: Sequence[dict[str, Any]], out: Path, seed: int = 0) -> list[Path]:
    """Box plots: the paired ratios per robot; final and tracking errors, cycle times p99 per solver (PNG paths)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    written = []
    ratios = [s for s in paired_ratios(rows, seed) if s.tasks]
    if ratios:
        fig, ax = plt.subplots(figsize=(max(6.0, 1.3 * len(ratios)), 4.0))
        ax.boxplot([s.ratios for s in ratios], showfliers=True)
        ax.set_xticks(range(1, len(ratios) + 1), [f"{s.robot}\n{s.solver.replace('_qp', '')}\n{s.variant}"
                                                  for s in ratios], fontsize=8)
        ax.axhline(1.0, color="grey", lw=0.8, ls="--")
        ax.set_ylabel(f"l0(solver) / l0({REFERENCE}), paired by task")
        ax.set_title("active joints relative to the standard QP")
        fig.tight_layout()
        fig.savefig(out / "l0_ratios.png", dpi=120)
        plt.close(fig)
        written.append(out / "l0_ratios.png")
    written += tradeoff_plot(rows, out, plt)
    cells = [(f"{r}\n{s.replace('_qp', '')}\n{v}", runs) for (r, v), solvers in sorted(grouped(rows).items())
             for s, runs in sorted(solvers.items())]
    for column, scale, label, name in (("final_position_error_m", 1.0, "final position error [m]", "final_errors.png"),
                                       ("max_tracking_error_m", 1.0, "max tracking error [m]", "tracking_errors.png"),
                                       ("cycle_time_p99_s", 1e3, "cycle time p99 [ms]", "cycle_times.png"),
                                       ("joint_limit_min_margin", 100.0, "closest joint-limit margin [% of range]",
                                        "joint_limit_margins.png"),
                                       ("repulsive_zone_joint_s", 1.0, "time in the repulsive zone of eq (24) [joint s]",
                                        "repulsive_zone_time.png"),
                                       ("repulsive_zone_depth_s", 1.0, "depth-weighted time in the zone [joint s]",
                                        "repulsive_zone_depth.png")):
        if not cells:
            break
        if not any(_column(runs, column) for _, runs in cells):
            continue  # a table that predates the column
        fig, ax = plt.subplots(figsize=(max(6.0, 1.1 * len(cells)), 4.0))
        ax.boxplot([_column(runs, column, scale) for _, runs in cells])
        ax.set_xticks(range(1, len(cells) + 1), [c for c, _ in cells], fontsize=8)
        if column.endswith("error_m"):
            ax.set_yscale("log")
        ax.set_ylabel(label)
        fig.tight_layout()
        fig.savefig(out / name, dpi=120)
        plt.close(fig)
        written.append(out / name)
    return written


def tradeoff_plot(rows: Sequence[dict[str, Any]], out: Path, plt: Any) -> list[Path]:
    """tradeoff.png (issue 43): per robot, each (solver, variant) as a point, median l0 against the median
    depth-weighted time in eq (24)'s repulsive zone (down and left is better on both); none for a table that
    predates the column."""
    points: dict[str, list[tuple[str, float, float]]] = defaultdict(list)
    seen: dict[tuple[str, str, float, float], str] = {}  # a solver the variant does not change: drawn once
    for (robot, variant), solvers in sorted(grouped(rows).items(), key=lambda item: item[0][1] != "default"):
        for solver, runs in sorted(solvers.items()):
            depth = _median(runs, "repulsive_zone_depth_s")
            l0 = _median(runs, "l0_mean")
            if np.isfinite(depth) and (robot, solver, l0, depth) not in seen:
                label = solver.replace("_qp", "") + ("" if variant == "default" else f" {variant}")
                seen[(robot, solver, l0, depth)] = label
                points[robot].append((label, l0, depth))
    if not points:
        return []
    fig, axes = plt.subplots(1, len(points), figsize=(5.0 * len(points), 4.2), squeeze=False)
    for ax, (robot, cells) in zip(axes[0], sorted(points.items()), strict=True):
        for label, l0, depth in cells:
            ax.scatter([l0], [depth], s=25)
            ax.annotate(label, (l0, depth), fontsize=6, xytext=(3, 3), textcoords="offset points")
        ax.set_xlabel("median mean ||qd||_0 (active joints)")
        ax.set_ylabel("median depth-weighted zone time [joint s]")
        ax.set_title(robot)
    fig.tight_layout()
    fig.savefig(out / "tradeoff.png", dpi=120)
    plt.close(fig)
    return [out / "tradeoff.png"]


def report(table: Path, out: Path, seed: int = 0) -> tuple[str, list[Path]]:
    """The Markdown (also written to ``out/report.md``) and the figures of the dataset ``table``."""
    rows = read_table(table).to_pylist()
    text = markdown(rows, seed)
    out.mkdir(parents=True, exist_ok=True)
    (out / "report.md").write_text(text)
    return text, [out / "report.md", *plot(rows, out, seed)]
