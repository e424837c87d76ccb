"""Multi-start global planner (paper 003, Sect. III-IV) on a process pool.

Two stages, each a set of independent NLPs (:mod:`dualarm_control.planning.global_opt`):

1. key points Gamma (eq 19): ``starts`` random feasible starts; the best result wins;
2. the inner points of each interval between consecutive key points (eq 20), both ends fixed
   at the stage-1 winner: ``min(starts, inner_starts)`` starts per interval (start 0 is the
   interpolation between the ends, starts 1.. add a Gaussian perturbation of
   ``inner_spread`` rad). Measured on the corner path: every inner start reaches the same
   optimum as start 0 (12 starts per interval, values equal to 1e-6), so the default is 10
   inner starts, not the paper's 100; raise ``plan.inner_starts`` to check.

Stage 2 runs for the ``candidates`` best *distinct* stage-1 optima (default 1 = the paper's
method). With more, the complete plan with the lowest whole-path cost
``sum_i c(q_i) + lambda_inner sum_i ||q_i - q_{i-1}||^4`` over all h samples is kept: eq (19)
on six key points is only a proxy of the paper's target sum_i c_i (Sect. III), and the best
key-point optimum did not always give the best complete plan (docs/planner.md).

Every (stage, problem, start) task draws its random numbers from its own
``numpy.random.SeedSequence(seed, spawn_key=(stage, problem, start))`` and results are
reduced in start order (lowest value, ties to the lowest start index), so the plan depends
on the seed and the number of starts only, never on the number of workers or the order in
which tasks finish.
"""

from __future__ import annotations

import multiprocessing
import os
import time
from collections.abc import Callable, Iterator
from concurrent.futures import Future, ProcessPoolExecutor, as_completed
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

import numpy as np

from dualarm_control.kinematics import DualArmModel, FloatArray
from dualarm_control.lifetime import stop_with_parent
from dualarm_control.planning.baseline import BaselineResult, run_baseline
from dualarm_control.planning.config import PlanConfig
from dualarm_control.planning.global_opt import (
    BlockResult,
    closure_errors,
    inner_block,
    interpolated_start,
    key_block,
    random_feasible_chain,
    solve_block,
)
from dualarm_control.planning.index import chain_terms, performance_index
from dualarm_control.planning.path import SampledPath

Progress = Callable[[float, str], None]

KEY_STAGE = 0
INNER_STAGE = 1
RANDOM_INITIAL_CONFIGURATIONS = 3  # Fig. 5: baseline from this many random feasible starts


@dataclass(frozen=True)
class PlanResult:
    """A complete plan and its comparison with the baseline.

    Attributes:
        config: the settings used.
        configurations: planned q_i at every path sample, (h, 14) [rad].
        indices: c(q_i) of eq (14), (h,).
        baseline: the pseudo-inverse baseline from configurations[0].
        random_baselines: baselines from random feasible initial configurations (Fig. 5).
        closure_position_errors, closure_rotation_errors: per sample [m], [rad], (h,).
        joint_limit_violations: number of (sample, joint) outside the limits.
        key_values: eq (19) value of every key-point start, (starts,).
        key_start_values: eq (19) value at every key-point start's initial guess, (starts,).
        best_key_start: index of the key-point start the plan is built on.
        candidate_starts: key-point starts that went through stage 2 (best distinct first).
        candidate_costs: whole-path cost of each candidate's complete plan.
        inner_values: eq (20) value per interval and start, (intervals, starts).
        best_inner_starts: winning start per interval.
        runtime_s: wall time of the optimisation (both stages) [s].
        baseline_runtime_s: wall time of the baselines [s].
        workers: processes used.
    """

    config: PlanConfig
    configurations: FloatArray
    indices: FloatArray
    baseline: BaselineResult
    random_baselines: list[BaselineResult]
    closure_position_errors: FloatArray
    closure_rotation_errors: FloatArray
    joint_limit_violations: int
    key_values: FloatArray
    key_start_values: FloatArray
    best_key_start: int
    candidate_starts: list[int]
    candidate_costs: list[float]
    inner_values: FloatArray
    best_inner_starts: list[int]
    runtime_s: float
    baseline_runtime_s: float
    workers: int

    @property
    def average_index(self) -> float:
        """Mean of c(q_i) over the path samples (the paper's 1.17)."""
        return float(np.mean(self.indices))

    @property
    def baseline_average_index(self) -> float:
        """Mean of c over the path samples for the baseline (the paper's 1.52)."""
        return float(np.mean(self.baseline.indices))


# ---- worker side: one model per process -------------------------------------------------
_WORKER: dict[str, Any] = {}


def _init_worker(config: PlanConfig, parent: int) -> None:
    """Pool initializer: model and sampled path for this worker process, which stops when the planning
    process ``parent`` (its pid) dies, even by SIGKILL (no worker left computing for nobody)."""
    stop_with_parent(parent)
    _WORKER["model"] = DualArmModel(config.robot)
    _WORKER["path"] = config.corner.sample()
    _WORKER["config"] = config


def _rng(config: PlanConfig, stage: int, problem: int, start: int) -> np.random.Generator:
    """The random generator of one task, a pure function of (seed, stage, problem, start)."""
    return np.random.default_rng(np.random.SeedSequence(config.seed, spawn_key=(stage, problem, start)))


def key_task(start: int) -> BlockResult:
    """Stage 1, one start: random feasible chain over Gamma, then eq (19)."""
    model, path, config = _WORKER["model"], _WORKER["path"], _WORKER["config"]
    keys = config.key_indices
    chain = random_feasible_chain(model, path, keys, _rng(config, KEY_STAGE, 0, start))
    return solve_block(model, path, key_block(keys, config.lambda_key), chain)


def inner_task(interval: int, start: int, q_a: FloatArray, q_b: FloatArray) -> BlockResult:
    """Stage 2, one start of one interval: eq (20) between fixed q_a and q_b."""
    model, path, config = _WORKER["model"], _WORKER["path"], _WORKER["config"]
    keys = config.key_indices
    block = inner_block(keys[interval], keys[interval + 1], q_a, q_b, config.lambda_inner)
    rng = None if start == 0 else _rng(config, INNER_STAGE, interval, start)
    initial = interpolated_start(model, path, block, rng, config.inner_spread)
    return solve_block(model, path, block, initial)


# ---- driver ------------------------------------------------------------------------------
_SINGLE_THREAD_ENV = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


@contextmanager
def _single_threaded_children() -> Iterator[None]:
    """Environment for spawned workers: one BLAS/OpenMP thread each (restored afterwards)."""
    saved = {k: os.environ.get(k) for k in _SINGLE_THREAD_ENV}
    os.environ.update(_SINGLE_THREAD_ENV)
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def default_workers() -> int:
    """Every core this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


def _run_tasks(
    calls: list[tuple[Callable[..., BlockResult], tuple[Any, ...]]],
    pool: ProcessPoolExecutor,
    on_done: Callable[[], None],
) -> list[BlockResult]:
    """Run the calls in the pool; results in call order."""
    futures: dict[Future[BlockResult], int] = {pool.submit(fn, *args): k for k, (fn, args) in enumerate(calls)}
    results: list[BlockResult | None] = [None] * len(calls)
    for fut in as_completed(futures):
        results[futures[fut]] = fut.result()
        on_done()
    return [r for r in results if r is not None]


def _best(results: list[BlockResult]) -> int:
    """Index of the lowest value; ties go to the lowest index (order-independent reduction)."""
    return min(range(len(results)), key=lambda k: (results[k].value, k))


def optimise(
    config: PlanConfig, workers: int | None = None, progress: Progress | None = None
) -> tuple[FloatArray, dict[str, Any]]:
    """Both stages with ``config.starts`` starts each; returns (configurations (h, 14), details)."""
    workers = default_workers() if workers is None else max(1, workers)
    n_starts = config.starts
    n_inner = min(config.starts, config.inner_starts)
    keys = config.key_indices
    n_intervals = len(keys) - 1
    total = n_starts + min(config.candidates, n_starts) * n_inner * n_intervals
    done = {"n": 0}

    def tick(label: str) -> Callable[[], None]:
        def on_done() -> None:
            done["n"] += 1
            if progress is not None:
                progress(min(done["n"] / total, 1.0), label)

        return on_done

    with _single_threaded_children():
        ctx = multiprocessing.get_context("spawn")
        pool = ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=_init_worker,
                                   initargs=(config, os.getpid()))
        try:
            result = _both_stages(config, pool, tick, n_starts, n_inner, workers)
        finally:
            pool.shutdown()
    if progress is not None and done["n"] < total:  # fewer distinct candidates than asked for
        progress(1.0, "inner points")
    return result


def distinct_best(results: list[BlockResult], count: int, tolerance: float = 1e-3) -> list[int]:
    """Indices of the ``count`` best results in (value, index) order, skipping any result whose
    configurations are within ``tolerance`` rad (max abs) of one already chosen (the same
    local optimum reached from several starts)."""
    chosen: list[int] = []
    for k in sorted(range(len(results)), key=lambda k: (results[k].value, k)):
        q = results[k].configurations
        if all(np.max(np.abs(q - results[c].configurations)) > tolerance for c in chosen):
            chosen.append(k)
        if len(chosen) == count:
            break
    return chosen


def whole_path_cost(model: DualArmModel, path: SampledPath, configurations: FloatArray, weight: float) -> float:
    """Cost of a complete plan: sum_i c(q_i) + weight * sum_i ||q_i - q_{i-1}||^4 over all h samples
    (eq 19 applied to the whole path; the paper's target sum_i c_i plus its smoothness term)."""
    c = float(np.sum(path_indices(model, path, configurations)))
    steps = np.diff(configurations, axis=0)
    return c + weight * float(np.sum(np.sum(steps**2, axis=1) ** 2))


def _both_stages(
    config: PlanConfig,
    pool: ProcessPoolExecutor,
    tick: Callable[[str], Callable[[], None]],
    n_starts: int,
    n_inner: int,
    workers: int,
) -> tuple[FloatArray, dict[str, Any]]:
    """Stage 1, then stage 2 for each of the best distinct stage-1 candidates, on ``pool``."""
    keys = config.key_indices
    n_intervals = len(keys) - 1
    key_results = _run_tasks([(key_task, (s,)) for s in range(n_starts)], pool, tick("key points"))
    candidates = distinct_best(key_results, config.candidates)
    calls: list[tuple[Callable[..., BlockResult], tuple[Any, ...]]] = []
    for c in candidates:
        q_key = key_results[c].configurations
        calls += [(inner_task, (j, s, q_key[j], q_key[j + 1])) for j in range(n_intervals) for s in range(n_inner)]
    inner_flat = _run_tasks(calls, pool, tick("inner points"))
    model = DualArmModel(config.robot)
    path = config.corner.sample()
    plans, costs, inner_values, best_inner = [], [], [], []
    per_candidate = n_intervals * n_inner
    for rank, c in enumerate(candidates):
        q_key = key_results[c].configurations
        configurations = np.zeros((len(path), model.nq))
        for k, i in enumerate(keys):
            configurations[i] = q_key[k]
        values = np.zeros((n_intervals, n_inner))
        winners = []
        for j in range(n_intervals):
            first = rank * per_candidate + j * n_inner
            results = inner_flat[first:first + n_inner]
            values[j] = [r.value for r in results]
            b = _best(results)
            winners.append(b)
            configurations[keys[j] + 1:keys[j + 1]] = results[b].configurations
        plans.append(configurations)
        costs.append(whole_path_cost(model, path, configurations, config.lambda_inner))
        inner_values.append(values)
        best_inner.append(winners)
    chosen = min(range(len(candidates)), key=lambda r: (costs[r], r))
    details = {
        "key_values": np.array([r.value for r in key_results]),
        "key_start_values": np.array([r.start_value for r in key_results]),
        "best_key_start": candidates[chosen],
        "candidate_starts": candidates,
        "candidate_costs": costs,
        "inner_values": inner_values[chosen],
        "best_inner_starts": best_inner[chosen],
        "workers": workers,
    }
    return plans[chosen], details


def path_indices(model: DualArmModel, path: SampledPath, configurations: FloatArray) -> FloatArray:
    """c(q_i) of eq (14) at every sample, (h,)."""
    return np.array([performance_index(chain_terms(model, q), path.tangents[i]) for i, q in enumerate(configurations)])


def plan(config: PlanConfig, workers: int | None = None, progress: Progress | None = None) -> PlanResult:
    """Optimise, then evaluate the plan and run the baselines (Fig. 4 and Fig. 5)."""
    start = time.perf_counter()
    configurations, details = optimise(config, workers, progress)
    runtime = time.perf_counter() - start
    model = DualArmModel(config.robot)
    path = config.corner.sample()
    errors = np.array([closure_errors(model, q, path.positions[i], path.rotation) for i, q in enumerate(configurations)])
    violations = int(np.sum((configurations < model.q_min) | (configurations > model.q_max)))
    t0 = time.perf_counter()
    baseline = run_baseline(model, path, configurations[0], config.baseline)
    rng = np.random.default_rng(np.random.SeedSequence(config.seed, spawn_key=(2, 0, 0)))
    randoms = []
    for _ in range(RANDOM_INITIAL_CONFIGURATIONS):
        q0 = random_feasible_chain(model, path, [0], rng)[0]
        randoms.append(run_baseline(model, path, q0, config.baseline))
    return PlanResult(
        config=config,
        configurations=configurations,
        indices=path_indices(model, path, configurations),
        baseline=baseline,
        random_baselines=randoms,
        closure_position_errors=errors[:, 0],
        closure_rotation_errors=errors[:, 1],
        joint_limit_violations=violations,
        key_values=details["key_values"],
        key_start_values=details["key_start_values"],
        best_key_start=details["best_key_start"],
        candidate_starts=details["candidate_starts"],
        candidate_costs=details["candidate_costs"],
        inner_values=details["inner_values"],
        best_inner_starts=details["best_inner_starts"],
        runtime_s=runtime,
        baseline_runtime_s=time.perf_counter() - t0,
        workers=details["workers"],
    )
