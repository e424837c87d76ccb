"""``dualarm bench``'s collision part: the control cycle with and without the collision limit,
side by side in one run (issue 27, docs/collision.md).

Per robot, the assembly task is run once in one process (hierarchical sparse QP, the limit on);
its recorded joint states and targets are then replayed through two controllers per solver, one
with the collision limit and one without, interleaved case by case (the order alternating), so
that both see the same machine at the same moment. Reported: the pairs the model checks, the rows
per cycle, the cycle's p50/p99 with and without, and their ratios.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from dualarm_control.app.run.experiment import run_scenario
from dualarm_control.arrays import FloatArray
from dualarm_control.collision import CollisionParams
from dualarm_control.controller import ControllerParams, RelativeController
from dualarm_control.kinematics import DualArmModel
from dualarm_control.metrics import percentiles
from dualarm_control.scenario import Scenario, load_scenario

OFF = CollisionParams(enabled=False)



def interleaved_cycles(on: RelativeController, off: RelativeController, cases: Sequence[tuple[Any, Any]],
                       limit: str, before: Callable[[int], None] | None = None) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Each case (q, target) cycled through ``on`` and ``off``, the order alternating case by case (a drift of the
    machine's speed falls on both alike): the cycle times [s] with and without, (N,) each, and the rows the limit
    named ``limit`` gave each cycle of ``on``, (N,). ``before(k)``, untimed, before case k's cycle of ``on`` (e.g. a
    new snapshot of live obstacles, which a node's intake thread would publish)."""
    times = {True: np.empty(len(cases)), False: np.empty(len(cases))}
    rows = np.zeros(len(cases))
    for k, (q, target) in enumerate(cases):
        for enabled in ((True, False) if k % 2 == 0 else (False, True)):
            controller = on if enabled else off
            if enabled and before is not None:
                before(k)
            start = time.perf_counter()
            cycle = controller.step(q, target)
            times[enabled][k] = time.perf_counter() - start
            report: Any = cycle.reports.get(limit) if enabled else None
            if report is not None:
                rows[k] = report.rows
    return times[True], times[False], rows


def replay_cases(scenario: Scenario, model: DualArmModel) -> list[tuple[Any, Any]]:
    """The scenario run once in process (default controller): each cycle's joint positions q [rad] (n,) with the
    target sampled at its time, the cases a bench replays through two controllers."""
    log = run_scenario(scenario, ControllerParams(), model)
    trajectory = scenario.trajectory(*model.relative_pose(log.positions[0]))
    return [(q, trajectory.sample(t)) for q, t in zip(log.positions, log.time, strict=True)]


def bench_collision(robots: Sequence[str], solvers: Sequence[str], progress: Callable[[str], None] | None = None,
                    scenario_name: str = "assembly") -> dict[str, dict[str, Any]]:
    """Rows "robot | solver": cycle times [ms] with and without the collision limit (module docstring)."""
    rows: dict[str, dict[str, Any]] = {}
    for robot in robots:
        scenario = load_scenario(scenario_name, robot)
        model = DualArmModel(scenario.robot)
        if progress:
            progress(f"collision: {scenario_name} on {robot} (recording the states to replay)")
        cases = replay_cases(scenario, model)
        for solver in solvers:
            if progress:
                progress(f"collision: {robot} | {solver}, {len(cases)} cycles with and without the limit")
            params = scenario.controller_params(ControllerParams(solver=solver))  # the scenario's allowed pairs
            on = RelativeController(model, params)
            off = RelativeController(model, replace(params, collision=OFF))
            assert on.collision_model is not None
            with_limit, without, near = interleaved_cycles(on, off, cases, "collision")
            (on50, on99), (off50, off99) = percentiles(with_limit), percentiles(without)
            rows[f"{robot} | {solver}"] = {
                "pairs": len(on.collision_model.pairs), "cycles": len(cases),
                "rows_p50": float(np.percentile(near, 50)), "rows_max": int(near.max()),
                "cycle_p50_ms": on50 * 1e3, "cycle_p99_ms": on99 * 1e3,
                "off_p50_ms": off50 * 1e3, "off_p99_ms": off99 * 1e3,
                "p50_ratio": on50 / off50, "p99_ratio": on99 / off99,
            }
    return rows
