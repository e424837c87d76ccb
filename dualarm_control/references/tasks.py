"""Reference source of paper 001: a set of tasks with gains and bounds instead of relative segments.

Keys under ``scenario.`` (flattened, see :mod:`dualarm_control.scenario`):
  ``duration`` [s]; ``table_height`` [m, world z of the table top; or the top of the obstacle named
  ``table``, :func:`~dualarm_control.obstacles.table_top`: one definition of the plane for f6 and the cell;
  neither: no table];
  ``convergence_time`` [s] (metrics after it); ``gains`` (k values to compare, 1/s);
  ``tasks`` (ordered names) and per task ``<task>.type``:

  * ``circle`` (eq 8/9): ``pan_frame``, ``tool_frame``, ``radius`` [m], ``period`` [s]
    (L = 2 pi / period), ``height`` [m] (tip above the pan surface);
  * ``cone`` (f_4): ``pan_frame``, ``tool_frame``, ``max_angle_deg``;
  * ``singularity`` (eq 10): ``frame``, ``side`` (left|right), ``bound`` (b_5 < 0);
  * ``table`` (eq 11): ``frames`` and ``radii`` [m] (spheres), ``bound`` (b_6 < 0, m);

  any type a plugin registers (``plugins``: Python files, relative to the scenario file, or module
  names; docs/limits.md); optional ``<task>.weight`` (slack weight). ``force.*`` configures the force variant
  (eq 9), see :class:`~dualarm_control.force.ForceParams`; ``contact_links`` (two link
  names) are the links that touch in the force variant (pan and brush).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from dualarm_control.controller import ControllerParams, Cycle, RelativeController
from dualarm_control.errors import ScenarioError
from dualarm_control.force import (
    ForceParams,
    ForcePI,
    ForceSensorModel,
    contact_normal_force,
)
from dualarm_control.kinematics import Configuration, DualArmModel, FloatArray
from dualarm_control.obstacles import parse_obstacles, table_top
from dualarm_control.plugins import load_plugins
from dualarm_control.references.base import (
    RunOptions,
    SourceDefaults,
    StreamSample,
    cycle_count,
)
from dualarm_control.references.held import HeldSetup, HoldController, parse_held
from dualarm_control.scenario_keys import PREFIX, get, number
from dualarm_control.tasks import (
    CircleTask,
    Task,
    TaskContext,
    TaskSpec,
    build_task,
    check_task_type,
)


@dataclass(frozen=True)
class TasksSource(SourceDefaults):
    """Tasks (paper 001): a :class:`~dualarm_control.references.base.ReferenceSource`.

    No stream besides /joint_states; the force variant (a run option) adds /wrench.

    Attributes:
        duration: run time [s]. table_height: table top, world z [m] (None: no table in the cell).
        convergence_time: time after which tracking metrics are taken [s].
        gains: the k values [1/s] the experiment compares by default.
        tasks: task specs in order. force: the force variant's parameters.
        contact_links: the two links that make contact in the force variant.
        table_obstacle: the table is the scenario's obstacle ``table`` (its top is ``table_height``):
            the cell has it as an obstacle body, not as :class:`~dualarm_sim.cell.CellConfig`'s table.
        held: an object held by both hands and its internal-force control (:mod:`.held`; the run option
            ``force`` switches the control on), or None.
    """

    duration: float
    table_height: float | None
    convergence_time: float
    gains: tuple[float, ...]
    tasks: tuple[TaskSpec, ...]
    force: ForceParams
    contact_links: tuple[str, str] = ("left_flange", "right_tool")
    table_obstacle: bool = False
    held: HeldSetup | None = None
    kind: ClassVar[str] = "tasks"
    streams: ClassVar[tuple[str, ...]] = ()

    def describe(self) -> str:
        return f"{len(self.tasks)} tasks"

    def gain(self, options: RunOptions) -> float:
        """The run's task gain k [1/s]: the option's, else force.gain (force variant) or the first of ``gains``."""
        return options.gain if options.gain is not None else (self.force.gain if options.force else self.gains[0])

    @property
    def cell_table(self) -> float | None:
        """The cell's own table top [m] (:class:`~dualarm_sim.cell.CellConfig`'s ``table_height``), None when
        the table is an obstacle of the scenario (the cell gets it with the obstacles)."""
        return None if self.table_obstacle else self.table_height

    def cell(self, options: RunOptions) -> dict[str, Any]:
        if self.held is not None:
            return {"table_height": self.cell_table, **self.held.cell()}
        return {"table_height": self.cell_table, "contact_pairs": (self.contact_links,) if options.force else ()}

    def tracker(self, model: DualArmModel, params: ControllerParams, options: RunOptions) -> Any:
        duration = options.duration if options.duration is not None else self.duration
        if self.held is not None:
            base = TasksController(model, params, self, self.gain(options), False, duration)
            return HoldController(base, self.held.control, options.force, self.held.phases, options.limits)
        return TasksController(model, params, self, self.gain(options), options.force, duration)

    def stream(self, model: DualArmModel, q0: FloatArray, options: RunOptions, period: float) -> Any:
        """No target stream: the controller node evaluates the tasks itself (ScenarioError)."""
        raise ScenarioError("a task scenario has no target stream: the controller node runs its tasks "
                            "(no trajectory node)")

    def build(self, gain: float, height_offset: float = 0.0) -> list[Task]:
        """Task objects with gain k for every task; ``height_offset`` [m] is added to the circle
        height (a modelling error of the pan along its normal: the model's pan surface is
        that far above the real one)."""
        context = TaskContext(gain, self.table_height, height_offset)
        return [build_task(spec, context) for spec in self.tasks]

    def build_variant(self, gain: float, force: bool) -> list[Task]:
        """The tasks a run uses: with ``force`` the circle includes the pan modelling error
        (``force.model_error``) that the force loop has to absorb."""
        return self.build(gain, height_offset=self.force.model_error if force else 0.0)


def _check_frames(model: DualArmModel, tasks: list[Task]) -> None:
    """Evaluate every task once at q = 0 so that a frame missing from the URDF is reported
    now, naming the task (ScenarioError), not at the first control cycle."""
    conf = Configuration(model, np.zeros(model.nq))
    for task in tasks:
        try:
            task.evaluate(conf, 0.0)
        except KeyError as exc:
            raise ScenarioError(f"scenario task {task.name!r}: {exc.args[0]}") from None


class TasksController:
    """The tasks of a task scenario at gain k and, with ``force``, the force loop of eq (9):
    F/T reading -> noise and low-pass (:class:`ForceSensorModel`, the simulated sensor chain)
    -> f_c = N^T F (N and R_2 from the controller's own kinematics) -> PI -> circle offset.

    With ``force`` the circle's height includes the scenario's pan modelling error
    (``force.model_error``), which the force loop has to absorb.
    """

    def __init__(self, model: DualArmModel, params: ControllerParams, spec: TasksSource, gain: float,
                 force: bool = False, duration: float | None = None) -> None:
        self.model = model
        self.gain = gain
        self.label = f"k={gain:g}" + (" force" if force else "")
        self.uses_wrench = force
        self.steps: int | None = cycle_count(duration if duration is not None else spec.duration, params.period)
        self.spec = spec
        self.force = force
        self.period = params.period
        self.controller = RelativeController(model, params)
        self.tasks: list[Task] = spec.build_variant(gain, force)
        _check_frames(model, self.tasks)
        circles = [(i, t) for i, t in enumerate(self.tasks) if isinstance(t, CircleTask)]
        if force and len(circles) != 1:
            raise ValueError(f"the force variant needs exactly one circle task, the scenario has {len(circles)}")
        self.circle: CircleTask | None = circles[0][1] if circles else None  # as built (normal offset 0)
        self._circle_index = circles[0][0] if circles else -1
        self.reset()

    def circle_error(self, cycle: Cycle) -> float:
        """|value| of the circle task in a cycle of this controller [m] (NaN without a circle task)."""
        rows = next((r for r in cycle.rows if self.circle is not None and r.name == self.circle.name), None)
        return float(np.linalg.norm(rows.value)) if rows is not None else math.nan

    def reset(self) -> None:
        """Forget the solver's warm start, the filter state and the force integral."""
        self.controller.reset()
        self._sensor = ForceSensorModel(self.spec.force, self.period)
        self._pi = ForcePI(self.spec.force)
        self._offset = 0.0

    def track(self, q: FloatArray, sample: StreamSample | None, t: float, wrench: FloatArray | None) -> Cycle:
        """:meth:`step` as a :class:`~dualarm_control.references.base.Tracker` (tasks have no stream)."""
        return self.step(q, t, wrench)

    def report(self, cycle: Cycle, t: float) -> dict[str, Any]:
        """The task cycle's /diagnostics values at full precision (``dualarm report`` recomputes
        the task values from t, the normal offset and the filtered force)."""
        return {"cycle_time_s": repr(cycle.cycle_time), "task_gain": repr(self.gain), "force": int(self.force),
                "task_time_s": repr(t), "normal_offset_m": repr(cycle.normal_offset),
                "measured_force_n": repr(cycle.measured_force), "circle_error_m": f"{self.circle_error(cycle):.6e}"}

    def step(self, q: FloatArray, t: float, wrench: FloatArray | None = None) -> Cycle:
        """One cycle at joint positions q (n,) [rad] and task time t [s]; the cycle's rows, the
        filtered normal force f_c [N] the PI used (NaN without force feedback or when the reading
        was not finite) and the offset f_F [m] in the circle task.

        Args:
            wrench: force variant only: raw sensor reading [N, N m] (6,) in the tool frame
                (the wrench the flange exerts on the tool). A non-finite reading keeps the
                previous offset (the force loop holds) and gives measured_force NaN.
        """
        measured = math.nan
        tasks = self.tasks
        if self.force:
            if wrench is None:
                raise ValueError("the force variant needs the F/T reading every cycle")
            wrench = np.asarray(wrench, dtype=float)
            q = self.model.check_q(q)
            circle = self.circle
            assert circle is not None
            if wrench.shape == (6,) and math.isfinite(wrench.sum()) and math.isfinite(q.sum()):
                pan, tool = self.model.frame_poses(q, (circle.pan_frame, circle.tool_frame))
                measured = contact_normal_force(self._sensor.filter(wrench), tool.rotation, pan.rotation[:, 2],
                                                self.spec.force.tool_mass)
                self._offset = self._pi.step(measured, self.period)
            tasks = list(self.tasks)
            tasks[self._circle_index] = dataclasses.replace(circle, normal_offset=self._offset)
        out = self.controller.solve_tasks(q, tasks, t)
        out.measured_force, out.normal_offset, out.stage = measured, self._offset, "circle" if self.circle else "tasks"
        return out


def _table_height(flat: Mapping[str, Any], base: Path | None) -> tuple[float | None, bool]:
    """The table plane's height [m] and whether it is the top of the obstacle ``table``: that top, or
    ``scenario.table_height`` (both given: they must agree to 1e-9 m; ScenarioError otherwise); None: neither
    (no table)."""
    top = table_top(parse_obstacles(flat, base or Path.cwd()))
    if top is None:
        return (number(flat, "table_height") if PREFIX + "table_height" in flat else None), False
    if PREFIX + "table_height" in flat and abs(number(flat, "table_height") - top) > 1e-9:
        raise ScenarioError(f"scenario parameter '{PREFIX}table_height': got {flat[PREFIX + 'table_height']!r}, "
                            f"but the obstacle 'table' has its top at {top!r} m (give one of them)")
    return top, True


def parse_tasks(flat: Mapping[str, Any], base: Path | None = None) -> TasksSource:
    """Read the task keys (module docstring) from flattened parameters; ScenarioError on a bad value.

    ``scenario.plugins`` (Python files or module names, :func:`~dualarm_control.plugins.load_plugins`) are
    imported first, so that the task types they register are known; a relative file path is taken from
    ``base`` (the scenario file's directory) when given."""

    names = get(flat, "tasks")
    if not isinstance(names, list) or not names or not all(isinstance(n, str) for n in names):
        raise ScenarioError(f"scenario parameter '{PREFIX}tasks': got {names!r}, expected a list of task names")
    plugins = get(flat, "plugins", [""])
    if not isinstance(plugins, list) or not all(isinstance(p, str) for p in plugins):
        raise ScenarioError(f"scenario parameter '{PREFIX}plugins': got {plugins!r}, expected a list of Python "
                            "files or module names")
    if base is not None:
        plugins = [str(base / p) if p.endswith(".py") and not Path(p).is_absolute() else p for p in plugins]
    try:
        load_plugins(plugins, PREFIX + "plugins")
    except ValueError as exc:
        raise ScenarioError(str(exc)) from None
    specs = []
    for name in names:
        sub = PREFIX + name + "."
        values = {k: v for k, v in flat.items() if k.startswith(sub)}
        spec = TaskSpec(name, str(values.get(sub + "type")), values)
        check_task_type(spec)
        specs.append(spec)
    gains = get(flat, "gains", [1.0])
    if not isinstance(gains, list) or not gains or not all(
            isinstance(g, int | float) and not isinstance(g, bool) and g > 0 for g in gains):
        raise ScenarioError(f"scenario parameter '{PREFIX}gains': got {gains!r}, expected numbers > 0")
    force_keys = {f.name for f in fields(ForceParams)}
    force_values = {k[len(PREFIX) + 6:]: v for k, v in flat.items() if k.startswith(PREFIX + "force.")}
    unknown = sorted(set(force_values) - force_keys)
    if unknown:
        raise ScenarioError(f"scenario force parameters: unknown {', '.join(unknown)}; valid: "
                            f"{', '.join(sorted(force_keys))}")
    try:
        force = ForceParams(**force_values)
    except (TypeError, ValueError) as exc:
        raise ScenarioError(f"scenario force parameters: {exc}") from None
    links = get(flat, "contact_links", ["left_flange", "right_tool"])
    if not isinstance(links, list) or len(links) != 2 or not all(isinstance(n, str) for n in links):
        raise ScenarioError(f"scenario parameter '{PREFIX}contact_links': got {links!r}, expected two link names")
    table, from_obstacle = _table_height(flat, base)
    out = TasksSource(duration=number(flat, "duration"), table_height=table, table_obstacle=from_obstacle,
                      convergence_time=number(flat, "convergence_time", 5.0), gains=tuple(float(g) for g in gains),
                      tasks=tuple(specs), force=force, contact_links=(links[0], links[1]), held=parse_held(flat))
    if out.duration <= out.convergence_time:
        raise ScenarioError(f"scenario parameter '{PREFIX}duration' must exceed convergence_time "
                            f"({out.convergence_time} s), got {out.duration}")
    for gain in out.gains:
        out.build(gain)  # validate every task now, with the message naming it
    return out
