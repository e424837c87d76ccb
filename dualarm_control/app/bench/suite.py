"""``dualarm bench``: solver and QP back-end timings, pink comparison, exactness, scaling.

Machines are shared and noisy, so every table reports percentiles (p50/p99) and ratios
measured in the same run, never a single absolute figure on its own. Parts:

- random set (:mod:`dualarm_control.app.bench.random_set`): RelativeController.step per solver
  and QP back-end on seeded random configurations and targets, interleaved with pink's
  ``solve_ik`` on the same cases (:mod:`dualarm_control.app.bench.pink`), ratios of each
  p50 to pink's fastest and default set-ups, active joints per cycle; the daqp QP solvers run
  twice, on paper 000's problem as pink solves it and with the collision limit on as by default
  ("solver | daqp, collision limit": pink has no collision checks);
- the scenario (assembly) run in-process per solver and back-end, and pink replaying the
  recorded states and targets of one run;
- exactness of the lasso solve against a reference (proxsuite at eps 1e-12);
- scaling with the number of joints (3- and 4-arm chains of the LWR4);
- the collision limit (:mod:`dualarm_control.app.bench.collision`): the assembly's cycles with and
  without it, per robot (the other parts run without it, but for the random set's and the scenario's
  "collision limit" rows: the solvers on paper 000's problem).
"""

from __future__ import annotations

import json
import platform
import time
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from dualarm_control.app.bench.collision import bench_collision
from dualarm_control.app.bench.pink import pink_cycle, pink_version
from dualarm_control.app.bench.random_set import (
    Case,
    exactness,
    random_cases,
    time_random_set,
    time_scaling,
    with_backend,
)
from dualarm_control.app.run.experiment import run_scenario
from dualarm_control.collision import CollisionParams
from dualarm_control.controller import ControllerParams
from dualarm_control.errors import ParameterError
from dualarm_control.kinematics import DualArmModel
from dualarm_control.metrics import percentiles
from dualarm_control.scenario import Scenario
from dualarm_control.solvers import make_solver

Progress = Callable[[str], None]

PINK_SETUPS = {
    "pink | quadprog, Configuration.update": ("quadprog", True),
    "pink | daqp, Configuration.update": ("daqp", True),
    "pink | proxqp, new Configuration (default)": ("proxqp", False),
}
PINK_DEFAULT = "pink | proxqp, new Configuration (default)"


def solver_configs(
    params: ControllerParams, solvers: Sequence[str], backends: Sequence[str]
) -> tuple[dict[str, ControllerParams], dict[str, str]]:
    """``{"solver | backend": params}`` for every pair a solver accepts, and ``{pair: reason}`` for refusals.

    A solver without a QP (pseudo_inverse) is listed once, with back-end "-".
    """
    configs: dict[str, ControllerParams] = {}
    refused: dict[str, str] = {}
    for s in solvers:
        if not make_solver(s).uses_qp:
            configs[f"{s} | -"] = with_backend(params, s, params.solver_params.qp_backend)
            continue
        for b in backends:
            candidate = with_backend(params, s, b)
            try:
                make_solver(s, candidate.solver_params)
            except ParameterError as exc:
                refused[f"{s} | {b}"] = str(exc)
                continue
            configs[f"{s} | {b}"] = candidate
    return configs, refused


COLLISION_SUFFIX = ", collision limit"
"""What the back-end column of a configuration with the collision limit on ends with."""


def collision_configs(configs: dict[str, ControllerParams]) -> dict[str, ControllerParams]:
    """The daqp QP configurations of ``configs`` again with the collision limit on (its default parameters), as
    ``"solver | daqp, collision limit"``."""
    return {f"{name}{COLLISION_SUFFIX}": replace(params, collision=CollisionParams())
            for name, params in configs.items() if name.endswith(" | daqp")}


def _pink_calls(model: DualArmModel) -> dict[str, Callable[[Case], None]]:
    if pink_version() is None:
        return {}
    return {name: pink_cycle(model, solver, update) for name, (solver, update) in PINK_SETUPS.items()}


def add_ratio(rows: dict[str, dict[str, Any]], reference: str, column: str, key: str = "cycle_p50_ms") -> None:
    """Set ``row[column]`` = row's ``key`` (cycle p50) / the ``reference`` row's, for every row."""
    base = rows[reference][key]
    for row in rows.values():
        row[column] = row[key] / base


def add_cpu_ratio(rows: dict[str, dict[str, Any]]) -> None:
    """``cpu_p50_ratio_to_pink_fastest``: each row's CPU-time p50 / pink's fastest set-up's in CPU time (the
    ratio that holds on a loaded machine: :func:`~dualarm_control.app.bench.random_set.time_random_set`)."""
    fastest = min(PINK_SETUPS, key=lambda name: rows[name]["cpu_p50_ms"])
    add_ratio(rows, fastest, "cpu_p50_ratio_to_pink_fastest", "cpu_p50_ms")


def bench_random(
    model: DualArmModel, params: ControllerParams, configs: dict[str, ControllerParams], count: int, seed: int,
    fallback_reference: str,
) -> dict[str, Any]:
    """Random-set part: timings of every config and of pink, ratios to pink's fastest and default set-ups."""
    cases = random_cases(model, count, seed)
    pink = _pink_calls(model)
    for call in pink.values():  # first calls import and set up pink's QP solvers: not timed
        call(cases[0])
    rows = time_random_set(model, cases, configs, extra=pink)
    out: dict[str, Any] = {"cases": count, "seed": seed, "rows": rows, "ratio_columns": []}
    if pink:
        fastest = min(PINK_SETUPS, key=lambda name: rows[name]["cycle_p50_ms"])
        out["pink_fastest"] = fastest
        add_ratio(rows, fastest, "p50_ratio_to_pink_fastest")
        add_ratio(rows, PINK_DEFAULT, "p50_ratio_to_pink_default")
        add_cpu_ratio(rows)
        out["ratio_columns"] = ["p50_ratio_to_pink_fastest", "p50_ratio_to_pink_default"]
    elif fallback_reference in rows:
        add_ratio(rows, fallback_reference, "p50_ratio_to_reference")
        out["ratio_columns"] = ["p50_ratio_to_reference"]
        out["reference"] = fallback_reference
    return out


def bench_scenario(
    scenario: Scenario, model: DualArmModel, configs: dict[str, ControllerParams], progress: Progress | None = None,
) -> dict[str, Any]:
    """Scenario part: one in-process run per config; pink replays the states and targets of the first QP run."""
    rows: dict[str, dict[str, Any]] = {}
    replay: list[Case] = []
    for name, params in configs.items():
        if progress:
            progress(f"scenario {scenario.name}: {name}")
        log = run_scenario(scenario, params, model)
        s50, s99 = percentiles(log.solve_time)
        c50, c99 = percentiles(log.cycle_time)
        rows[name] = {
            "cycles": len(log.time), "solve_p50_ms": s50 * 1e3, "solve_p99_ms": s99 * 1e3,
            "cycle_p50_ms": c50 * 1e3, "cycle_p99_ms": c99 * 1e3, "cycle_max_ms": float(np.max(log.cycle_time)) * 1e3,
            "share_of_period_p99": c99 / log.period,
        }
        if not replay and not name.endswith("| -"):
            trajectory = scenario.trajectory(*model.relative_pose(log.positions[0]))
            replay = [Case(q=q, target=trajectory.sample(t)) for q, t in zip(log.positions, log.time, strict=True)]  # type: ignore[arg-type]
    out: dict[str, Any] = {"scenario": scenario.name, "rows": rows}
    pink = _pink_calls(model)
    if pink and replay:
        if progress:
            progress(f"scenario {scenario.name}: pink replay")
        for name, call in pink.items():
            call(replay[0])
            samples = []
            for case in replay:
                start = time.perf_counter()
                call(case)
                samples.append(time.perf_counter() - start)
            c50, c99 = percentiles(np.asarray(samples))
            rows[name] = {"cycles": len(samples), "cycle_p50_ms": c50 * 1e3, "cycle_p99_ms": c99 * 1e3}
        fastest = min(PINK_SETUPS, key=lambda name: rows[name]["cycle_p50_ms"])
        out["pink_fastest"] = fastest
        add_ratio(rows, fastest, "p50_ratio_to_pink_fastest")
        if progress:
            progress(f"scenario {scenario.name}: its states replayed through every configuration and pink, interleaved")
        scenario_params = {name: scenario.controller_params(params) for name, params in configs.items()}  # its pairs
        out["replay"] = replayed = time_random_set(model, replay, scenario_params, extra=pink, reset=False)
        out["replay_pink_fastest"] = fastest = min(PINK_SETUPS, key=lambda name: replayed[name]["cycle_p50_ms"])
        add_ratio(replayed, fastest, "p50_ratio_to_pink_fastest")
        add_cpu_ratio(replayed)
    return out


def run_bench(
    scenario: Scenario | None,
    solvers: Sequence[str],
    backends: Sequence[str],
    count: int = 400,
    seed: int = 0,
    fallback_reference: str = "standard_qp | daqp",
    scaling_arms: Sequence[int] = (2, 3, 4),
    progress: Progress | None = None,
    collision_robots: Sequence[str] = (),
) -> dict[str, Any]:
    """The whole benchmark as one JSON-able record (see the module docstring)."""
    model = DualArmModel()
    # the solvers on paper 000's problem (as pink solves it); then, beside pink without collision checks, the QP
    # solvers with the collision limit on, as by default (issue 39's target); the collision part compares both
    params = ControllerParams(collision=CollisionParams(enabled=False))
    configs, refused = solver_configs(params, solvers, backends)
    configs.update(collision_configs(configs))
    say = progress or (lambda _msg: None)
    say(f"random set: {count} cases x {len(configs)} configurations")
    record: dict[str, Any] = {
        "machine": {"python": platform.python_version(), "processor": platform.processor() or platform.machine(),
                    "pink": pink_version()},
        "refused": refused,
        "random": bench_random(model, params, configs, count, seed, fallback_reference),
    }
    say("exactness of the lasso solve")
    record["exactness"] = exactness(model, random_cases(model, count, seed), params)
    say("scaling with the number of joints")
    qp_solvers = [s for s in solvers if make_solver(s).uses_qp]
    record["scaling"] = time_scaling(model, params, qp_solvers, backends, scaling_arms, count=max(count // 4, 20),
                                     seed=seed + 1)
    if scenario is not None:
        scenario_configs = {k: v for k, v in configs.items()
                            if k.split(" | ")[1].split(",")[0] in ("daqp", "proxsuite", "-")}
        record["scenario"] = bench_scenario(scenario, model, scenario_configs, progress)
    if collision_robots:
        record["collision"] = bench_collision(collision_robots, ["hierarchical_sparse_qp", "sparse_qp", "standard_qp"],
                                              progress)
    return record


def _table(rows: dict[str, dict[str, Any]], columns: Sequence[tuple[str, str, str]], first: str) -> list[str]:
    """Markdown table; row names "a | b" fill the first columns named by ``first`` ("a | b")."""
    head = [*first.split(" | "), *(c[1] for c in columns)]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for name, row in rows.items():
        cells = name.split(" | ")
        for key, _, fmt in columns:
            value = row.get(key)
            cells.append("—" if value is None else fmt.format(value))
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def format_bench(record: dict[str, Any]) -> str:
    """Markdown report of :func:`run_bench`."""
    rnd = record["random"]
    ratio_cols = [(c, "cycle " + c.replace("p50_ratio_to_", "p50 / ").replace("_", " "), "{:.2f}")
                  for c in rnd["ratio_columns"]]
    timing = [("cycle_p50_ms", "cycle p50 [ms]", "{:.3f}"), ("cycle_p99_ms", "cycle p99 [ms]", "{:.3f}"),
              ("solve_p50_ms", "solve p50 [ms]", "{:.3f}"), ("solve_p99_ms", "solve p99 [ms]", "{:.3f}")]
    lines = [f"# Solver benchmark (python {record['machine']['python']}, pink {record['machine']['pink']})", "",
             f"## Random set: {rnd['cases']} configurations and targets (seed {rnd['seed']}), one run, interleaved", ""]
    cpu = [("cpu_p50_ms", "CPU p50 [ms]", "{:.3f}"), ("cpu_p99_ms", "CPU p99 [ms]", "{:.3f}"),
           ("cpu_p50_ratio_to_pink_fastest", "CPU p50 / pink fastest", "{:.2f}")]
    lines += _table(rnd["rows"], [*timing, *ratio_cols, *cpu,
                                  ("active_joints_p50", "active joints p50", "{:.0f}"),
                                  ("active_joints_max", "max", "{:d}"),
                                  ("share_at_most_6_active", "share <= 6", "{:.3f}"),
                                  ("failures", "failures", "{:d}"),
                                  ("max_bound_excess", "max bound excess [rad/s]", "{:.1e}")],
                       "solver | QP back-end")
    if rnd.get("pink_fastest"):
        lines += ["", f"pink's fastest set-up in this run: {rnd['pink_fastest']}."]
    if record["refused"]:
        lines += ["", "Refused at start-up (no silent zero command):", ""]
        lines += [f"- {k}: {v}" for k, v in record["refused"].items()]
    ex = record["exactness"]
    lines += ["", f"## Exactness of the lasso (eq 17-19) on the random set, vs {ex['reference']}", "",
              f"- references verified optimal (KKT): {ex['verified_references']} of {ex['cases']}",
              (f"- relative objective difference to them: min {ex['objective_rel_diff_min']:.2e}, "
               f"max {ex['objective_rel_diff_max']:.2e}"),
              f"- same active set (non-zero joints and joints at a bound, 1e-7): {ex['same_active_set']}",
              (f"- relative difference to the raw reference solve: min {ex['raw_reference_rel_diff_min']:.2e}, "
               f"max {ex['raw_reference_rel_diff_max']:.2e}")]
    if "scenario" in record:
        sc = record["scenario"]
        lines += ["", f"## Scenario {sc['scenario']} (in-process, lockstep); pink replays the recorded states", ""]
        lines += _table(sc["rows"], [("cycles", "cycles", "{:d}"), *timing,
                                     ("p50_ratio_to_pink_fastest", "cycle p50 / pink fastest", "{:.2f}")],
                        "solver | QP back-end")
        if sc.get("replay"):
            title = (f"## Scenario {sc['scenario']}: its recorded states replayed through every configuration "
                     "and pink, interleaved case by case (warm: no reset)")
            lines += ["", title, ""]
            lines += _table(sc["replay"], [("samples", "cycles", "{:d}"), *timing,
                                           ("p50_ratio_to_pink_fastest", "cycle p50 / pink fastest", "{:.2f}"), *cpu],
                            "solver | QP back-end")
    if record.get("collision"):
        lines += ["", "## Collision limit: the assembly's recorded cycles with and without it, interleaved", ""]
        lines += _table(record["collision"], [("pairs", "pairs", "{:d}"), ("rows_p50", "rows p50", "{:.0f}"),
                                              ("rows_max", "rows max", "{:d}"),
                                              ("cycle_p50_ms", "with: p50 [ms]", "{:.3f}"),
                                              ("cycle_p99_ms", "p99 [ms]", "{:.3f}"),
                                              ("off_p50_ms", "without: p50 [ms]", "{:.3f}"),
                                              ("off_p99_ms", "p99 [ms]", "{:.3f}"),
                                              ("p50_ratio", "p50 ratio", "{:.2f}"), ("p99_ratio", "p99 ratio", "{:.2f}")],
                        "robot | solver")
    lines += ["", "## Scaling with the number of joints (chains of LWR4 arms, relative tasks between neighbours)", ""]
    lines += _table(record["scaling"], [("solve_p50_ms", "solve p50 [ms]", "{:.3f}"),
                                        ("solve_p99_ms", "solve p99 [ms]", "{:.3f}"),
                                        ("active_joints_p50", "active joints p50", "{:.0f}")],
                    "arms | solver | QP back-end")
    return "\n".join(lines) + "\n"


def write_bench(out: Path, record: dict[str, Any]) -> None:
    """Write ``out/bench.json`` and ``out/bench.md``."""
    out.mkdir(parents=True, exist_ok=True)
    (out / "bench.json").write_text(json.dumps(record, indent=2) + "\n")
    (out / "bench.md").write_text(format_bench(record))
