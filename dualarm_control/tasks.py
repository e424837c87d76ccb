"""Tasks: scalar or vector task functions f(q, t) with bounds, the one mechanism of both papers.

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
from typing import Literal, Protocol

import numpy as np

from dualarm_control.collision import sphere_plane_distances, witness_rows
from dualarm_control.kinematics import (
    Configuration,
    FloatArray,
    jacobian_derivatives,
    luh_components,
    skew,
)
from dualarm_control.solvers.base import ControlProblem

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
    """

    name: str
    kind: Kind
    value: FloatArray
    bound: FloatArray
    jacobian: FloatArray
    time_derivative: FloatArray
    gain: float
    weight: float

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


def _check_gain_weight(name: str, gain: float, weight: float) -> None:
    if not (math.isfinite(gain) and gain > 0):
        raise ValueError(f"task {name!r}: gain must be > 0 [1/s], got {gain}")
    if not (math.isfinite(weight) and weight > 0):
        raise ValueError(f"task {name!r}: slack weight must be > 0, got {weight}")


class RelativeTarget(Protocol):
    """A desired relative pose and twist (x*, xd*) of F2 in F1 (paper 000)."""

    @property
    def position(self) -> FloatArray: ...  # (3,) m

    @property
    def rotation(self) -> FloatArray: ...  # (3, 3)

    @property
    def linear_velocity(self) -> FloatArray: ...  # (3,) m/s

    @property
    def angular_velocity(self) -> FloatArray: ...  # (3,) rad/s


@dataclass(frozen=True)
class RelativePoseTask:
    """Relative pose of F2 in F1 equal to a target, paper 000 eq (8)-(13), 6 equality rows.

    f = -e = [p - p*; -e_o(R, R*)] (Luh error, eq 10), b = 0, df/dq = J (relative Jacobian,
    eq 5), df/dt = -[v*; w*]; the rows are J qd = xd* + K e, eq (13). J is the exact Jacobian
    of the position rows; for the orientation rows it is exact at zero orientation error
    (where Luh's L matrix is the identity), the approximation of paper 000.
    """

    target: RelativeTarget
    gain: float
    weight: float = DEFAULT_EQUALITY_WEIGHT
    name: str = "relative_pose"
    kind: Kind = EQUALITY

    def __post_init__(self) -> None:
        _check_gain_weight(self.name, self.gain, self.weight)

    def evaluate(self, conf: Configuration, t: float) -> TaskRows:
        state = conf.relative()
        target = self.target
        px, py, pz = state.position.tolist()
        tx, ty, tz = np.asarray(target.position, float).tolist()
        ox, oy, oz = luh_components(state.rotation, np.asarray(target.rotation, float))
        value = np.array((px - tx, py - ty, pz - tz, -ox, -oy, -oz))  # f = -e = [p - p*; -e_o]
        time_derivative = np.concatenate((target.linear_velocity, target.angular_velocity))
        np.negative(time_derivative, out=time_derivative)
        return TaskRows(self.name, self.kind, value, np.zeros(6), state.jacobian, time_derivative, self.gain,
                        self.weight)


@dataclass(frozen=True)
class CircleTask:
    """Tool tip on a circle relative to the pan, paper 001 eq (8) (eq (9) with ``normal_offset``).

        f_1-3 = p_1 - p_2 - d(t) - f_F N = p_1 - p_2 + R_1 c(t),   b = 0  (equality, 3 rows)
        c(t) = [D cos(L t), D sin(L t), h - f_F]  in the pan frame,

    i.e. d(t) = -R_1 [D cos Lt, D sin Lt, h] (the circle of radius D in the pan's x-y plane,
    height h above it; the paper's handle terms 2D(z_1 + x_2) are zero here because the
    frames are at the pan centre and the tool tip) and N = z_1, the pan normal; f_F is the
    force controller's output [m] (eq 9; 0 without force feedback). With w_1 the angular
    velocity of the pan frame, d(R_1 c)/dt = w_1 x R_1 c, so (eq 18)

        df/dq = J_p1 - J_p2 - S(R_1 c) J_w1,   df/dt = R_1 c'(t) = R_1 [-D L sin Lt, D L cos Lt, 0].

    Attributes:
        pan_frame, tool_frame: frames 1 (pan centre, z = normal) and 2 (tool tip).
        radius: D [m], >= 0. rate: L [rad/s]. height: h [m]. normal_offset: f_F [m].
    """

    pan_frame: str
    tool_frame: str
    radius: float
    rate: float
    gain: float
    height: float = 0.0
    normal_offset: float = 0.0
    weight: float = DEFAULT_EQUALITY_WEIGHT
    name: str = "circle"
    kind: Kind = EQUALITY

    def __post_init__(self) -> None:
        _check_gain_weight(self.name, self.gain, self.weight)
        if not (math.isfinite(self.radius) and self.radius >= 0):
            raise ValueError(f"task {self.name!r}: radius must be >= 0 [m], got {self.radius}")
        for key in ("rate", "height", "normal_offset"):
            if not math.isfinite(getattr(self, key)):
                raise ValueError(f"task {self.name!r}: {key} must be finite, got {getattr(self, key)}")

    def offset(self, t: float) -> FloatArray:
        """c(t): desired tip position in the pan frame [m], (3,)."""
        a = self.rate * t
        return np.array((self.radius * math.cos(a), self.radius * math.sin(a), self.height - self.normal_offset))

    def evaluate(self, conf: Configuration, t: float) -> TaskRows:
        pan, tool = conf.frame(self.pan_frame), conf.frame(self.tool_frame)
        rc = pan.rotation @ self.offset(t)
        value = pan.position - tool.position + rc
        jac = pan.jacobian[:3] - tool.jacobian[:3] - skew(rc) @ pan.jacobian[3:]
        a = self.rate * t
        dc = np.array((-self.radius * self.rate * math.sin(a), self.radius * self.rate * math.cos(a), 0.0))
        return TaskRows(self.name, self.kind, value, np.zeros(3), jac, pan.rotation @ dc, self.gain, self.weight)


@dataclass(frozen=True)
class ConeTask:
    """Tool axis inside a cone about the reversed pan normal, paper 001 f_4 (1 inequality row).

        f_4 = z_1^T z_2 <= b_4 = -cos(max_angle),

    z_1 the pan normal, z_2 the tool axis (both frames' z): the tool points into the pan
    within ``max_angle`` of -z_1. With z_i' = w_i x z_i,
    df/dq = (z_1 x z_2)^T (J_w1 - J_w2), df/dt = 0.

    Attributes:
        max_angle: cone half-angle [rad], in (0, pi).
    """

    pan_frame: str
    tool_frame: str
    max_angle: float
    gain: float
    weight: float = DEFAULT_INEQUALITY_WEIGHT
    name: str = "cone"
    kind: Kind = INEQUALITY

    def __post_init__(self) -> None:
        _check_gain_weight(self.name, self.gain, self.weight)
        if not 0.0 < self.max_angle < math.pi:
            raise ValueError(f"task {self.name!r}: max_angle must be in (0, pi) [rad], got {self.max_angle}")

    def evaluate(self, conf: Configuration, t: float) -> TaskRows:
        pan, tool = conf.frame(self.pan_frame), conf.frame(self.tool_frame)
        z1, z2 = pan.rotation[:, 2], tool.rotation[:, 2]
        jac = np.cross(z1, z2) @ (pan.jacobian[3:] - tool.jacobian[3:])
        return TaskRows(self.name, self.kind, np.array([z1 @ z2]), np.array([-math.cos(self.max_angle)]),
                        jac[None, :], np.zeros(1), self.gain, self.weight)


def manipulability(jacobian: FloatArray) -> tuple[float, FloatArray]:
    """det(J J^T) and its gradient with respect to the chain's joints (paper 001, eq 10).

    The paper writes det(J^T J) for its 6-joint Puma arms (square J, the same number); for
    a 7-joint arm J^T J (7, 7) has rank 6 and a zero determinant, so the 6x6 J J^T is used
    (Yoshikawa's manipulability squared). With A = J J^T and dJ/dq_k of
    :func:`jacobian_derivatives`: d det A / dq_k = 2 tr(adj(A) dJ_k J^T), adj(A) = det(A) A^-1
    the adjugate, computed from the eigen-decomposition A = U diag(w) U^T as
    U diag(prod_{j != i} w_j) U^T, so that a singular arm (det A = 0) gives a finite gradient.

    Args:
        jacobian: J (6, m) of one arm at its tool frame, world axes.

    Returns:
        (det(J J^T), gradient (m,)).
    """
    a = jacobian @ jacobian.T
    w, u = np.linalg.eigh(a)
    n = w.shape[0]
    others = np.array([np.prod(np.delete(w, i)) for i in range(n)])  # prod_{j != i} w_j
    adj_j = (u * others) @ (u.T @ jacobian)  # adj(A) J, (6, m)
    derivs = jacobian_derivatives(jacobian)  # (m, 6, m)
    # tr(adj(A) dJ_k J^T) = sum_ij (adj(A) J)_ij (dJ_k)_ij  (adj(A) symmetric)
    grad = 2.0 * np.einsum("ij,kij->k", adj_j, derivs)
    return float(np.prod(w)), grad


@dataclass(frozen=True)
class ManipulabilityTask:
    """Singularity margin of one arm, paper 001 eq (10) (1 inequality row).

        f_5i = -1/2 det(J_i J_i^T) <= b_5 < 0,

    J_i (6, 7) the geometric Jacobian of arm i at its tool frame (see :func:`manipulability`),
    df/dq = -1/2 d det / dq on that arm's joints (0 on the other arm), df/dt = 0.

    Attributes:
        frame: the arm's tool frame. side: "left" or "right". bound: b_5 < 0.
    """

    frame: str
    side: str
    bound: float
    gain: float
    weight: float = DEFAULT_INEQUALITY_WEIGHT
    name: str = "singularity"
    kind: Kind = INEQUALITY

    def __post_init__(self) -> None:
        _check_gain_weight(self.name, self.gain, self.weight)
        if not (math.isfinite(self.bound) and self.bound < 0):
            raise ValueError(f"task {self.name!r}: bound b_5 must be < 0, got {self.bound}")

    def evaluate(self, conf: Configuration, t: float) -> TaskRows:
        cols = conf.model.arm_columns(self.side)
        det, grad = manipulability(conf.frame(self.frame).jacobian[:, cols])
        jac = np.zeros((1, conf.model.nq))
        jac[0, cols] = -0.5 * grad
        return TaskRows(self.name, self.kind, np.array([-0.5 * det]), np.array([self.bound]), jac, np.zeros(1),
                        self.gain, self.weight)


UP = np.array([0.0, 0.0, 1.0])
"""The table plane's outward normal (world z)."""


@dataclass(frozen=True)
class TablePlaneTask:
    """Distance of the robot to a horizontal table plane, paper 001 eq (11) (one row per point).

    The robot is represented by spheres (frame origin, radius r_j) as the paper suggests;
    f_6 = -min_j (z_j - r_j - z_table) <= b_6 < 0 is written as one row per sphere,
    f_6j = -(z_j - r_j - z_table) <= b_6 (the same feasible set, each row smooth):
    df_6j/dq = -(J_v,j)_z, df/dt = 0.

    Attributes:
        points: (frame, radius [m]) pairs. table_height: z of the table top in the world [m].
        bound: b_6 < 0: minus the smallest allowed clearance [m].
    """

    points: tuple[tuple[str, float], ...]
    table_height: float
    bound: float
    gain: float
    weight: float = DEFAULT_INEQUALITY_WEIGHT
    name: str = "table"
    kind: Kind = INEQUALITY

    def __post_init__(self) -> None:
        _check_gain_weight(self.name, self.gain, self.weight)
        if not self.points or any(not (math.isfinite(r) and r >= 0) for _, r in self.points):
            raise ValueError(f"task {self.name!r}: points must be (frame, radius >= 0) pairs, got {self.points}")
        if not (math.isfinite(self.bound) and self.bound < 0):
            raise ValueError(f"task {self.name!r}: bound b_6 must be < 0, got {self.bound}")

    def distances(self, conf: Configuration) -> FloatArray:
        """Clearance z_j - r_j - z_table of every sphere [m], (m,)."""
        return self._distances(conf)[0]

    def _distances(self, conf: Configuration) -> tuple[FloatArray, FloatArray]:
        """The spheres' clearances [m] (m,) and their normals from sphere to table (m, 3), from the
        collision limit's distance code (:func:`~dualarm_control.collision.sphere_plane_distances`)."""
        centres = np.array([conf.frame(f).position for f, _ in self.points])
        radii = np.array([r for _, r in self.points])
        d, _, normals = sphere_plane_distances(centres, radii, UP, self.table_height)
        return d, normals

    def evaluate(self, conf: Configuration, t: float) -> TaskRows:
        """f_6j = -d_j, df_6j/dq = -dd_dq: the collision limit's row (:func:`~dualarm_control.collision.witness_rows`)
        of the sphere's lowest point, which moves with the frame: (-n)^T J_v + ((-r up) x (-n))^T J_w =
        (J_v)_z, the second term zero (up and -n are parallel)."""
        d, normals = self._distances(conf)
        jac = np.array([-witness_rows(-normals[j:j + 1], -r * UP[None, :], conf.frame(f).jacobian)[0]
                        for j, (f, r) in enumerate(self.points)])
        m = len(self.points)
        return TaskRows(self.name, self.kind, -d, np.full(m, self.bound), jac, np.zeros(m),
                        self.gain, self.weight)


def evaluate_tasks(tasks: Sequence[Task], conf: Configuration, t: float) -> tuple[TaskRows, ...]:
    """Every task's rows at one configuration and time."""
    return tuple(task.evaluate(conf, t) for task in tasks)


def assemble_problem(rows: Sequence[TaskRows], lower: FloatArray, upper: FloatArray,
                     repulsive: FloatArray) -> ControlProblem:
    """Stack task rows into one :class:`ControlProblem` (paper 001, eq (12)-(14)).

    Equality rows become ``jacobian``/``reference`` (A_e, k_e(b_e - f_e) - h_e), inequality
    rows ``inequality_jacobian``/``inequality_bound``; slack weights per row. A single
    equality task and no inequality gives exactly paper 000's problem (J, xd* + K e).

    Args:
        rows: evaluated tasks, at least one equality.
        lower, upper: joint velocity bounds of eq (23) [rad/s], (n,). repulsive: (n,).
    """
    eq = [r for r in rows if r.kind == EQUALITY]
    ie = [r for r in rows if r.kind == INEQUALITY]
    if not eq:
        raise ValueError("at least one equality task is needed")
    if len(eq) == 1 and not ie:
        return ControlProblem(eq[0].jacobian, eq[0].reference, lower, upper, repulsive)
    jac = np.vstack([r.jacobian for r in eq])
    ref = np.concatenate([r.reference for r in eq])
    w_eq = np.concatenate([np.full(r.value.shape[0], r.weight) for r in eq])
    if not ie:
        return ControlProblem(jac, ref, lower, upper, repulsive, equality_weights=w_eq)
    return ControlProblem(
        jac, ref, lower, upper, repulsive,
        inequality_jacobian=np.vstack([r.jacobian for r in ie]),
        inequality_bound=np.concatenate([r.reference for r in ie]),
        equality_weights=w_eq,
        inequality_weights=np.concatenate([np.full(r.value.shape[0], r.weight) for r in ie]),
    )
