"""In-process lockstep run of any scenario: pybullet cell + the reference source's follower, one loop.

One control period per step: read the joint state (and, when the follower needs it, the F/T
sensor) from the physics, run the follower's cycle at the step's time (relative segments:
sample the ruckig target and solve; tasks: evaluate the tasks and solve the constraint-based
QP), command, step the physics. Deterministic for a given scenario, solver, gain and seed.
The result is one :class:`RunRecord`, whatever the reference source; the bag reader
(:mod:`dualarm_control.app.record.bag`) turns a recorded run into the same record.

Task scenarios (paper 001): without force feedback the brush and the pan do not collide (the
paper's simulation, eq 8); with it (eq 9) they make real pybullet contact, the sensor reading
is noisy and filtered (:class:`~dualarm_control.force.ForceSensorModel`), the pan's modelled
surface is ``force.model_error`` above the real one, and a PI controller sets the circle
task's normal offset. The table is in the cell in both variants.
"""

from __future__ import annotations

import dataclasses
import math
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from dualarm_control.app.run import DEFAULT_SOLVERS
from dualarm_control.controller import ControllerParams
from dualarm_control.errors import DualArmError
from dualarm_control.kinematics import Configuration, DualArmModel, FloatArray
from dualarm_control.references.base import RunOptions
from dualarm_control.scenario import Scenario
from dualarm_control.tasks import CircleTask, evaluate_tasks
from dualarm_sim.cell import CellConfig, DualArmCell


@dataclass(frozen=True)
class TaskValues:
    """The task part of a run record (scenarios with tasks).

    Attributes:
        gain: task gain k [1/s]. force: force variant or not.
        values, bounds: per task name, f (N, m) and b (m,). kinds: per task, its kind.
        tip_in_pan: brush tip in the model's pan frame [m], (N, 3).
        set_point: f_c^0 [N] (NaN without force feedback).
    """

    gain: float
    force: bool
    values: dict[str, FloatArray]
    bounds: dict[str, FloatArray]
    kinds: dict[str, str]
    tip_in_pan: FloatArray
    set_point: float


@dataclass(frozen=True)
class RunRecord:
    """Per-cycle record of one run, in-process or from a bag; arrays have N rows (one per control period).

    Plain arrays per field, so that any reader (report, viewer) takes what it needs. Fields a
    source does not produce hold NaN (relative errors of a task run, forces without force
    feedback, measured velocities and solve times a bag does not carry).

    Attributes:
        label: run name (the solver for relative motion, "k=1 force" for tasks).
        kind: the reference source's kind ("segments", "tasks", "plan").
        period: control period [s].
        time: cycle times since the start [s], (N,).
        positions, velocities: measured joint state at each cycle [rad, rad/s], (N, 14).
        commands: commanded joint velocities [rad/s], (N, 14).
        status: solver status per cycle.
        solve_time, cycle_time: wall times [s], (N,).
        position_error, orientation_error: relative tracking errors vs the cycle's target [m, rad], (N,).
        final_positions: joint positions after the last step [rad], (14,) (NaN when unknown).
        contact_force: pybullet normal force of the contact pair [N], (N,) (0 without contact pair).
        measured_force: filtered sensor f_c [N], (N,) (NaN without force feedback).
        normal_offset: f_F of eq (9) [m], (N,).
        table_contacts: contact points with the table, (N,).
        tasks: task values and bounds where there are tasks, else None.
        final_errors: final relative (position [m], orientation [rad]) error where the recording
            gives it (a bag: its last /relative_pose against its last /relative_target); None:
            the report computes it from ``final_positions`` and the scenario.
    """

    label: str
    kind: str
    period: float
    time: FloatArray
    positions: FloatArray
    velocities: FloatArray
    commands: FloatArray
    status: list[str]
    solve_time: FloatArray
    cycle_time: FloatArray
    position_error: FloatArray
    orientation_error: FloatArray
    final_positions: FloatArray
    contact_force: FloatArray
    measured_force: FloatArray
    normal_offset: FloatArray
    table_contacts: FloatArray
    tasks: TaskValues | None = field(default=None)
    final_errors: tuple[float, float] | None = None


EXIT_INTERRUPTED = 130
SCALARS = ("time", "solve_time", "cycle_time", "position_error", "orientation_error", "contact_force",
           "measured_force", "normal_offset", "table_contacts")


def run_scenario(
    scenario: Scenario,
    params: ControllerParams,
    model: DualArmModel | None = None,
    progress: Callable[[float, str], None] | None = None,
    gain: float | None = None,
    force: bool = False,
    duration: float | None = None,
) -> RunRecord:
    """Run ``scenario`` with ``params`` in lockstep; ``progress(fraction, stage)`` ~ every 1 %.

    ``gain``, ``force`` and ``duration`` are the run options of a task scenario
    (:class:`~dualarm_control.references.base.RunOptions`).
    """
    source = scenario.reference
    model = model or DualArmModel(scenario.robot)
    options = RunOptions(scenario.limits, scenario.settle_time, gain, force, duration)
    period = params.period
    cell_options = source.cell(options)
    pairs: tuple[tuple[str, str], ...] = cell_options.get("contact_pairs", ())
    config = CellConfig.for_robot(scenario.robot, control_period=period, **cell_options)
    with DualArmCell(config, initial_positions=source.initial_positions(scenario.initial_positions)) as cell:
        state = cell.state()
        follower = source.follower(model, params, state.positions, options)
        steps, n = follower.steps, model.nq
        rec = {k: np.zeros((steps, n)) for k in ("positions", "velocities", "commands")}
        scal = {k: np.zeros(steps) for k in SCALARS}
        status: list[str] = []
        every = max(steps // 100, 1)
        for k in range(steps):
            t = k * period
            out = follower.cycle(t, state.positions, cell.wrench() if follower.uses_wrench else None)
            cell.apply_command(out.velocities)
            rec["positions"][k], rec["velocities"][k], rec["commands"][k] = state.positions, state.velocities, out.velocities
            for key, value in (("time", t), ("solve_time", out.result.solve_time), ("cycle_time", out.cycle_time),
                               ("position_error", out.position_error), ("orientation_error", out.orientation_error),
                               ("normal_offset", out.normal_offset), ("measured_force", out.measured_force)):
                scal[key][k] = value
            status.append(out.result.status)
            state = cell.step()
            scal["contact_force"][k] = cell.contact_force(*pairs[0]) if pairs else 0.0
            scal["table_contacts"][k] = cell.table_contacts()
            if progress is not None and (k % every == 0 or k == steps - 1):
                progress((k + 1) / steps, out.stage)
        final_q = state.positions.copy()
    record = RunRecord(label=follower.label, kind=source.kind, period=period, time=scal["time"],
                       positions=rec["positions"], velocities=rec["velocities"], commands=rec["commands"],
                       status=status, solve_time=scal["solve_time"], cycle_time=scal["cycle_time"],
                       position_error=scal["position_error"], orientation_error=scal["orientation_error"],
                       final_positions=final_q, contact_force=scal["contact_force"],
                       measured_force=scal["measured_force"], normal_offset=scal["normal_offset"],
                       table_contacts=scal["table_contacts"])
    return with_task_values(record, scenario, model, gain, force)


def with_task_values(record: RunRecord, scenario: Scenario, model: DualArmModel, gain: float | None,
                     force: bool) -> RunRecord:
    """``record`` with its task values (a scenario with tasks; otherwise unchanged).

    The task values f_i and bounds b_i and the tool path in the pan frame are evaluated here,
    from the measured joint positions and the cycle times (the circle at the cycle's normal
    offset f_F in the force variant): the same values the controller solved with, computed by
    the one piece of code that serves the in-process runner and a recorded bag
    (:mod:`dualarm_control.app.record.bag`).
    """
    spec = scenario.tasks
    if spec is None:
        return record
    k_gain = spec.gain(RunOptions(scenario.limits, scenario.settle_time, gain, force))
    tasks = spec.build_variant(k_gain, force)
    circles = [(i, t) for i, t in enumerate(tasks) if isinstance(t, CircleTask)]
    if not circles:
        raise ValueError(f"scenario {scenario.name!r} has no circle task")
    circle_index, circle = circles[0]
    values: dict[str, list[FloatArray]] = {t.name: [] for t in tasks}
    bounds: dict[str, FloatArray] = {}
    tip = np.zeros((len(record.time), 3))
    for k, (q, t) in enumerate(zip(record.positions, record.time, strict=True)):
        cycle_tasks = tasks
        if force:
            cycle_tasks = list(tasks)
            cycle_tasks[circle_index] = dataclasses.replace(circle, normal_offset=float(record.normal_offset[k]))
        for rows in evaluate_tasks(cycle_tasks, Configuration(model, model.check_q(q)), float(t)):
            values[rows.name].append(rows.value)
            bounds.setdefault(rows.name, rows.bound)
        o1, o2 = model.frame_poses(q, (circle.pan_frame, circle.tool_frame))
        tip[k] = o1.rotation.T @ (o2.translation - o1.translation)
    part = TaskValues(gain=k_gain, force=force, values={name: np.array(v) for name, v in values.items()},
                      bounds=bounds, kinds={t.name: t.kind for t in tasks}, tip_in_pan=tip,
                      set_point=spec.force.set_point if force else float("nan"))
    return dataclasses.replace(record, tasks=part)


def nan_column(n: int) -> FloatArray:
    """(n,) NaN: a field a source or a bag does not give."""
    return np.full(n, math.nan)


def experiment_command(scenario_name: str, solver_names: str | None, params_files: list[str], out: Path,
                       gain_values: str | None, force: bool, duration: float | None, robot: str | None = None) -> int:
    """``dualarm experiment``: one run per solver, or for a task scenario one per gain k (force
    variant with ``force``); write ``out/metrics.json`` and the figures of the scenario's kind,
    print the table. Returns the exit code (130 when interrupted)."""
    from dualarm_control.app.record.report import (
        format_table,
        summarize_run,
        write_figures,
        write_json,
    )
    from dualarm_control.app.run.progress import progress_bar
    from dualarm_control.controller import controller_params
    from dualarm_control.params import read_params_files
    from dualarm_control.robot import robot_defaults
    from dualarm_control.scenario import load_scenario

    scenario = load_scenario(scenario_name, robot)
    spec = scenario.tasks
    base = {**robot_defaults(scenario.robot), **read_params_files(params_files, "controller_node")}
    runs: list[tuple[str, ControllerParams, float | None]]
    if spec is None:
        if gain_values or force or duration:
            raise DualArmError(f"--gains, --force and --duration apply to task scenarios (pan_cleaning), "
                               f"not to {scenario.name!r}")
        solvers = [s.strip() for s in (solver_names or DEFAULT_SOLVERS).split(",") if s.strip()]
        runs = [(name, controller_params({**base, "solver": name}), None) for name in solvers]  # validates all first
        model: DualArmModel | None = DualArmModel(scenario.robot)
        print(f"scenario {scenario.name!r} ({scenario.source}) on robot {scenario.robot.name!r}; solvers: "
              f"{', '.join(solvers)}; output: {out}", file=sys.stderr)
    else:
        solver = solver_names or "constraint_based"
        if "," in solver:
            raise DualArmError("a task scenario runs one solver (constraint_based); got --solver " + solver)
        params = controller_params({**base, "solver": solver})
        try:
            gains = [float(g) for g in gain_values.split(",") if g.strip()] if gain_values else (
                [spec.force.gain] if force else list(spec.gains))
        except ValueError:
            raise DualArmError(f"--gains {gain_values!r}: expected comma-separated numbers > 0") from None
        if not gains or any(not g > 0 for g in gains):
            raise DualArmError(f"--gains {gain_values!r}: expected comma-separated numbers > 0")
        runs = [(f"k={gain:g}" + (" force" if force else ""), params, gain) for gain in gains]
        model = None  # each run builds the model of the scenario's URDF
        print(f"scenario {scenario.name!r} ({scenario.source}); solver {solver}; gains {gains}"
              f"{'; force feedback' if force else ''}; output: {out}", file=sys.stderr)

    results: dict[str, dict[str, Any]] = {}
    logs: list[RunRecord] = []
    try:
        for label, params, gain in runs:
            start = time.perf_counter()
            log = run_scenario(scenario, params, model, progress_bar(label), gain=gain, force=force, duration=duration)
            results[log.label] = summarize_run(log, scenario, model)
            logs.append(log)
            print(f"[{label}] done: {len(log.time)} cycles in {time.perf_counter() - start:.1f} s wall", file=sys.stderr)
    except KeyboardInterrupt:
        print("\ninterrupted: writing what is complete", file=sys.stderr)
        if results:
            write_json(out / "metrics.json", results)
        return EXIT_INTERRUPTED
    write_json(out / "metrics.json", results)
    kind = scenario.reference.kind
    paths = [str(out / f) for f in ("metrics.json", *write_figures(kind, out, scenario.name, logs, scenario))]
    print(format_table(results, kind))
    print(f"\nwrote {' and '.join(paths) if len(paths) == 2 else ', '.join(paths)}")
    return 0
