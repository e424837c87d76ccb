"""In-process lockstep run of a scenario: pybullet cell + controller + ruckig targets.

One control period per step: read joint states from the physics, sample the target at the
step's time, solve, command, step the physics. Deterministic for a given scenario/solver.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from dualarm_control.controller import ControllerParams, RelativeController
from dualarm_control.kinematics import DualArmModel, FloatArray
from dualarm_control.scenario import Scenario
from dualarm_sim.cell import CellConfig, DualArmCell


@dataclass(frozen=True)
class RunLog:
    """Per-cycle record of a run; arrays have N rows (one per control period).

    Attributes:
        solver: solver name.
        period: control period [s].
        time: cycle start times [s], (N,).
        positions, velocities: measured joint state at each cycle [rad, rad/s], (N, 14).
        commands: commanded joint velocities [rad/s], (N, 14).
        status: solver status per cycle.
        solve_time, cycle_time: wall times [s], (N,).
        position_error, orientation_error: tracking errors vs the current target [m, rad], (N,).
        final_positions: joint positions after the last step [rad], (14,).
    """

    solver: str
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


def run_scenario(
    scenario: Scenario,
    params: ControllerParams,
    model: DualArmModel | None = None,
    progress: Callable[[float, str], None] | None = None,
) -> RunLog:
    """Run ``scenario`` with ``params`` in lockstep; ``progress(fraction, segment)`` ~ every 1 %."""
    model = model or DualArmModel()
    controller = RelativeController(model, params)
    period = params.period
    with DualArmCell(CellConfig(control_period=period), initial_positions=scenario.initial_positions) as cell:
        state = cell.state()
        trajectory = scenario.trajectory(*model.relative_pose(state.positions))
        steps = math.ceil((trajectory.duration + scenario.settle_time) / period)
        n = model.nq
        rec = {k: np.zeros((steps, n)) for k in ("positions", "velocities", "commands")}
        scal = {k: np.zeros(steps) for k in ("time", "solve_time", "cycle_time", "position_error", "orientation_error")}
        status: list[str] = []
        every = max(steps // 100, 1)
        for k in range(steps):
            t = k * period
            target = trajectory.sample(t)
            out = controller.step(state.positions, target)
            cell.apply_command(out.velocities)
            rec["positions"][k], rec["velocities"][k], rec["commands"][k] = state.positions, state.velocities, out.velocities
            for key, value in (("time", t), ("solve_time", out.result.solve_time), ("cycle_time", out.cycle_time),
                               ("position_error", out.position_error), ("orientation_error", out.orientation_error)):
                scal[key][k] = value
            status.append(out.result.status)
            if progress is not None and (k % every == 0 or k == steps - 1):
                progress((k + 1) / steps, target.segment_name)
            state = cell.step()
        final_q = state.positions.copy()
    return RunLog(solver=params.solver, period=period, status=status, final_positions=final_q, **rec, **scal)


def final_errors(log: RunLog, scenario: Scenario, model: DualArmModel) -> tuple[float, float]:
    """Relative position [m] and orientation [rad] error of the final state vs the scenario's end pose."""
    from dualarm_control.kinematics import rotation_angle

    start = model.relative_pose(log.positions[0])
    trajectory = scenario.trajectory(*start)
    end = trajectory.sample(trajectory.duration)
    p, r = model.relative_pose(log.final_positions)
    return float(np.linalg.norm(p - end.position)), rotation_angle(r, end.rotation)


def summarize_log(log: RunLog, scenario: Scenario, model: DualArmModel) -> dict[str, float | int]:
    """The metrics.json record of an in-process run (see :func:`dualarm_control.app.record.report.summarize`)."""
    from dualarm_control.app.record.report import summarize

    return summarize(
        commands=log.commands,
        positions=np.vstack((log.positions, log.final_positions)),
        velocities=log.velocities,
        period=log.period,
        statuses=log.status,
        cycle_times=log.cycle_time,
        final_errors=final_errors(log, scenario, model),
        q_limits=(model.q_min, model.q_max),
        qd_max=model.qd_max,
        tracking_errors=(log.position_error, log.orientation_error),
    )
