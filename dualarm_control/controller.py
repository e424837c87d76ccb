"""One cycle of closed-loop relative control (paper 000, Fig. 3): state + target -> joint velocities.

Used unchanged by the in-process experiment, the controller node and the benchmark.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from dualarm_control.collision import CollisionModel, CollisionParams
from dualarm_control.errors import ParameterError
from dualarm_control.joint_tracking import TrackingProjection
from dualarm_control.kinematics import (
    Configuration,
    DualArmModel,
    FloatArray,
    rotation_angle,
)
from dualarm_control.limits import (
    DEFAULT_LIMITS,
    CollisionReport,
    JointLimits,
    Limit,
    LimitContext,
    LimitReport,
    RepulsiveField,
    allowed_pairs,
    apply_limits,
    make_limits,
    ordered,
    velocity_bounds,
)
from dualarm_control.plugins import load_plugins
from dualarm_control.qp import make_backend
from dualarm_control.solvers import (
    ACTIVITY_THRESHOLD,
    SolverParams,
    SolverResult,
    make_solver,
)
from dualarm_control.solvers.policy import rest_command
from dualarm_control.status import Status
from dualarm_control.tasks import (
    DEFAULT_EQUALITY_WEIGHT,
    INEQUALITY,
    AbsolutePoseTask,
    RelativeTarget,
    SecondPriority,
    Task,
    TaskRows,
    assemble_problem,
    evaluate_tasks,
    relative_pose_rows,
)


@dataclass(frozen=True)
class ControllerParams:
    """Validated controller parameters (paper 000, Sect. VI defaults).

    Attributes:
        solver: registered solver name.
        gain: K of eq (12)-(13) [1/s], > 0; paper: 10.
        period: control period T of eq (21)-(23) [s], > 0; paper: 0.005.
        alpha: repulsive activation share of eq (24), in [0, 1]; paper: 0.1.
        velocity_scale: factor in (0, 1] on the nominal joint velocity limits.
        acceleration_limit: joint acceleration bound a_max [rad/s^2], one value for every
            joint or one per joint; empty (default) = no bound. When set, each cycle's
            velocity bounds are narrowed to the previous command +- a_max T
            (:func:`dualarm_control.limits.acceleration_bounds`). KUKA publishes no joint
            acceleration limits for the LWR4; ``DEFAULT_ACCELERATION_LIMIT`` is this
            project's documented choice (docs/bench.md).
        solver_params: parameters of the QP solvers.
        collision: the collision limit (:mod:`dualarm_control.limits.collision`): on by default,
            d_i 0.10 m, d_s 0.03 m, xi 0.5 m/s (docs/collision.md gives the reasons).
        limits: registered limits added to the default ones (:data:`~dualarm_control.limits.DEFAULT_LIMITS`),
            by name (docs/limits.md).
        plugins: Python files or modules imported first: a user's own limits and tasks register there.
    """

    solver: str = "hierarchical_sparse_qp"
    gain: float = 10.0
    period: float = 0.005
    alpha: float = 0.1
    velocity_scale: float = 1.0
    acceleration_limit: tuple[float, ...] = ()
    solver_params: SolverParams = field(default_factory=SolverParams)
    collision: CollisionParams = field(default_factory=CollisionParams)
    limits: tuple[str, ...] = ()
    plugins: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        for key in ("gain", "period"):
            value = getattr(self, key)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{key} must be a positive number, got {value}")
        if not 0.0 <= self.alpha <= 1.0:
            raise ValueError(f"alpha must be in [0, 1], got {self.alpha}")
        if not 0.0 < self.velocity_scale <= 1.0:
            raise ValueError(f"velocity_scale must be in (0, 1], got {self.velocity_scale}")
        problem = acceleration_limit_problem(list(self.acceleration_limit))
        if problem:
            raise ValueError(f"acceleration_limit must be {problem}, got {list(self.acceleration_limit)}")


DEFAULT_ACCELERATION_LIMIT = 10.0
"""rad/s^2: the documented acceleration bound (``acceleration_limit: [10.0]``) for every joint.

KUKA gives no joint acceleration limits for the LWR4; 10 rad/s^2 is well below what the
arm reaches (the chatter measured without a bound was 34 rad/s^2) and keeps the assembly
task's tracking and sparsity (docs/bench.md)."""


def acceleration_limit_problem(value: Sequence[float]) -> str:
    """'' when ``value`` is a valid acceleration_limit (empty, or finite values > 0), else what is expected."""
    if all(isinstance(v, (int, float)) and math.isfinite(v) and v > 0 for v in value):
        return ""
    return "an empty list (no bound) or values > 0 [rad/s^2], one for all joints or one per joint"


@dataclass(slots=True)
class Cycle:
    """Result of one control cycle, whatever the reference: a row of the run record.

    A per-cycle record: slotted, not frozen (cheaper to build, docs/bench.md); read-only by
    convention, except that a follower adds what it knows (force, offset, stage).

    Attributes:
        velocities: command [rad/s], (n,), finite and inside the eq (23) bounds.
        result: the solver's record (status, timings, active joints).
        cycle_time: wall time of the whole cycle (kinematics + solve) [s].
        position: measured relative position p_r^1 [m], (3,) (NaN when unknown: tasks, invalid state).
        rotation: measured relative rotation R_r^1, (3, 3) (NaN when unknown).
        position_error: ||p* - p|| [m] (NaN when unknown).
        orientation_error: geodesic angle between R* and R [rad] (NaN when unknown).
        rows: every task evaluated at the cycle's (q, t) (tasks only, else empty).
        measured_force: filtered normal force f_c [N] of paper 001's force loop (NaN without).
        normal_offset: f_F of eq (9) of paper 001 [m] (0 without force feedback).
        stage: what is being followed (segment name, "circle", "execute"), for progress output.
        reports: what each limit saw, by limit name (the limits that had something to say).
        absolute_position_error, absolute_orientation_error: the absolute frame's distance [m] and angle
            [rad] to its target (issue 41: a relative cycle with an absolute target; NaN without).
        internal_wrench: a held object's internal wrench h_I [N, N m] in F1, (6,) (None without a held object).
    """

    velocities: FloatArray
    result: SolverResult
    cycle_time: float
    position: FloatArray = field(default_factory=lambda: np.full(3, np.nan))
    rotation: FloatArray = field(default_factory=lambda: np.full((3, 3), np.nan))
    position_error: float = math.nan
    orientation_error: float = math.nan
    rows: tuple[TaskRows, ...] = ()
    measured_force: float = math.nan
    normal_offset: float = 0.0
    stage: str = ""
    reports: dict[str, LimitReport] = field(default_factory=dict)
    absolute_position_error: float = math.nan
    absolute_orientation_error: float = math.nan
    internal_wrench: FloatArray | None = None

    @property
    def collision(self) -> CollisionReport | None:
        """What the collision limit saw (closest pair, rows), None when it is off."""
        report = self.reports.get("collision")
        return report if isinstance(report, CollisionReport) else None


class RelativeController:
    """Closed-loop task controller: paper 000's relative pose task (xd* + K e) or any set of
    tasks (paper 001), fed to the configured solver.

    It remembers its last command for the optional acceleration bound; ``reset`` forgets it
    (the next cycle then starts from rest, zero velocity).

    The constraints of a cycle are its limits (:class:`~dualarm_control.limits.Limit`), intersected by
    priority whatever their order (:func:`~dualarm_control.limits.apply_limits`): the joint position and
    velocity limits (eq 21-23), the acceleration bound when set, the collision limit when
    ``params.collision.enabled``, and the limits ``params.limits`` names (registered by the package or by a
    file ``params.plugins`` names; docs/limits.md). Every tracker (:meth:`step`, :meth:`solve_tasks`,
    :meth:`track_joints`) solves under all of them. ``collision`` is the robot's collision
    model, when None the model's shared one (:meth:`CollisionModel.shared`: the robot's and the
    parameters' allowed pairs removed); a controller taking over from another
    (:meth:`continue_from`) keeps the old one's when the allowed pairs are the same.
    """

    def __init__(self, model: DualArmModel, params: ControllerParams | None = None,
                 collision: CollisionModel | None = None) -> None:
        self.model = model
        self.params = params or ControllerParams()
        load_plugins(self.params.plugins)
        self.limits = JointLimits(model.q_min, model.q_max, model.qd_max).scaled_velocity(self.params.velocity_scale)
        self.solver = make_solver(self.params.solver, self.params.solver_params)
        n = model.nq
        acc = self.params.acceleration_limit
        if len(acc) not in (0, 1, n):
            raise ValueError(f"acceleration_limit must have 0, 1 or {n} values, got {len(acc)}")
        self._acceleration: FloatArray | None = np.broadcast_to(np.asarray(acc, float), (n,)).copy() if acc else None
        self._previous = np.zeros(n)
        self._zeros = np.zeros(n)
        self._repulsive = RepulsiveField(self.limits, self.params.alpha)
        self.collision_model: CollisionModel | None = None
        if self.params.collision.enabled:
            allowed = allowed_pairs(model, self.params.collision)
            obstacles = self.params.collision.obstacles
            if collision is None or collision.allowed_given != frozenset(frozenset(p) for p in allowed) \
                    or collision.obstacles != obstacles:
                collision = CollisionModel.shared(model, allowed, obstacles)
            self.collision_model = collision
        self.constraints: tuple[Limit, ...] = self._limits()
        self._projection: TrackingProjection | None = None  # a plan's tracking QP (track_joints), made on first use

    def _limits(self) -> tuple[Limit, ...]:
        """The cycle's limits by priority (class docstring); ParameterError naming an unknown limit."""
        context = LimitContext(self.model, self.limits, self.params.period, self._acceleration,
                               self.collision_model, self.params)
        return ordered(make_limits(DEFAULT_LIMITS + self.params.limits, context))

    def limit(self, name: str) -> Limit | None:
        """The controller's limit called ``name`` (e.g. "collision"), None when it has none."""
        return next((limit for limit in self.constraints if limit.name == name), None)

    def reset(self) -> None:
        self.solver.reset()
        self._previous = np.zeros(self.model.nq)
        for limit in self.constraints:
            limit.reset()

    @property
    def previous_command(self) -> FloatArray:
        """The last command [rad/s], (n,): the centre of the next cycle's acceleration bound."""
        return self._previous

    def continue_from(self, old: RelativeController) -> RelativeController:
        """Take over from ``old`` at a cycle boundary (a live parameter change); returns self.

        This controller was built off the cycle with the new parameters; what it takes from
        ``old`` is cheap, so the swap costs the cycle it lands in nothing measurable:

        * the previous command, so that the acceleration bound ``|qd_k - qd_{k-1}| <= a_max T``
          (:func:`~dualarm_control.limits.acceleration_bounds`) holds across the change;
        * with the same solver and solver parameters, ``old``'s solver object itself: its QP
          warm start and the sparse QPs' proximal memory z_prev go on unchanged;
        * with another solver (or other solver parameters), the new solver starts from the
          previous command (:meth:`~dualarm_control.solvers.base.Solver.seed`);
        * each limit, what the limit of its name in ``old`` carries from cycle to cycle
          (:meth:`~dualarm_control.limits.base.Limit.continue_from`: a stall's brake, the live obstacles' feed).

        Raises ValueError when the two controllers do not control the same joints.
        """
        if old.model.nq != self.model.nq:
            raise ValueError(f"continue_from: {old.model.nq} joints, expected {self.model.nq}")
        self._previous = old._previous.copy()
        if self.collision_model is not None and old.collision_model is not None \
                and old.collision_model.allowed == self.collision_model.allowed \
                and old.collision_model.obstacles == self.collision_model.obstacles:
            self.collision_model = old.collision_model
            self.constraints = self._limits()
        before = {limit.name: limit for limit in old.constraints}
        for limit in self.constraints:
            if limit.name in before:
                limit.continue_from(before[limit.name])
        if (old.params.solver, old.params.solver_params) == (self.params.solver, self.params.solver_params):
            self.solver = old.solver
        else:
            self.solver.seed(self._previous)
        return self

    def step(self, q: FloatArray, target: RelativeTarget, absolute: RelativeTarget | None = None,
             grasp: pin.SE3 | None = None, weight: float | None = None) -> Cycle:
        """Compute the joint velocity command for measured positions q (n,) and a target.

        With ``absolute`` (issue 41: a pose and twist of the absolute frame in the world, the halfway frame or,
        with ``grasp``, the object frame fixed to the left tool's grasp) the absolute pose task is the second
        priority, under the relative pose (:mod:`dualarm_control.solvers.priority`), or with ``weight`` weighted
        beside it in one least-squares problem (the relative pose's weight 1).

        Non-finite q or target never reach the solver (its input check rejects the problem
        they make): the safe command is returned with status "invalid_input" and the
        culprit in ``detail`` (see :meth:`_invalid`); so is an unusable absolute target (NaN, or the
        halfway frame at a half turn), named.
        """
        start = time.perf_counter()
        q = self.model.check_q(q)
        conf = Configuration(self.model, q)
        rows = relative_pose_rows(conf, target, self.params.gain)  # RelativePoseTask's rows (gain validated)
        tracked: tuple[TaskRows, ...] = (rows,)
        if absolute is not None:
            try:
                task = absolute_task(absolute, self.params.gain, grasp, weight)
                tracked = (rows, (SecondPriority(task) if weight is None else task).evaluate(conf, 0.0))
            except ValueError as exc:
                return self._invalid(f"absolute target: {exc}", start, q)
        result = self._solve_rows(conf, tracked)
        if result.status == Status.INVALID_INPUT:
            return self._invalid(_culprit(q, target) or result.detail, start, q)
        state = conf.relative()
        ex, ey, ez = rows.value[:3].tolist()  # -e: the position rows are p - p*
        out = Cycle(
            velocities=result.velocities,
            result=result,
            position=state.position,
            rotation=state.rotation,
            position_error=math.sqrt(ex * ex + ey * ey + ez * ez),
            orientation_error=rotation_angle(state.rotation, np.asarray(target.rotation, dtype=float)),
            cycle_time=time.perf_counter() - start,
            reports=self._reports(result.velocities),
        )
        if len(tracked) == 2:
            out.absolute_position_error = float(np.linalg.norm(tracked[1].value[:3]))
            out.absolute_orientation_error = rotation_angle(task.state(conf).rotation, task.rotation)
        return out

    def _reports(self, velocities: FloatArray) -> dict[str, LimitReport]:
        """What each limit saw in the cycle whose command is ``velocities`` [rad/s] (n,), by limit name."""
        out = {}
        for limit in self.constraints:
            report = limit.report(velocities)
            if report is not None:
                out[limit.name] = report
        return out

    def solve_tasks(self, q: FloatArray, tasks: Sequence[Task], t: float) -> Cycle:
        """One cycle on any set of tasks at time t [s] (paper 001, eq (12)-(14)).

        Inequality tasks need a solver that handles inequality rows (``constraint_based``);
        ParameterError (a ValueError) otherwise. Non-finite q gives the safe command (status "invalid_input").
        """
        start = time.perf_counter()
        q = self.model.check_q(q)
        if any(task.kind == INEQUALITY for task in tasks) and not getattr(self.solver, "supports_inequalities", False):
            raise ParameterError("solver", self.solver.name, "a solver that handles inequality tasks: constraint_based")
        if not math.isfinite(q.sum()):
            return self._invalid("non-finite joint positions", start, q)
        conf = Configuration(self.model, q)
        rows = evaluate_tasks(tasks, conf, t)
        result = self._solve_rows(conf, rows)
        return Cycle(result.velocities, result, time.perf_counter() - start, rows=rows,
                     reports=self._reports(result.velocities))

    def _solve_rows(self, conf: Configuration, rows: Sequence[TaskRows]) -> SolverResult:
        """The limits' bounds and rows (class docstring), the problem of the task rows, the solve."""
        q = conf.q
        bounds = apply_limits(self.constraints, conf, self._previous)
        repulsive = self._repulsive(q) if self.solver.uses_repulsive else self._zeros
        problem = assemble_problem(rows, bounds.lower, bounds.upper, repulsive)
        if bounds.rows is not None:
            problem.limit_deferred, problem.limit_bound, problem.limit_labels = bounds.rows, bounds.bound, bounds.labels
        result = self.solver.solve(problem)
        self._previous = result.velocities
        return result

    def track_joints(self, q: FloatArray, q_ref: FloatArray, qd_ref: FloatArray, target: RelativeTarget,
                     gain: float) -> Cycle:
        """Joint-space tracking of a planned trajectory under every limit of the cycle, as the task
        solvers are (issue 39: before, a plan ran inside the eq (23) box alone, with no acceleration bound
        and no collision limit): the command nearest to qd_ref + K (q_ref - q) within the limits
        (:class:`~dualarm_control.joint_tracking.TrackingProjection`). The relative pose error is measured
        against ``target`` (the reference's relative pose) for the report. Non-finite inputs give the
        safe command ("invalid_input")."""
        start = time.perf_counter()
        q = self.model.check_q(q)
        q_ref, qd_ref = self.model.check_q(q_ref, "joint reference"), self.model.check_q(qd_ref, "joint reference")
        if not math.isfinite(q.sum()):
            return self._invalid("non-finite joint positions", start, q)
        if not math.isfinite(q_ref.sum() + qd_ref.sum()):
            return self._invalid("non-finite joint reference", start, q)
        conf = Configuration(self.model, q)
        bounds = apply_limits(self.constraints, conf, self._previous)
        if self._projection is None:
            self._projection = TrackingProjection(make_backend(self.params.solver_params.qp_backend,
                                                               self.params.solver_params.qp))
        velocities, status = self._projection(qd_ref + gain * (q_ref - q), bounds)
        self._previous = velocities
        state = conf.relative()
        p, r = state.position, state.rotation
        p_des, r_des = np.asarray(target.position, dtype=float), np.asarray(target.rotation, dtype=float)
        active = int(np.count_nonzero(np.abs(velocities) > ACTIVITY_THRESHOLD))
        elapsed = time.perf_counter() - start
        result = SolverResult(velocities, status, elapsed, 0, active, float("nan"), "joint tracking")
        return Cycle(velocities=velocities, result=result, position=p, rotation=r,
                     position_error=float(np.linalg.norm(p_des - p)),
                     orientation_error=rotation_angle(r, r_des), cycle_time=elapsed,
                     reports=self._reports(velocities))

    def safe_command(self, q: FloatArray, reason: str) -> Cycle:
        """The safe command at q (n,) [rad] for a reason outside the solver (a wrench limit, a lost sensor): as
        for an invalid input (status "invalid_input"), the reason in the result's ``detail``."""
        return self._invalid(reason, time.perf_counter(), np.asarray(q, float))

    def _invalid(self, what: str, start: float, q: FloatArray) -> Cycle:
        """The safe command for an invalid input, with the reason in ``detail`` (status "invalid_input").

        Zero velocity, or, when q is finite, the command of the eq (23) bounds nearest to rest
        (:func:`rest_command`: zero inside the position range, the way back beyond a limit).
        """
        n = self.model.nq
        velocities = (rest_command(*velocity_bounds(q, self.limits, self.params.period)) if math.isfinite(q.sum())
                      else np.zeros(n))
        self.solver.reset()
        result = SolverResult(velocities, Status.INVALID_INPUT, time.perf_counter() - start, 0,
                              int(np.count_nonzero(np.abs(velocities) > ACTIVITY_THRESHOLD)), float("nan"),
                              what)
        self._previous = velocities
        return Cycle(velocities, result, time.perf_counter() - start)


def absolute_task(target: RelativeTarget, gain: float, grasp: pin.SE3 | None,
                  weight: float | None = None) -> AbsolutePoseTask:
    """The absolute pose task toward ``target`` (pose and twist of the absolute frame, world), gain k
    [1/s], slack weight ``weight`` (None: the default); ValueError naming a non-finite target."""
    values = (target.position, target.rotation, target.linear_velocity, target.angular_velocity)
    if not all(np.all(np.isfinite(np.asarray(v, dtype=float))) for v in values):
        raise ValueError("non-finite absolute target")
    return AbsolutePoseTask(np.asarray(target.position, float), np.asarray(target.rotation, float), gain, grasp,
                            weight=DEFAULT_EQUALITY_WEIGHT if weight is None else weight,
                            linear_velocity=np.asarray(target.linear_velocity, float),
                            angular_velocity=np.asarray(target.angular_velocity, float))


def _culprit(q: FloatArray, target: RelativeTarget) -> str:
    """Which input of :meth:`RelativeController.step` is non-finite ('' when both are finite)."""
    if not math.isfinite(q.sum()):
        return "non-finite joint positions"
    values = (target.position, target.rotation, target.linear_velocity, target.angular_velocity)
    if not all(np.all(np.isfinite(np.asarray(v, dtype=float))) for v in values):
        return "non-finite relative target"
    return ""
