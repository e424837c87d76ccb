"""What a task is: scalar or vector task functions f(q, t) with bounds, the one mechanism of both papers.

A task (like pink's and mink's tasks and limits) is a small object whose ``evaluate``
returns its :class:`TaskRows` at a :class:`~dualarm_control.kinematics.Configuration` and
time t: the value f (m,), the bound b (m,), the Jacobian df/dq (m, n), the time derivative
df/dt (m,), its kind (equality f = b or inequality f <= b), its gain k [1/s] and its slack
weight. Paper 001 (Wang et al.), eq (5)-(6) and (16)-(17), turns every task into the rows

    (df/dq) qd  = k (b - f) - df/dt     (equality)
    (df/dq) qd <= k (b - f) - df/dt     (inequality),

so an equality error decays as exp(-k t) and an inequality bound is approached no faster
than that. Paper 000's closed-loop relative pose control (eq 13: J qd = xd* + K e) is the
equality task :class:`RelativePoseTask` with f = -e, b = 0, df/dt = -xd*.

Units: positions m, angles rad, time s; velocities m/s, rad/s. Joint vector order of
:class:`~dualarm_control.kinematics.DualArmModel` (left 1..7, right 1..7).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal, Protocol

import numpy as np

from dualarm_control.kinematics import FloatArray
from dualarm_control.solvers.problem import ControlProblem

if TYPE_CHECKING:
    from dualarm_control.kinematics import Configuration

Kind = Literal["equality", "inequality"]
EQUALITY: Kind = "equality"
INEQUALITY: Kind = "inequality"

DEFAULT_EQUALITY_WEIGHT = 1.0
"""Slack weight of an equality row: cheap, so equalities give way when tasks conflict."""
DEFAULT_INEQUALITY_WEIGHT = 1.0e3
"""Slack weight of an inequality row (safety): expensive, kept whenever feasible."""


@dataclass(slots=True)
class TaskRows:
    """One task evaluated at (q, t).

    A per-cycle record: slotted, not frozen (cheaper to build, docs/bench.md); read-only by convention.

    Attributes:
        name: task name (for logs and plots).
        kind: "equality" (f = b) or "inequality" (f <= b).
        value: f(q, t), (m,).
        bound: b, (m,).
        jacobian: df/dq, (m, n).
        time_derivative: df/dt (explicit time dependence), (m,).
        gain: k [1/s], > 0.
        weight: slack weight of every row, > 0.
        priority: 1 (the default: every task of priority 1 weighted beside the others in one QP) or 2 (an
            equality task realised in the optimal set of the priority-1 tasks, in every solver:
            :mod:`dualarm_control.solvers.priority`; issue 41's absolute pose under the relative one).
    """

    name: str
    kind: Kind
    value: FloatArray
    bound: FloatArray
    jacobian: FloatArray
    time_derivative: FloatArray
    gain: float
    weight: float
    priority: int = 1

    @property
    def reference(self) -> FloatArray:
        """Right-hand side k (b - f) - df/dt of eq (16)-(17), (m,)."""
        return self.gain * (self.bound - self.value) - self.time_derivative

    @property
    def violation(self) -> FloatArray:
        """f - b, (m,): > 0 means an inequality is violated."""
        return self.value - self.bound


class Task(Protocol):
    """What every task provides (see the module docstring)."""

    @property
    def name(self) -> str: ...

    @property
    def kind(self) -> Kind: ...

    def evaluate(self, conf: Configuration, t: float) -> TaskRows: ...


PRIORITIES = (1, 2)
"""The priorities a task may have (:class:`TaskRows`)."""


@dataclass(frozen=True)
class SecondPriority:
    """An equality task at priority 2 (``<task>.priority: 2`` in a task scenario): its rows, marked so that
    :func:`assemble_problem` puts them under the priority-1 tasks."""

    task: Task

    def __post_init__(self) -> None:
        if self.task.kind != EQUALITY:
            raise ValueError(f"task {self.task.name!r}: only an equality task can have priority 2, this one is an "
                             f"{self.task.kind}")

    @property
    def name(self) -> str:
        return self.task.name

    @property
    def kind(self) -> Kind:
        return self.task.kind

    def evaluate(self, conf: Configuration, t: float) -> TaskRows:
        rows = self.task.evaluate(conf, t)
        rows.priority = 2
        return rows


def check_gain_weight(name: str, gain: float, weight: float) -> None:
    if not (math.isfinite(gain) and gain > 0):
        raise ValueError(f"task {name!r}: gain must be > 0 [1/s], got {gain}")
    if not (math.isfinite(weight) and weight > 0):
        raise ValueError(f"task {name!r}: slack weight must be > 0, got {weight}")


def evaluate_tasks(tasks: Sequence[Task], conf: Configuration, t: float) -> tuple[TaskRows, ...]:
    """Every task's rows at one configuration and time."""
    return tuple(task.evaluate(conf, t) for task in tasks)


def assemble_problem(rows: Sequence[TaskRows], lower: FloatArray, upper: FloatArray,
                     repulsive: FloatArray) -> ControlProblem:
    """Stack task rows into one :class:`ControlProblem` (paper 001, eq (12)-(14)).

    Equality rows become ``jacobian``/``reference`` (A_e, k_e(b_e - f_e) - h_e), inequality
    rows ``inequality_jacobian``/``inequality_bound``; slack weights per row. A single
    equality task and no inequality gives exactly paper 000's problem (J, xd* + K e). Equality rows of
    priority 2 become ``secondary_jacobian``/``secondary_reference``, scaled by the square root of their weight.

    Args:
        rows: evaluated tasks, at least one equality.
        lower, upper: joint velocity bounds of eq (23) [rad/s], (n,). repulsive: (n,).
    """
    if len(rows) == 1 and rows[0].kind == EQUALITY and rows[0].priority == 1:  # paper 000's problem, every cycle
        return ControlProblem(rows[0].jacobian, rows[0].reference, lower, upper, repulsive)
    eq = [r for r in rows if r.kind == EQUALITY and r.priority == 1]
    ie = [r for r in rows if r.kind == INEQUALITY]
    second = [r for r in rows if r.kind == EQUALITY and r.priority == 2]
    if not eq:
        raise ValueError("at least one equality task of priority 1 is needed")
    problem = _first_priority(eq, ie, lower, upper, repulsive)
    if second:
        scale = np.concatenate([np.full(r.value.shape[0], math.sqrt(r.weight)) for r in second])
        problem.secondary_jacobian = np.vstack([r.jacobian for r in second]) * scale[:, None]
        problem.secondary_reference = np.concatenate([r.reference for r in second]) * scale
    return problem


def _first_priority(eq: Sequence[TaskRows], ie: Sequence[TaskRows], lower: FloatArray, upper: FloatArray,
                    repulsive: FloatArray) -> ControlProblem:
    """The problem of the priority-1 equality rows ``eq`` (at least one) and the inequality rows ``ie``.

    Several equality tasks are weighted beside each other in every solver: their rows are scaled by the square root
    of their weight (1/2 w ||a qd - r||^2 = 1/2 ||sqrt(w) a qd - sqrt(w) r||^2, the constraint-based QP's term), so
    the problem carries no ``equality_weights``."""
    if len(eq) == 1 and not ie:
        return ControlProblem(eq[0].jacobian, eq[0].reference, lower, upper, repulsive)
    scale = np.concatenate([np.full(r.value.shape[0], math.sqrt(r.weight)) for r in eq])
    jac = np.vstack([r.jacobian for r in eq]) * scale[:, None]
    ref = np.concatenate([r.reference for r in eq]) * scale
    if not ie:
        return ControlProblem(jac, ref, lower, upper, repulsive)
    return ControlProblem(
        jac, ref, lower, upper, repulsive,
        inequality_jacobian=np.vstack([r.jacobian for r in ie]),
        inequality_bound=np.concatenate([r.reference for r in ie]),
        inequality_weights=np.concatenate([np.full(r.value.shape[0], r.weight) for r in ie]),
    )
