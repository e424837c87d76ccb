"""In-process lockstep run of any scenario: pybullet cell + the reference source's follower, one loop.

One control period per step: read the joint state (and, when the follower needs it, the F/T
sensor) from the physics, run the follower's cycle at the step's time (relative segments:
sample the ruckig target and solve; tasks: evaluate the tasks and solve the constraint-based
QP), command, step the physics. Deterministic for a given scenario, solver, gain and seed.
The result is one :class:`~dualarm_control.app.record.run_record.RunRecord`, whatever the
reference source; the bag reader (:mod:`dualarm_control.app.record.bag`) turns a recorded run into
the same record. The ``dualarm experiment`` verb around it is :mod:`dualarm_control.app.run.command`.

Task scenarios (paper 001): without force feedback the brush and the pan do not collide (the
paper's simulation, eq 8); with it (eq 9) they make real pybullet contact, the sensor reading
is noisy and filtered (:class:`~dualarm_control.force.ForceSensorModel`), the pan's modelled
surface is ``force.model_error`` above the real one, and a PI controller sets the circle
task's normal offset. The table is in the cell in both variants.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np

from dualarm_control.app.record.run_record import (
    RunRecord,
    absolute_columns,
    with_task_values,
)
from dualarm_control.controller import ControllerParams
from dualarm_control.kinematics import DualArmModel
from dualarm_control.moving_feed import MovingFeed
from dualarm_control.references.base import RunOptions
from dualarm_control.scenario import Scenario
from dualarm_sim.cell import DualArmCell
from dualarm_sim.cell_config import CellConfig
from dualarm_sim.moving import MovingBodies

SCALARS = ("time", "solve_time", "cycle_time", "position_error", "orientation_error", "contact_force",
           "measured_force", "normal_offset", "table_contacts", "absolute_position_error", "absolute_orientation_error")


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
    params = scenario.controller_params(params)  # its allowed contacts (the assembly's tools)
    period = params.period
    cell_options = source.cell(options)
    pairs: tuple[tuple[str, str], ...] = cell_options.get("contact_pairs", ())
    config = CellConfig.for_robot(scenario.robot, allowed=scenario.robot_pairs_allowed, control_period=period,
                                  obstacles=scenario.obstacles, **cell_options)
    with DualArmCell(config, initial_positions=source.initial_positions(scenario.initial_positions)) as cell:
        if cell.held_object is not None:  # as sim_node: the grasp clock starts with the first motion command (a
            cell.count_grasp_from_motion()  # carry's first command is zero: its close starts at rest)
        state = cell.state()
        follower = source.follower(model, params, state.positions, options)
        steps, n = follower.steps, model.nq
        rec = {k: np.zeros((steps, n)) for k in ("positions", "velocities", "commands")}
        scal = {k: np.zeros(steps) for k in SCALARS}
        status: list[str] = []
        internal = np.full((steps, 6), np.nan) if cell.held_object is not None else None
        box = np.full((steps, 7), np.nan) if cell.held_object is not None else None
        every = max(steps // 100, 1)
        moving = MovingFeed(scenario.moving_obstacles, follower) if scenario.moving_obstacles else None
        bodies = MovingBodies(scenario.moving_obstacles, cell.client_id)
        for k in range(steps):
            t = k * period
            if moving is not None:  # the hand where it is at t, for the controller and the physics
                moving.publish(t)
                bodies.place(t)
            wrench = None if not follower.uses_wrench else (
                cell.wrist_wrenches().ravel() if cell.held_object is not None else cell.wrench())
            out = follower.cycle(t, state.positions, wrench)
            if box is not None and cell.held_object is not None:  # where the box is at this state (slip)
                box[k] = cell.held_object.pose_vector()
            if moving is not None:
                moving.observe(out.reports.get("live_obstacles"), t)
            cell.apply_command(out.velocities)
            rec["positions"][k], rec["velocities"][k], rec["commands"][k] = state.positions, state.velocities, out.velocities
            for key, value in (("time", t), ("solve_time", out.result.solve_time), ("cycle_time", out.cycle_time),
                               ("position_error", out.position_error), ("orientation_error", out.orientation_error),
                               ("normal_offset", out.normal_offset), ("measured_force", out.measured_force),
                               ("absolute_position_error", out.absolute_position_error),
                               ("absolute_orientation_error", out.absolute_orientation_error)):
                scal[key][k] = value
            status.append(out.result.status)
            if internal is not None and out.internal_wrench is not None:
                internal[k] = out.internal_wrench
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
                       table_contacts=scal["table_contacts"],
                       obstacle_events=moving.finish() if moving is not None else (),
                       absolute_error=absolute_columns(scal["absolute_position_error"],
                                                       scal["absolute_orientation_error"]),
                       internal_wrench=internal, object_pose=box)
    identification = getattr(getattr(follower, "tracker", None), "identification", None)
    if identification is not None:  # a held object: the payload its still step identified
        record = dataclasses.replace(record, identified_mass=identification.mass)
    return with_task_values(record, scenario, model, gain, force)
