"""One run of a sweep: sample its task, run it with the one in-process runner, summarise it as a row.

What runs on a Dask worker (or in the sweep's own process). The row's metrics are metrics.json's
(:func:`dualarm_control.app.record.report.summarize_run`); a run that raises is a row with the
error's text and NaN metrics, not a failed Dask task. The scenario's robot model, collision model
and task sampler are built once per process (``lru_cache``).
"""

from __future__ import annotations

import math
import time
import traceback
from collections.abc import Sequence
from dataclasses import dataclass, replace
from functools import lru_cache
from typing import Any

from dualarm_control.app.record.report import (
    JOINT_LIMIT_KEYS,
    METRIC_KEYS,
    TRACKING_KEYS,
    summarize_run,
)
from dualarm_control.app.run.experiment import run_scenario
from dualarm_control.app.sweep.spec import SweepSpec
from dualarm_control.app.sweep.tasks import RelativeTask, TaskSampler, TaskSampling
from dualarm_control.kinematics import DualArmModel
from dualarm_control.scenario import Scenario, load_scenario

KEY_COLUMNS = ("robot", "solver", "variant", "seed", "task")
METRIC_COLUMNS = METRIC_KEYS + TRACKING_KEYS + JOINT_LIMIT_KEYS
WALL_COLUMNS = ("cycle_time_p50_s", "cycle_time_p99_s", "wall_time_s")
"""Wall-clock columns: they differ between two runs of the same task; every other column is bitwise the same."""
COLUMNS = ("key", *KEY_COLUMNS, *METRIC_COLUMNS, "steps", "task_duration_s", "wall_time_s", "error")


@dataclass(frozen=True)
class RunKey:
    """One cell of the grid: (robot, solver, variant, seed, task index)."""

    robot: str
    solver: str
    variant: str
    seed: int
    task: int

    @property
    def text(self) -> str:
        """The key as one string (the Dask key and the table's ``key`` column)."""
        return f"{self.robot}|{self.solver}|{self.variant}|{self.seed}|{self.task}"


def grid(spec: SweepSpec) -> list[RunKey]:
    """Every run of the spec, task-major (the solvers of one task run close together)."""
    return [RunKey(robot, solver, variant, spec.seed, task) for task in range(spec.tasks) for robot in spec.robots
            for variant, _ in spec.variants for solver in spec.solvers]


@lru_cache(maxsize=8)
def _cell(scenario: str, robot: str) -> tuple[Scenario, DualArmModel]:
    base = load_scenario(scenario, robot)
    return base, DualArmModel(base.robot)


@lru_cache(maxsize=8)
def _sampler(scenario: str, robot: str, sampling: TaskSampling, settle_time: float) -> TaskSampler:
    base, model = _cell(scenario, robot)
    return TaskSampler(model, sampling, base.limits, settle_time, base.collision_allowed)


@lru_cache(maxsize=64)
def sample_task(scenario: str, robot: str, sampling: TaskSampling, settle_time: float, seed: int,
                task: int) -> RelativeTask:
    """Task ``task`` of ``seed`` for ``robot`` in ``scenario``'s cell (cached per process)."""
    return _sampler(scenario, robot, sampling, settle_time).sample(seed, task)


def task_scenario(base: Scenario, task: RelativeTask, settle_time: float) -> Scenario:
    """The scenario of a task: ``base``'s cell, limits and allowed pairs, the task's start and goal."""
    return replace(base, name=f"{base.name} task {task.seed}/{task.index}", initial_positions=task.start,
                   reference=task.source(), settle_time=settle_time)


def empty_row(key: RunKey) -> dict[str, Any]:
    """A row with the key and NaN metrics."""
    row: dict[str, Any] = {"key": key.text, **{c: getattr(key, c) for c in KEY_COLUMNS}}
    row.update({c: math.nan for c in METRIC_COLUMNS}, steps=0, task_duration_s=math.nan, wall_time_s=math.nan,
               error=None)
    return row


def run_one(spec: SweepSpec, key: RunKey) -> dict[str, Any]:
    """The row of one run (module docstring); never raises for a failing run."""
    row = empty_row(key)
    start = time.perf_counter()
    try:
        base, model = _cell(spec.scenario, key.robot)
        task = sample_task(spec.scenario, key.robot, spec.sampling, spec.settle_time, key.seed, key.task)
        scenario = task_scenario(base, task, spec.settle_time)
        params = spec.params(key.robot, key.solver, key.variant)
        record = run_scenario(scenario, params, model)
        summary = summarize_run(record, scenario, model, params.alpha)
        row.update({c: float(summary[c]) for c in METRIC_COLUMNS if c in summary})
        row.update(steps=len(record.time), task_duration_s=task.duration)
    except Exception as exc:  # noqa: BLE001 -- a run's failure is its row, not the sweep's crash
        row["error"] = f"{type(exc).__name__}: {exc}\n{traceback.format_exc(limit=3)}"
    row["wall_time_s"] = time.perf_counter() - start
    return row


def task_groups(keys: Sequence[RunKey]) -> list[list[RunKey]]:
    """``keys`` grouped by task (robot, variant, seed, task index), in order of first appearance: the
    runs of one sampled task, the unit of work sent to a Dask worker."""
    groups: dict[tuple[str, str, int, int], list[RunKey]] = {}
    for key in keys:
        groups.setdefault((key.robot, key.variant, key.seed, key.task), []).append(key)
    return list(groups.values())


def run_runs(spec: SweepSpec, keys: Sequence[RunKey]) -> list[dict[str, Any]]:
    """The rows of ``keys`` (:func:`run_one` each), in order."""
    return [run_one(spec, key) for key in keys]
