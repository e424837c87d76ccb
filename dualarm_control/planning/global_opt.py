"""Global manipulability optimisation of a relative path (paper 003, Sect. III, eq 15-20).

A *block* is a run of consecutive path points whose configurations are optimised together:

* key points Gamma (eq 19): ``w = sum_i c(q_i) + lambda sum_{i>1} ||q_i - q_{i-1}||^4``;
* the inner points of one interval between two fixed key configurations (eq 20): the same
  sum plus ``lambda (||q_first - q_before||^4 + ||q_after - q_last||^4)``;

subject to the joint limits (eq 16) and the closure constraint T_e1e2(q_i) = T_d,i (eq 17),
written as ``h_i(q_i) = [p(q_i) - p_d,i; log3(R_d^T R(q_i))] = 0`` (6 per point). ``c`` is
the index of eq (14) with u_i = [t_i; 0]. Each block is one NLP solved by scipy's SLSQP with
analytic gradients (:mod:`dualarm_control.planning.index`), from one start; the multi-start
loop and its reduction are in :mod:`dualarm_control.app.plan.optimise`.

Units: q [rad], c [m^2/rad^2], lambda [m^2/rad^6] (so that lambda ||dq||^4 is an index).
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from dualarm_control.kinematics import DualArmModel, FloatArray
from dualarm_control.planning.index import (
    ChainTerms,
    chain_terms,
    closure_jacobian,
    closure_residual,
    index_and_gradient,
    performance_index,
)
from dualarm_control.planning.path import SampledPath

# Feasibility after the final Newton polish (well inside the 1e-5 m / 1e-4 rad).
POSITION_TOLERANCE = 1e-9  # m
ROTATION_TOLERANCE = 1e-8  # rad
SAMPLING_MARGIN = 0.05  # random configurations are drawn in the inner 90 % of each joint range


@dataclass(frozen=True)
class Block:
    """One NLP of eq (19) or (20).

    Attributes:
        indices: 0-based path indices of the free points, increasing.
        weight: lambda of the smoothness term.
        before, after: fixed configurations next to the first / last free point (eq 20), (14,),
            or None (eq 19).
    """

    indices: tuple[int, ...]
    weight: float
    before: FloatArray | None = None
    after: FloatArray | None = None


@dataclass(frozen=True)
class BlockResult:
    """Outcome of one start of one block.

    Attributes:
        configurations: optimised q_i, (n, 14) [rad], feasible to the module tolerances.
        value: objective w (eq 19/20) at ``configurations``.
        start_configurations: the feasible start, (n, 14).
        start_value: w at the start.
        iterations: SLSQP iterations.
        status: "optimised", or "kept_start" when SLSQP did not improve on a feasible start.
    """

    configurations: FloatArray
    value: float
    start_configurations: FloatArray
    start_value: float
    iterations: int
    status: str


def smoothness(configs: Sequence[FloatArray], before: FloatArray | None, after: FloatArray | None) -> float:
    """Smoothness sum of eq (18)/(20) without lambda: sum of ||q_i - q_{i-1}||^4 along the chain."""
    chain = ([before] if before is not None else []) + list(configs) + ([after] if after is not None else [])
    return float(sum(np.sum((b - a) ** 2) ** 2 for a, b in itertools.pairwise(chain)))


class BlockProblem:
    """Objective, gradient, constraints and constraint Jacobian of one block, with a kinematics cache."""

    def __init__(self, model: DualArmModel, path: SampledPath, block: Block) -> None:
        self.model = model
        self.path = path
        self.block = block
        self.n = len(block.indices)
        self.nq = model.nq
        self._x: FloatArray | None = None
        self._terms: list[ChainTerms] = []

    def terms(self, x: FloatArray) -> list[ChainTerms]:
        """Chain terms of every free point at x (cached for the last x)."""
        if self._x is None or not np.array_equal(x, self._x):
            qs = x.reshape(self.n, self.nq)
            self._terms = [chain_terms(self.model, q) for q in qs]
            self._x = x.copy()
        return self._terms

    def objective(self, x: FloatArray) -> tuple[float, FloatArray]:
        """w(x) of eq (19)/(20) and its gradient, (n*14,)."""
        qs = x.reshape(self.n, self.nq)
        grad = np.zeros((self.n, self.nq))
        value = 0.0
        for k, (terms, i) in enumerate(zip(self.terms(x), self.block.indices, strict=True)):
            c, g = index_and_gradient(terms, self.path.tangents[i])
            value += c
            grad[k] += g
        lam = self.block.weight
        chain: list[tuple[int | None, FloatArray]] = []
        if self.block.before is not None:
            chain.append((None, self.block.before))
        chain += [(k, qs[k]) for k in range(self.n)]
        if self.block.after is not None:
            chain.append((None, self.block.after))
        for (ka, qa), (kb, qb) in itertools.pairwise(chain):
            d = qb - qa
            sq = float(d @ d)
            value += lam * sq * sq
            g = 4.0 * lam * sq * d  # d/dq_b of lambda ||q_b - q_a||^4
            if kb is not None:
                grad[kb] += g
            if ka is not None:
                grad[ka] -= g
        return value, grad.ravel()

    def value(self, x: FloatArray) -> float:
        """w(x) without the gradient."""
        qs = x.reshape(self.n, self.nq)
        c = sum(performance_index(t, self.path.tangents[i])
                for t, i in zip(self.terms(x), self.block.indices, strict=True))
        return float(c + self.block.weight * smoothness(list(qs), self.block.before, self.block.after))

    def constraints(self, x: FloatArray) -> FloatArray:
        """Stacked closure residuals h_i (eq 17), (6n,)."""
        rot = self.path.rotation
        return np.concatenate([closure_residual(t, self.path.positions[i], rot)
                               for t, i in zip(self.terms(x), self.block.indices, strict=True)])

    def constraint_jacobian(self, x: FloatArray) -> FloatArray:
        """Block-diagonal d h / d x, (6n, 14n)."""
        jac = np.zeros((6 * self.n, self.nq * self.n))
        for k, t in enumerate(self.terms(x)):
            jac[6 * k:6 * k + 6, self.nq * k:self.nq * (k + 1)] = closure_jacobian(t, self.path.rotation)
        return jac


def closure_errors(model: DualArmModel, q: FloatArray, position: FloatArray, rotation: FloatArray) -> tuple[float, float]:
    """(position error [m], rotation error [rad]) of the closure constraint (eq 17) at q."""
    h = closure_residual(chain_terms(model, q), position, rotation)
    return float(np.linalg.norm(h[:3])), float(np.linalg.norm(h[3:]))


def project_to_pose(
    model: DualArmModel,
    q0: FloatArray,
    position: FloatArray,
    rotation: FloatArray,
    max_iterations: int = 60,
) -> FloatArray | None:
    """Nearest-ish configuration within the joint limits that satisfies eq (17), by damped Newton.

    Steps ``dq = -J^T (J J^T + mu I)^{-1} h`` (J the closure Jacobian) from q0, clipped to the
    limits; joints held at a limit that the step would push further are frozen for that step.

    Returns:
        q (14,) with closure errors below POSITION_TOLERANCE / ROTATION_TOLERANCE, or None.
    """
    lo, hi = model.q_min, model.q_max
    q = np.clip(np.asarray(q0, dtype=float), lo, hi)
    for _ in range(max_iterations):
        terms = chain_terms(model, q)
        h = closure_residual(terms, position, rotation)
        if np.linalg.norm(h[:3]) < POSITION_TOLERANCE and np.linalg.norm(h[3:]) < ROTATION_TOLERANCE:
            return q
        jac = closure_jacobian(terms, rotation)
        mu = min(1e-2, float(h @ h))
        free = np.ones(q.size, dtype=bool)
        for _pass in range(2):
            jf = jac * free
            dq = -jf.T @ np.linalg.solve(jf @ jf.T + mu * np.eye(6), h)
            blocked = ((q <= lo) & (dq < 0)) | ((q >= hi) & (dq > 0))
            if not np.any(blocked & free):
                break
            free &= ~blocked
        step = float(np.max(np.abs(dq)))
        if step > 0.5:  # rad: keep Newton steps local
            dq *= 0.5 / step
        q = np.clip(q + dq, lo, hi)
    return None


def random_configuration(model: DualArmModel, rng: np.random.Generator) -> FloatArray:
    """Uniform random q in the inner 90 % of every joint range, (14,) [rad]."""
    span = model.q_max - model.q_min
    return model.q_min + span * (SAMPLING_MARGIN + (1.0 - 2.0 * SAMPLING_MARGIN) * rng.random(model.nq))


def feasible_chain(
    model: DualArmModel, path: SampledPath, indices: Sequence[int], seed_configuration: FloatArray
) -> FloatArray | None:
    """Feasible configurations for ``indices`` by continuation: project the seed onto the first
    pose, then each solution onto the next pose. (n, 14) or None if a projection fails."""
    out = []
    q = seed_configuration
    for i in indices:
        projected = project_to_pose(model, q, path.positions[i], path.rotation)
        if projected is None:
            return None
        out.append(projected)
        q = projected
    return np.array(out)


def random_feasible_chain(
    model: DualArmModel, path: SampledPath, indices: Sequence[int], rng: np.random.Generator, attempts: int = 50
) -> FloatArray:
    """A random feasible start (eq 16-17 hold): a random configuration carried along the poses.

    Raises:
        RuntimeError: no feasible chain after ``attempts`` random seeds.
    """
    for _ in range(attempts):
        chain = feasible_chain(model, path, indices, random_configuration(model, rng))
        if chain is not None:
            return chain
    raise RuntimeError(f"no feasible configuration chain for path points {list(indices)} in {attempts} attempts")


def solve_block(
    model: DualArmModel,
    path: SampledPath,
    block: Block,
    start: FloatArray,
    max_iterations: int = 200,
) -> BlockResult:
    """Solve one NLP (eq 19 or 20) with SLSQP from a feasible ``start`` (n, 14).

    The SLSQP result is polished point by point with :func:`project_to_pose` (closure errors
    then ~1e-10); if that fails, or the polished value is not below the start's, the start
    is returned (status "kept_start"): a block never returns worse than its starting point.
    """
    # imported here: the nodes, which only execute a plan, never need scipy.optimize (0.1 s to import)
    from scipy.optimize import Bounds, minimize

    problem = BlockProblem(model, path, block)
    x0 = np.asarray(start, dtype=float).ravel()
    start_value = problem.value(x0)
    lo = np.tile(model.q_min, problem.n)
    hi = np.tile(model.q_max, problem.n)
    result = minimize(
        problem.objective,
        x0,
        jac=True,
        method="SLSQP",
        bounds=Bounds(lo, hi),
        constraints=[{"type": "eq", "fun": problem.constraints, "jac": problem.constraint_jacobian}],
        options={"maxiter": max_iterations, "ftol": 1e-10},
    )
    iterations = int(result.get("nit", 0))
    x = np.clip(np.asarray(result.x, dtype=float), lo, hi).reshape(problem.n, problem.nq)
    polished = []
    for q, i in zip(x, block.indices, strict=True):
        p = project_to_pose(model, q, path.positions[i], path.rotation, max_iterations=20)
        if p is None:
            break
        polished.append(p)
    if len(polished) == problem.n:
        xp = np.array(polished)
        value = problem.value(xp.ravel())
        if value < start_value:
            return BlockResult(xp, value, np.array(start), start_value, iterations, "optimised")
    return BlockResult(np.array(start), start_value, np.array(start), start_value, iterations, "kept_start")


def key_block(key_indices: Sequence[int], weight: float = 1.5) -> Block:
    """The key-point NLP of eq (19) (paper: Gamma = {1, 7, 13, 19, 25, 31}, 1-based; lambda = 1.5)."""
    return Block(indices=tuple(key_indices), weight=weight)


def inner_block(a: int, b: int, q_a: FloatArray, q_b: FloatArray, weight: float = 3.0) -> Block:
    """The NLP of eq (20) for the points strictly between path indices a and b (paper: lambda = 3)."""
    return Block(indices=tuple(range(a + 1, b)), weight=weight, before=np.asarray(q_a), after=np.asarray(q_b))


def interpolated_start(
    model: DualArmModel, path: SampledPath, block: Block, rng: np.random.Generator | None, spread: float
) -> FloatArray:
    """Feasible start of an inner block: linear interpolation between the fixed ends, plus a
    Gaussian perturbation of ``spread`` [rad] if ``rng`` is given, each point projected (eq 17).

    Raises:
        RuntimeError: a projection failed (after 20 perturbations).
    """
    assert block.before is not None and block.after is not None
    n = len(block.indices)
    for _ in range(20):
        out = []
        for k, i in enumerate(block.indices):
            s = (k + 1) / (n + 1)
            q = (1.0 - s) * block.before + s * block.after
            if rng is not None:
                q = q + spread * rng.standard_normal(model.nq)
            projected = project_to_pose(model, q, path.positions[i], path.rotation)
            if projected is None:
                break
            out.append(projected)
        if len(out) == n:
            return np.array(out)
        if rng is None:
            rng = np.random.default_rng(0)
            spread = max(spread, 0.05)
    raise RuntimeError(f"no feasible start for inner points {list(block.indices)}")
