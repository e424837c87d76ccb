"""Metrics of a task-scenario bag (pan_cleaning over ROS, paper 001): the same record as the
in-process experiment.

A task run's bag holds ``/joint_states``, ``/velocity_controller/commands``, ``/diagnostics``
(``/wrench``, ``/clock``). The controller's per-cycle status names the scenario, the gain k,
the force variant, and gives the cycle's joint-state stamp, task time, normal offset f_F,
filtered force, solver status and cycle time. The task values f_i and bounds b_i are not
recorded: :func:`~dualarm_control.app.run.experiment.with_task_values` recomputes them from the
joint state of each cycle's stamp and its task time -- the code the in-process runner uses --
and :func:`~dualarm_control.app.record.report.summarize_run` gives the metrics. In
lockstep the joint states, times and offsets are bit-identical to the in-process run, so are
the metrics (except the cycle times, which are wall-clock measurements).

The force variant's bag also holds ``/contact_force`` (pybullet's brush-pan normal force, the
ground truth the force metrics use; cycle k takes the sample stamped after its step, as the
in-process runner measures after ``cell.step()``). Not in the bag: the per-step table
contacts; ``table_contacts`` is the simulator's running total from its last 1 Hz status.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, cast

import numpy as np

from dualarm_control.app.record.bag import (
    COMMANDS_TOPIC,
    CONTROLLER_STATUS,
    DIAGNOSTICS_TOPIC,
    JOINT_STATES_TOPIC,
    BagError,
    open_reader,
)
from dualarm_control.app.run.experiment import RunRecord, nan_column, with_task_values
from dualarm_control.kinematics import DualArmModel, FloatArray
from dualarm_control.ros.convert import stamp_ns
from dualarm_control.scenario import Scenario, load_scenario

TASK_KEY = "task_gain"
"""A controller status with this key is a task cycle (controller_node task mode)."""
SCENARIO_KEY = "scenario"
"""The task scenario's name or path in a task cycle's status."""
SIM_STATUS = "sim_node"
CONTACT_TOPIC = "/contact_force"


@dataclass
class _TaskBag:
    joint_states: dict[int, tuple[list[str], FloatArray]] = field(default_factory=dict)  # by header stamp
    commands: list[tuple[int, FloatArray]] = field(default_factory=list)  # (receive ns, data)
    cycles: list[tuple[int, dict[str, str]]] = field(default_factory=list)  # (receive ns, values)
    table_contacts: int = 0
    contact: dict[int, float] = field(default_factory=dict)  # /contact_force by header stamp


def is_task_bag(path: Path) -> bool:
    """Whether the bag holds controller task cycles (and no relative target)."""
    reader = open_reader(path)
    try:
        if "/relative_target" in reader.topics or DIAGNOSTICS_TOPIC not in reader.topics:
            return False
        connections = [c for c in reader.connections if c.topic == DIAGNOSTICS_TOPIC]
        for conn, _, raw in reader.messages(connections=connections):
            for status in cast(Any, reader.deserialize(raw, conn.msgtype)).status:
                if status.name == CONTROLLER_STATUS and any(kv.key == TASK_KEY for kv in status.values):
                    return True
        return False
    finally:
        reader.close()


def _read(path: Path) -> _TaskBag:
    reader = open_reader(path)
    out = _TaskBag()
    try:
        topics = (JOINT_STATES_TOPIC, COMMANDS_TOPIC, DIAGNOSTICS_TOPIC, CONTACT_TOPIC)
        connections = [c for c in reader.connections if c.topic in topics]
        for conn, t, raw in reader.messages(connections=connections):
            msg: Any = reader.deserialize(raw, conn.msgtype)
            if conn.topic == JOINT_STATES_TOPIC:  # a re-sent state (lockstep) has the same stamp and values
                out.joint_states.setdefault(stamp_ns(msg.header.stamp),
                                            (list(msg.name), np.array(msg.position, dtype=np.float64)))
            elif conn.topic == CONTACT_TOPIC:
                out.contact.setdefault(stamp_ns(msg.header.stamp), float(msg.vector.z))
            elif conn.topic == COMMANDS_TOPIC:
                out.commands.append((t, np.array(msg.data, dtype=np.float64)))
            else:
                for status in msg.status:
                    values = {kv.key: kv.value for kv in status.values}
                    if status.name == CONTROLLER_STATUS and TASK_KEY in values:
                        out.cycles.append((t, values))
                    elif status.name == SIM_STATUS and "table_contacts" in values:
                        out.table_contacts = max(out.table_contacts, int(values["table_contacts"]))
    finally:
        reader.close()
    return out


def read_task_run(path: Path) -> tuple[RunRecord, Scenario]:
    """The :class:`RunRecord` of a task-scenario bag and its scenario; BagError if it is not one."""
    bag = _read(Path(path))
    if not bag.cycles:
        raise BagError(f"bag {path}: no controller task cycles on {DIAGNOSTICS_TOPIC} (key '{TASK_KEY}')")
    by_stamp: dict[int, tuple[int, dict[str, str]]] = {}
    for t, values in bag.cycles:
        by_stamp.setdefault(int(values["stamp_ns"]), (t, values))
    first = by_stamp[min(by_stamp)][1]
    # A real-time recording starts when the recorder's subscriptions are matched, which can be
    # a few states after the first cycle: cycles before the first recorded state are outside
    # the bag. From that state on, every cycle's state must be in the bag.
    covered_from = min(bag.joint_states, default=min(by_stamp))
    stamps = sorted(s for s in by_stamp if s >= covered_from)
    if not stamps:
        raise BagError(f"bag {path}: no controller task cycle at or after the first recorded {JOINT_STATES_TOPIC}")
    scenario = load_scenario(first[SCENARIO_KEY])
    model = DualArmModel(scenario.urdf_path)
    order: dict[tuple[str, ...], list[int]] = {}
    positions = np.zeros((len(stamps), model.nq))
    for k, stamp in enumerate(stamps):
        if stamp not in bag.joint_states:
            raise BagError(f"bag {path}: no {JOINT_STATES_TOPIC} with the stamp {stamp} of controller cycle {k}")
        names, q = bag.joint_states[stamp]
        idx = order.setdefault(tuple(names), [names.index(j) for j in model.joint_names])
        positions[k] = q[idx]
    cycles = [by_stamp[s] for s in stamps]
    received = np.array([t for t, _ in bag.commands], dtype=np.int64)
    nearest = np.clip(np.searchsorted(received, [t for t, _ in cycles]), 0, max(len(received) - 1, 0))
    commands = (np.array([bag.commands[i][1] for i in nearest]) if len(received)
                else np.full((len(stamps), model.nq), np.nan))

    def column(key: str) -> FloatArray:
        return np.array([float(v[key]) for _, v in cycles])

    table = np.zeros(len(stamps))
    table[-1] = bag.table_contacts
    contact = np.full(len(stamps), np.nan)
    if bag.contact:  # cycle k's contact is the one after its step: the first sample stamped after it
        contact_stamps = np.array(sorted(bag.contact), dtype=np.int64)
        after = np.searchsorted(contact_stamps, np.array(stamps, dtype=np.int64), side="right")
        for k, i in enumerate(after):
            if i < len(contact_stamps):
                contact[k] = bag.contact[int(contact_stamps[i])]
    n, gain, force = len(stamps), float(first["task_gain"]), first["force"] == "1"
    label = f"k={gain:g}" + (" force" if force else "")
    record = RunRecord(
        label=label, kind=scenario.reference.kind, period=float(first["control_period_s"]), time=column("task_time_s"),
        positions=positions, velocities=np.full(positions.shape, np.nan), commands=commands,
        status=[v["status"] for _, v in cycles], solve_time=nan_column(n), cycle_time=column("cycle_time_s"),
        position_error=nan_column(n), orientation_error=nan_column(n), final_positions=nan_column(model.nq),
        contact_force=contact, measured_force=column("measured_force_n"), normal_offset=column("normal_offset_m"),
        table_contacts=table)
    return with_task_values(record, scenario, model, gain, force), scenario


def task_report(path: Path, output: Path) -> dict[str, dict[str, Any]]:
    """``dualarm report`` on a task bag: ``output/metrics.json`` ({label: record}, the keys of
    ``dualarm experiment pan_cleaning``), the tool path, task values and joint velocity plots."""
    from dualarm_control.app.record.report import (
        plot_joint_velocities,
        plot_task_values,
        plot_tool_paths,
        summarize_run,
        write_metrics,
    )
    from dualarm_control.tasks import CircleTask

    log, scenario = read_task_run(path)
    results = {log.label: summarize_run(log, scenario, DualArmModel(scenario.urdf_path))}
    output = Path(output)
    write_metrics(output / "metrics.json", results)
    assert scenario.tasks is not None
    circle = next(t for t in scenario.tasks.build(1.0) if isinstance(t, CircleTask))
    plot_tool_paths([log], circle.radius, output / "tool_path.png")
    plot_task_values([log], output / "task_values.png")
    plot_joint_velocities(log, output / "joint_velocities.png")
    return results
