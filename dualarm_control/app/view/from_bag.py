"""Adapter: a recorded run (today's bag readers) -> the arrays :func:`.rerun_view.log_run` takes.

Both kinds of bag are read by the one bag reader (``app.record.bag.read_bag``). A relative-pose
bag is cut into controller cycles, one per controller status on ``/diagnostics``; each cycle
takes the joint state, command and target received nearest to its status. A task-scenario bag
gives its :class:`RunRecord` (``app.record.bag_runs.read_run``), already per cycle.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from dualarm_control.app.view import rerun_view as rv
from dualarm_control.app.view.held_view import HeldDrawing, wrist_forces
from dualarm_control.app.view.obstacles_view import (
    ObstacleTrack,
    log_obstacles,
    read_obstacles,
)
from dualarm_control.kinematics import DualArmModel, FloatArray

if TYPE_CHECKING:
    from dualarm_control.app.record.bag import Bag
    from dualarm_control.app.record.run_record import RunRecord
    from dualarm_control.scenario import Scenario


@dataclass
class RunArrays:
    """The arguments of :func:`.rerun_view.log_run` for one run (N cycles)."""

    urdf: Path
    stamps: FloatArray
    q: FloatArray
    joint_names: list[str]
    series: dict[str, FloatArray]
    frames: dict[str, FloatArray] = field(default_factory=dict)
    statuses: list[str] | None = None
    closest: rv.ClosestPairs | None = None
    obstacles: dict[str, ObstacleTrack] = field(default_factory=dict)
    start_ns: int = 0
    """The stamp [ns] of the first cycle (time 0 of :attr:`stamps`): moving obstacles' stamps are on its clock."""
    held: HeldDrawing | None = None

    def log(self, recording: object = None) -> None:
        rv.log_run(self.urdf, self.stamps, self.q, self.joint_names, self.series, frames=self.frames,
                   statuses=self.statuses, recording=recording, closest=self.closest)
        log_obstacles(self.obstacles, self.start_ns, recording, rv.root_link(Path(self.urdf)))
        if self.held is not None:
            self.held.log(self.stamps, recording)


def relative_run_arrays(path: Path, model: DualArmModel, bag: Bag | None = None) -> RunArrays:
    """A relative-pose run's bag, per controller cycle (time: the cycles' joint-state stamps)."""
    from dualarm_control.app.record.bag import (
        COMMANDS_TOPIC,
        TARGET_TOPIC,
        parse_float,
        parse_int,
        read_bag,
    )
    from dualarm_control.app.record.bag_runs import nearest_index

    bag = bag or read_bag(Path(path))
    bag.require_report_topics(path)
    diag_t = np.array([t for t, _ in bag.cycles], dtype=np.int64)
    cycles = [v for _, v in bag.cycles]
    stamps = [parse_int(v.get("stamp_ns")) for v in cycles]
    by_stamp = all(s is not None for s in stamps) and bool(np.all(np.diff(np.array(stamps, dtype=float)) >= 0))
    ns = np.array(stamps, dtype=np.int64) if by_stamp else diag_t
    t = (ns - ns[0]).astype(float) * 1e-9
    commands, targets = bag.series(COMMANDS_TOPIC, model.nq), bag.series(TARGET_TOPIC, 7)
    positions, _ = bag.joint_states(model.joint_names)

    def column(key: str) -> FloatArray:
        return np.array([parse_float(v.get(key)) for v in cycles])

    series = {
        **rv.velocity_norm_series(commands.values[nearest_index(diag_t, commands.t)]),
        rv.TRACKING_POSITION: column("position_error_m"),
        rv.TRACKING_ORIENTATION: column("orientation_error_rad"),
        rv.CYCLE_TIME: column("cycle_time_s"),
    }
    q = positions.values[nearest_index(diag_t, positions.t)]
    return RunArrays(model.urdf, t, q, list(model.joint_names), series,
                     {"relative_target": targets.values[nearest_index(diag_t, targets.t)]},
                     [v.get("status", "") for v in cycles], rv.closest_pairs(model, q), read_obstacles(Path(path)),
                     int(ns[0]))


def record_arrays(record: RunRecord, model: DualArmModel,
                  frames: dict[str, FloatArray] | None = None, collision: Any = None) -> RunArrays:
    """Any run's :class:`RunRecord` (in-process or from a bag): the norms of the commands, tracking
    errors, solve and cycle time, and where there are tasks the task values f_i with their bounds
    b_i and the contact force [N], and a held object's internal wrench (``internal/*``, in F1 [N, N m]). Series
    that are all NaN (not produced by the source) are left out."""
    n = len(record.time)
    series: dict[str, FloatArray] = {
        **rv.velocity_norm_series(record.commands), rv.TRACKING_POSITION: record.position_error,
        rv.TRACKING_ORIENTATION: record.orientation_error, rv.SOLVE_TIME: record.solve_time,
        rv.CYCLE_TIME: record.cycle_time}
    if record.tasks is not None:
        series["force/contact_force_n"] = record.contact_force
        series["force/measured_force_n"] = record.measured_force
        for name, values in record.tasks.values.items():
            values = values.reshape(n, -1)
            bounds = np.broadcast_to(np.asarray(record.tasks.bounds[name], dtype=float).reshape(-1), (values.shape[1],))
            for j in range(values.shape[1]):
                suffix = f"_{j}" if values.shape[1] > 1 else ""
                series[f"task/{name}{suffix}"] = values[:, j]
                series[f"task/{name}{suffix}_bound"] = np.full(n, bounds[j])
    if record.internal_wrench is not None:  # a held object: its internal wrench in F1 [N, N m], per component
        for j, axis in enumerate(("fx_n", "fy_n", "fz_n", "mx_nm", "my_nm", "mz_nm")):
            series[f"internal/{axis}"] = record.internal_wrench[:, j]
    series = {k: np.asarray(v, dtype=float) for k, v in series.items() if not np.all(np.isnan(np.asarray(v, dtype=float)))}
    return RunArrays(model.urdf, record.time - record.time[0], record.positions, list(model.joint_names), series,
                     frames or {}, list(record.status), rv.closest_pairs(model, record.positions, collision))


def held_frames(scenario: Scenario, n: int, record: RunRecord | None = None,
                model: DualArmModel | None = None) -> dict[str, FloatArray]:
    """A held object's centre in the left tool frame, (n, 7) [x y z qx qy qz qw], by its name (drawn as axes);
    {} without one. At its grasp, or, where ``record`` has the simulator's box pose (a carry's bag:
    /held_object/pose), where the box was: on its support before the grasp and after the release."""
    import pinocchio as pin

    out = {}
    for body in scenario.held_bodies:
        quaternion = pin.Quaternion(body.rotation)
        pose = np.array([*body.position, quaternion.x, quaternion.y, quaternion.z, quaternion.w])
        out[body.name] = np.tile(pose, (n, 1))
        if record is not None and model is not None and record.object_pose is not None:
            for k, (q, world) in enumerate(zip(record.positions, record.object_pose, strict=True)):
                if np.all(np.isfinite(world)) and np.all(np.isfinite(q)):
                    out[body.name][k] = _in_left_tool(model, q, world)
    return out


def _in_left_tool(model: DualArmModel, q: FloatArray, world: FloatArray) -> FloatArray:
    """A world pose (x, y, z, qx, qy, qz, qw) in the left tool frame at q (n,) [rad], the same 7 numbers."""
    import pinocchio as pin

    tool = model.frame_poses(q, ("left_tool",))[0]
    x, y, z, w = world[3:]
    placed = tool.actInv(pin.SE3(pin.Quaternion(w, x, y, z).normalized().toRotationMatrix(), world[:3]))
    quaternion = pin.Quaternion(placed.rotation)
    return np.array([*placed.translation, quaternion.x, quaternion.y, quaternion.z, quaternion.w])


def bag_run_arrays(path: Path) -> RunArrays:
    """Either kind of bag the cell records: a task scenario's through the same :class:`RunRecord`
    the report reads, a relative-pose run's per controller cycle."""
    from dualarm_control.app.record.bag import read_bag
    from dualarm_control.app.record.bag_runs import read_run

    bag = read_bag(Path(path))
    if not bag.task_cycles:
        return relative_run_arrays(path, DualArmModel(bag.robot), bag)
    (record,), scenario = read_run(Path(path), bag)
    assert scenario is not None
    model = DualArmModel(scenario.robot)
    if not scenario.held_bodies:
        arrays = record_arrays(record, model)
        arrays.obstacles = read_obstacles(Path(path))  # a task scenario's: its table (no moving ones)
        return arrays
    # a held object: its frame, box and wrist forces, and the closest pairs of the scenario's collision model
    arrays = record_arrays(record, model, held_frames(scenario, len(record.time), record, model),
                           scenario.collision_model(model))
    body = scenario.held_bodies[0]
    stamps = sorted({int(v["stamp_ns"]) for _, v in bag.task_cycles})[-len(record.time):]  # read_run's cycles
    return dataclasses.replace(arrays, held=HeldDrawing(body.name, body.size, wrist_forces(bag.wrists, stamps)),
                               obstacles=read_obstacles(Path(path)))
