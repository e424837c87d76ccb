"""A bag's run: the run records of the in-process runner made from a recorded bag, and the report.

:func:`read_run` turns a :class:`~dualarm_control.app.record.bag.Bag` into
:class:`~dualarm_control.app.record.run_record.RunRecord` s (one per solver of a relative-motion run,
the one of a task run; the module docstring of :mod:`dualarm_control.app.record.bag` says what a task
bag holds); :func:`report` summarises them with the same
:func:`~dualarm_control.app.record.report.summarize_run` as ``dualarm experiment`` and draws the
figures of their kind.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from dualarm_control.app.record.bag import (
    COMMANDS_TOPIC,
    CONTROLLER_STATUS,
    DEFAULT_PERIOD_S,
    DIAGNOSTICS_TOPIC,
    JOINT_STATES_TOPIC,
    PLAN_TOPIC,
    POSE_TOPIC,
    SCENARIO_KEY,
    TARGET_TOPIC,
    Bag,
    BagError,
    IntArray,
    TimedSeries,
    parse_float,
    parse_int,
    read_bag,
)
from dualarm_control.arrays import FloatArray

if TYPE_CHECKING:
    from dualarm_control.app.record.run_record import RunRecord
    from dualarm_control.scenario import Scenario


def read_run(path: Path, bag: Bag | None = None) -> tuple[list[RunRecord], Scenario | None]:
    """The run records of a bag (``bag``: its messages if already read) and, for a task run, its
    scenario: one record per solver of a relative-motion run (:func:`_relative_records`), the one
    record of a task run (:func:`_task_record`); BagError naming what the bag lacks."""
    bag = bag or read_bag(Path(path))
    if bag.task_cycles:
        return _task_record(Path(path), bag)
    bag.require_report_topics(path)
    return _relative_records(bag), None


def _relative_records(bag: Bag) -> list[RunRecord]:
    """One :class:`RunRecord` per solver of the controller's statuses (a bag normally holds one).

    Messages are attributed to the solver of the nearest controller status in receive time.
    The final error is the last /relative_pose against the last /relative_target of the solver.
    """
    from dualarm_control.app.record.run_record import (
        RunRecord,
        absolute_columns,
        nan_column,
    )

    joint_names = bag.robot.joint_names
    n = len(joint_names)
    if not bag.cycles:
        raise BagError(f"{DIAGNOSTICS_TOPIC} has no status named '{CONTROLLER_STATUS}'")
    states, velocities = bag.joint_states(joint_names)
    diag_t = np.array([t for t, _ in bag.cycles], dtype=np.int64)
    solvers = [v.get("solver", "unknown") for _, v in bag.cycles]
    series = {JOINT_STATES_TOPIC: states, COMMANDS_TOPIC: bag.series(COMMANDS_TOPIC, n),
              POSE_TOPIC: bag.series(POSE_TOPIC, 7), TARGET_TOPIC: bag.series(TARGET_TOPIC, 7)}
    labels = {topic: nearest_labels(s.t, diag_t, solvers) for topic, s in series.items()}
    by_state = len(velocities) == len(states.t)
    out = []
    for solver in dict.fromkeys(solvers):
        mine = {topic: labels[topic] == solver for topic in series}
        commands = series[COMMANDS_TOPIC].values[mine[COMMANDS_TOPIC]]
        if commands.shape[0] == 0:
            continue
        cycles = [v for (_, v), s in zip(bag.cycles, solvers, strict=True) if s == solver]

        def column(key: str, cycles: list[dict[str, str]] = cycles) -> FloatArray:
            return np.array([parse_float(v.get(key)) for v in cycles])

        periods = column("control_period_s")
        period = float(np.median(periods[np.isfinite(periods)])) if np.isfinite(periods).any() else DEFAULT_PERIOD_S
        q = states.values[mine[JOINT_STATES_TOPIC]]
        k = commands.shape[0]
        out.append(RunRecord(
            label=solver, kind="segments", period=period,
            time=_time_axis([parse_int(v.get("stamp_ns")) for v in cycles], k, period),
            positions=q[:-1], velocities=velocities[mine[JOINT_STATES_TOPIC]] if by_state else np.zeros((0, n)),
            commands=commands, status=[v.get("status", "") for v in cycles], solve_time=nan_column(k),
            cycle_time=column("cycle_time_s"), position_error=column("position_error_m"),
            orientation_error=column("orientation_error_rad"),
            final_positions=q[-1] if len(q) else nan_column(n), contact_force=nan_column(k),
            measured_force=nan_column(k), normal_offset=nan_column(k), table_contacts=nan_column(k),
            final_errors=pose_error(_last_in(series[POSE_TOPIC], mine[POSE_TOPIC]),
                                    _last_in(series[TARGET_TOPIC], mine[TARGET_TOPIC])),
            absolute_error=absolute_columns(column("absolute_position_error_m"),
                                            column("absolute_orientation_error_rad"))))
    return out


# ===================================================================== summarising a run


def quaternion_angle(q_a: npt.ArrayLike, q_b: npt.ArrayLike) -> float:
    """Rotation angle [rad] between two (x, y, z, w) quaternions, in [0, pi] (robust near 0)."""
    a = np.asarray(q_a, dtype=float)
    b = np.asarray(q_b, dtype=float)
    a, b = a / np.linalg.norm(a), b / np.linalg.norm(b)
    if float(a @ b) < 0.0:
        b = -b
    return float(4.0 * np.arctan2(np.linalg.norm(a - b), np.linalg.norm(a + b)))


def pose_error(pose: npt.ArrayLike, target: npt.ArrayLike) -> tuple[float, float]:
    """(position [m], orientation [rad]) distance of two ``[x, y, z, qx, qy, qz, qw]`` poses."""
    p, q = np.asarray(pose, dtype=float), np.asarray(target, dtype=float)
    return float(np.linalg.norm(p[:3] - q[:3])), quaternion_angle(p[3:], q[3:])


def nearest_index(t: IntArray, ref_t: IntArray) -> IntArray:
    """For each time in ``t``, the index of the nearest time in ``ref_t`` (sorted, non-empty)."""
    right = np.clip(np.searchsorted(ref_t, t), 0, len(ref_t) - 1)
    left = np.clip(right - 1, 0, len(ref_t) - 1)
    return np.where(np.abs(t - ref_t[left]) <= np.abs(ref_t[right] - t), left, right)


def nearest_labels(t: IntArray, ref_t: IntArray, labels: Sequence[str]) -> npt.NDArray[np.str_]:
    """For each time in ``t``, the label of the nearest time in ``ref_t`` (sorted, non-empty)."""
    return np.asarray(labels, dtype=str)[nearest_index(t, ref_t)]


def _last_in(series: TimedSeries, mask: npt.NDArray[np.bool_]) -> FloatArray:
    """The last value selected by ``mask`` (the last overall when the mask selects none)."""
    values = series.values[mask] if mask.any() else series.values
    return values[-1]


def _time_axis(stamps: Sequence[int | None], n: int, period: float) -> FloatArray:
    """Seconds from the diagnostics' joint-state stamps when they match the commands, else k * period."""
    if len(stamps) == n and n > 0 and all(s is not None for s in stamps):
        arr = np.array(stamps, dtype=np.int64)
        return (arr - arr[0]).astype(float) * 1e-9
    return np.arange(n, dtype=float) * period


def _task_record(path: Path, bag: Bag) -> tuple[list[RunRecord], Scenario]:
    """The :class:`RunRecord` of a task-scenario bag (see the module docstring) and its scenario."""
    from dualarm_control.app.record.run_record import (
        RunRecord,
        nan_column,
        with_task_values,
    )
    from dualarm_control.kinematics import DualArmModel
    from dualarm_control.scenario import load_scenario

    by_stamp: dict[int, tuple[int, dict[str, str]]] = {}
    for t, values in bag.task_cycles:
        by_stamp.setdefault(int(values["stamp_ns"]), (t, values))
    first = by_stamp[min(by_stamp)][1]
    joint_states: dict[int, tuple[list[str], Any]] = {}  # by stamp: a re-sent state (lockstep) is the same
    for _, stamp, names, msg in bag.states:
        joint_states.setdefault(stamp, (names, msg.position))
    # A real-time recording starts when the recorder's subscriptions are matched, which can be
    # a few states after the first cycle: cycles before the first recorded state are outside
    # the bag. From that state on, every cycle's state must be in the bag.
    covered_from = min(joint_states, default=min(by_stamp))
    stamps = sorted(s for s in by_stamp if s >= covered_from)
    if not stamps:
        raise BagError(f"bag {path}: no controller task cycle at or after the first recorded {JOINT_STATES_TOPIC}")
    scenario = load_scenario(first[SCENARIO_KEY])
    model = DualArmModel(scenario.robot)
    order: dict[tuple[str, ...], list[int]] = {}
    positions = np.zeros((len(stamps), model.nq))
    for k, stamp in enumerate(stamps):
        if stamp not in joint_states:
            raise BagError(f"bag {path}: no {JOINT_STATES_TOPIC} with the stamp {stamp} of controller cycle {k}")
        names, q = joint_states[stamp]
        idx = order.setdefault(tuple(names), [names.index(j) for j in model.joint_names])
        positions[k] = np.asarray(q, dtype=np.float64)[idx]
    cycles = [by_stamp[s] for s in stamps]
    sent = bag.commands
    received = np.array([t for t, _ in sent], dtype=np.int64)
    nearest = np.clip(np.searchsorted(received, [t for t, _ in cycles]), 0, max(len(received) - 1, 0))
    commands = (np.array([sent[i][1] for i in nearest]) if len(received)
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
    label = f"k={gain:g}" + ((" internal on" if force else " internal off") if "internal_wrench" in first
                             else " force" if force else "")
    record = RunRecord(
        label=label, kind=scenario.reference.kind, period=float(first["control_period_s"]), time=column("task_time_s"),
        positions=positions, velocities=np.full(positions.shape, np.nan), commands=commands,
        status=[v["status"] for _, v in cycles], solve_time=nan_column(n), cycle_time=column("cycle_time_s"),
        position_error=nan_column(n), orientation_error=nan_column(n), final_positions=nan_column(model.nq),
        contact_force=contact, measured_force=column("measured_force_n"), normal_offset=column("normal_offset_m"),
        table_contacts=table, internal_wrench=(np.array([[float(x) for x in v["internal_wrench"].split()]
                                                         for _, v in cycles]) if "internal_wrench" in first else None),
        identified_mass=float(cycles[-1][1].get("identified_mass_kg", "nan")),
        object_pose=(np.array([bag.object_poses.get(s, np.full(7, np.nan)) for s in stamps]) if bag.object_poses
                     else None))
    return [with_task_values(record, scenario, model, gain, force)], scenario


def judged_scenario(bag: Bag) -> Scenario | None:
    """The scenario a relative-motion bag ran, when its run has verdicts (scripted goals, or segments: issue
    40): the controller's ``scenario`` on /diagnostics, on the bag's robot. None for another kind, or when
    the scenario cannot be loaded here (a file of another machine)."""
    from dualarm_control.errors import DualArmError
    from dualarm_control.references.segments import SegmentsSource
    from dualarm_control.scenario import load_scenario

    name = next((v[SCENARIO_KEY] for _, v in bag.cycles if v.get(SCENARIO_KEY)), "")
    if not name or bag.cell.get(CONTROLLER_STATUS, {}).get("plan") or PLAN_TOPIC in bag.recorded:
        return None  # a plan's run tracks its joint trajectory, not the scenario's reference
    try:
        scenario = load_scenario(name, bag.robot)
    except DualArmError:
        return None
    judged = getattr(scenario.reference, "commands", None) or isinstance(scenario.reference, SegmentsSource)
    return scenario if judged else None


def report(path: Path, output: Path) -> tuple[dict[str, dict[str, Any]], str, list[str]]:
    """``dualarm report``: ``output/metrics.json`` ({label: record}, the keys of ``dualarm
    experiment``) and the figures of the run's kind. Returns the records, the kind and the
    figures' file names; BagError when the bag lacks what the report needs.
    """
    from dualarm_control.app.record.figures import write_figures
    from dualarm_control.app.record.report import (
        DEFAULT_ALPHA,
        prepare_output,
        summarize_run,
        write_json,
    )
    from dualarm_control.kinematics import DualArmModel

    bag = read_bag(Path(path))
    runs, scenario = read_run(Path(path), bag)
    if not runs:
        raise BagError(f"bag {path}: no {COMMANDS_TOPIC} message could be attributed to a solver")
    model = DualArmModel(scenario.robot if scenario is not None else bag.robot)  # the run's limits
    if scenario is None:
        scenario = judged_scenario(bag)
    alpha = bag.cell.get(CONTROLLER_STATUS, {}).get("alpha", DEFAULT_ALPHA)  # the run's eq (24) share, if recorded
    results = {r.label: summarize_run(r, scenario, model, float(alpha)) for r in runs}
    prepare_output(Path(output))
    write_json(Path(output) / "metrics.json", results)
    return results, runs[0].kind, write_figures(runs[0].kind, Path(output), Path(path).name, runs, scenario)
