"""A task scenario holding one object with two hands (issue 41, items 2-3): the held object and wrist sensors of
the cell, and the tracker that regulates the internal wrench.

Scenario keys (under ``scenario.``, besides the tasks' keys, :mod:`dualarm_control.references.tasks`):

* ``held_object.*``: the simulated box (:class:`~dualarm_sim.held_object.HeldObjectConfig`: ``mass`` [kg],
  ``size`` [m], ``grasp_position`` [m] / ``grasp_rpy_deg`` (the box centre in the left tool frame),
  ``max_force`` [N], ``grasp_time`` [s]);
* ``wrist_sensors.*``: their bias and noise (:class:`~dualarm_sim.held_object.WristSensorConfig`);
* ``internal_force.*``: the control (:class:`~dualarm_control.internal_force.InternalForceParams`; its
  ``grasp_time`` is ``held_object.grasp_time``);
* ``absolute_segments`` and ``phases.*``: a carry (:mod:`~dualarm_control.references.carry`: close on the box, carry
  it along a path of the absolute frame, set it down and let go); its payload step is then the still step before
  the release (the box rests on its support until the lift).

The tracker (:class:`HoldController`) reads both wrist sensors every cycle ((12,): left then right, each as
:mod:`dualarm_sim.held_object` gives it), identifies the bias and payload in the still steps, computes the
internal wrench (each hand's moment about its own grasp point) in F1, and, with internal-force
control on (the run option ``force``: ``dualarm experiment --force``), moves the held relative pose's target by
the admittance's offset. Until the identification is over the absolute tasks hold the start pose. A hand's
force beyond ``wrench_limit`` stops the motion (the safe command, latched, the reason in the cycle's detail).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from dualarm_control.controller import Cycle, RelativeController
from dualarm_control.cooperative_wrench import hand_wrenches, in_frame, internal_wrench
from dualarm_control.errors import ScenarioError
from dualarm_control.internal_force import (
    InternalForceParams,
    RelativeAdmittance,
    WrenchIdentification,
    blend_pose,
    offset_target,
    ramp_fraction,
)
from dualarm_control.kinematics import Configuration, FloatArray
from dualarm_control.references.base import LEFT_WRENCH, RIGHT_WRENCH, StreamSample
from dualarm_control.references.carry import (
    CarryPhases,
    CarryPlan,
    parse_phases,
    path_of,
)
from dualarm_control.scenario_keys import PREFIX
from dualarm_control.tasks import AbsolutePoseTask, FixedTarget, RelativePoseTask, Task
from dualarm_control.trajectory import MotionLimits

HELD_KEYS = ("held_object", "wrist_sensors", "internal_force")


def _section(flat: Mapping[str, Any], name: str, valid: set[str]) -> dict[str, Any]:
    """``scenario.<name>.*`` as keyword arguments (lists as tuples); ScenarioError naming an unknown key."""
    prefix = f"{PREFIX}{name}."
    values = {k[len(prefix):]: tuple(v) if isinstance(v, list) else v for k, v in flat.items() if k.startswith(prefix)}
    unknown = sorted(set(values) - valid)
    if unknown:
        raise ScenarioError(f"scenario {name} parameters: unknown {', '.join(unknown)}; valid: {', '.join(sorted(valid))}")
    return values


@dataclass(frozen=True)
class HeldSetup:
    """A scenario's held object (as keyword values for the simulator) and its internal-force control."""

    held_object: dict[str, Any]
    wrist_sensors: dict[str, Any]
    control: InternalForceParams
    phases: CarryPhases | None = None
    """A carry's phases (close, path, release: :mod:`~dualarm_control.references.carry`), or None (held from the
    start to the end)."""

    @property
    def release_time(self) -> float:
        """When the hands open [s] (inf: never)."""
        return float(self.held_object.get("release_time", math.inf))

    def cell(self) -> dict[str, Any]:
        """The simulator's settings (:class:`~dualarm_sim.cell.CellConfig` fields)."""
        from dualarm_sim.held_object import HeldObjectConfig, WristSensorConfig

        return {"held_object": HeldObjectConfig(**self.held_object),
                "wrist_sensors": WristSensorConfig(**self.wrist_sensors)}


def parse_held(flat: Mapping[str, Any]) -> HeldSetup | None:
    """The ``held_object``, ``wrist_sensors`` and ``internal_force`` keys (module docstring); None without a
    held object; ScenarioError naming the section and the bad value."""
    if not any(k.startswith(f"{PREFIX}{name}.") for k in flat for name in HELD_KEYS):
        if PREFIX + "absolute_segments" in flat:
            raise ScenarioError(f"scenario parameter '{PREFIX}absolute_segments' in a task scenario: a carry's path, "
                                f"it needs the object, '{PREFIX}held_object.*'")
        return None
    from dualarm_sim.held_object import HeldObjectConfig, WristSensorConfig

    held = _section(flat, "held_object", {f.name for f in fields(HeldObjectConfig)})
    if not held:
        given = [name for name in HELD_KEYS if any(k.startswith(f"{PREFIX}{name}.") for k in flat)]
        raise ScenarioError(f"scenario parameters {', '.join(given)}: they need the object, '{PREFIX}held_object.*' "
                            "(at least its mass)")
    sensors = _section(flat, "wrist_sensors", {f.name for f in fields(WristSensorConfig)})
    control = _section(flat, "internal_force", {f.name for f in fields(InternalForceParams)} - {"grasp_time"})
    try:
        grasp = HeldObjectConfig(**held)
        WristSensorConfig(**sensors)
    except (TypeError, ValueError) as exc:
        raise ScenarioError(f"scenario held_object / wrist_sensors parameters: {exc}") from None
    try:
        params = InternalForceParams(grasp_time=grasp.grasp_time, **control)
    except (TypeError, ValueError) as exc:
        raise ScenarioError(f"scenario internal_force parameters: {exc}") from None
    if params.grasp_time < params.still_time:
        raise ScenarioError(f"scenario parameter '{PREFIX}held_object.grasp_time': got {params.grasp_time}, expected "
                            f">= internal_force.still_time ({params.still_time} s: the bias's still step comes first)")
    phases = parse_phases(flat, params, grasp.release_time)
    if phases is not None and "payload_time" not in control:  # the box rests on its support until the lift
        params = dataclasses.replace(params, payload_time=phases.release_time - 2.0 * params.still_time)
    return HeldSetup(held, sensors, params, phases)


def tuned(params: InternalForceParams, values: Mapping[str, Any]) -> InternalForceParams:
    """``params`` with a node's live ``internal_force.*`` values (:meth:`HoldController.retune`)."""
    changes: dict[str, Any] = {}
    for key in ("force_gain", "torque_gain"):
        value = values.get(f"internal_force.{key}", -1.0)
        if value >= 0:
            changes[key] = float(value)
    setpoint = list(values.get("internal_force.setpoint", [0.0]))
    if len(setpoint) != 1:
        changes["setpoint"] = tuple(float(v) for v in setpoint)
    return dataclasses.replace(params, **changes) if changes else params


class HoldController:
    """The tracker of a held-object scenario (module docstring) around a task scenario's tracker ``base`` (its
    tasks, controller, label and cycle count); ``enabled``: internal-force control on."""

    uses_wrench = True
    wrench_streams = (LEFT_WRENCH, RIGHT_WRENCH)

    def __init__(self, base: Any, params: InternalForceParams, enabled: bool, phases: CarryPhases | None = None,
                 limits: MotionLimits | None = None) -> None:
        self.base = base
        self.phases, self.limits = phases, limits or MotionLimits()
        self.params = self.scenario_params = params
        self.enabled = enabled
        self.label = f"{base.label} internal {'on' if enabled else 'off'}"
        self.steps: int | None = base.steps
        self.period: float = base.period
        tasks: list[Task] = list(base.tasks)
        held = [i for i, t in enumerate(tasks) if t.name == params.task]
        if not held or not isinstance(tasks[held[0]], RelativePoseTask):
            raise ScenarioError(f"scenario parameter '{PREFIX}internal_force.task': got {params.task!r}, expected the "
                                "name of a relative_pose task of the scenario")
        self._held_index = held[0]
        self._absolute = [i for i, t in enumerate(tasks) if isinstance(t, AbsolutePoseTask)]
        if phases is not None and len(self._absolute) != 1:
            raise ScenarioError(f"scenario parameter '{PREFIX}absolute_segments': a carry moves one absolute_pose "
                                f"task, the scenario has {len(self._absolute)}")
        if phases is not None:  # the path from the scenario's grasp pose is known now: refuse a late release now
            grasp = tasks[self._absolute[0]]
            assert isinstance(grasp, AbsolutePoseTask)
            path_of(phases, params, (grasp.position, grasp.rotation), self.limits)
        self.reset()

    @property
    def controller(self) -> RelativeController:
        return self.base.controller  # type: ignore[no-any-return]

    @controller.setter
    def controller(self, value: RelativeController) -> None:
        self.base.controller = value

    def reset(self) -> None:
        """Forget the offset, the identification, the start pose and a wrench stop."""
        self.base.reset()
        self.admittance = RelativeAdmittance(self.params)
        self.identification = WrenchIdentification(self.params)
        self.internal = np.full(6, math.nan)
        self.stopped = ""
        self._start: list[Task] | None = None
        self.plan: CarryPlan | None = None

    def carry_plan(self, q0: FloatArray) -> CarryPlan:
        """The carry's targets (:class:`~dualarm_control.references.carry.CarryPlan`) from the start q0 (n,) [rad]."""
        assert self.phases is not None
        return carry_plan(self.base.model, self.base.tasks, self._held_index, self._absolute[0], self.phases,
                          self.params, self.limits, q0)

    def measure(self, q: FloatArray, t: float, wrench: FloatArray) -> FloatArray:
        """The hands' wrenches on the object (2, 6) (world axes, each about its tool origin) from the readings (12,) at q,
        identification and internal wrench h_I in F1 (``self.internal``) updated."""
        readings = np.asarray(wrench, float).reshape(2, 6)
        conf = Configuration(self.base.model, q)
        left, right = conf.frame("left_tool"), conf.frame("right_tool")
        rotations = np.array((left.rotation, right.rotation))
        self.identification.add(t, readings, rotations)
        hands = hand_wrenches(readings, rotations, self.identification.bias, self.params.tool_mass)
        self.internal = in_frame(internal_wrench(hands), left.rotation)
        if self.phases is not None and self.plan is None:
            self.plan = self.carry_plan(q)
        if self._start is None:
            self._start = [dataclasses.replace(t_, position=(s := t_.state(conf)).position, rotation=s.rotation)
                           if isinstance(t_, AbsolutePoseTask) else t_ for t_ in self.base.tasks]
        return hands

    def track(self, q: FloatArray, sample: StreamSample | None, t: float, wrench: FloatArray | None) -> Cycle:
        """One cycle (module docstring); ``wrench``: both wrist readings (12,)."""
        q = self.base.model.check_q(q)
        if wrench is None or np.asarray(wrench).shape != (12,) or not math.isfinite(float(np.sum(wrench))) \
                or not math.isfinite(q.sum()):
            return self._stop(q, t, f"wrist wrenches missing or not finite: {wrench!r}")
        hands = self.measure(q, t, wrench)
        worst = int(np.argmax(np.linalg.norm(hands[:, :3], axis=1)))
        force = float(np.linalg.norm(hands[worst, :3]))
        if self.stopped or force > self.params.wrench_limit:
            side = ("left", "right")[worst]
            return self._stop(q, t, self.stopped or f"wrench limit: the {side} hand's force on the object "
                              f"{force:.1f} N > wrench_limit {self.params.wrench_limit:g} N; motion stopped")
        if self.enabled and self.params.grasp_time <= t < self.release_time:
            self.admittance.step(self.internal, self.period)
        tasks = self._absolute_targets(t) if self.plan is None else self._carry_targets(t)
        held = tasks[self._held_index]
        assert isinstance(held, RelativePoseTask)
        position, rotation = offset_target(held.target.position, held.target.rotation, self.admittance.offset)
        tasks[self._held_index] = dataclasses.replace(held, target=FixedTarget(
            position, rotation, held.target.linear_velocity, held.target.angular_velocity))
        out = self.controller.solve_tasks(q, tasks, t)
        self._annotate(out, t)
        return out

    def retune(self, values: Mapping[str, Any]) -> None:
        """The live parameters ``internal_force.force_gain``, ``.torque_gain`` (< 0: the scenario's) and
        ``.setpoint`` (6 values; one: the scenario's) from a node's ``values``; the admittance keeps its offset.
        ValueError naming the bad value (the change is refused)."""
        self.params = tuned(self.scenario_params, values)
        self.admittance.params = self.params

    @property
    def release_time(self) -> float:
        """When the hands open [s] (inf: never)."""
        return self.phases.release_time if self.phases is not None else math.inf

    def _carry_targets(self, t: float) -> list[Task]:
        """The tasks at t on the carry's plan (the relative target before the admittance's offset)."""
        assert self.plan is not None
        return carry_tasks(self.base.tasks, self.plan, t, self._held_index, self._absolute[0])

    def _absolute_targets(self, t: float) -> list[Task]:
        """The tasks at t: the absolute ones at their start pose until ``motion_start``, then blended to their
        targets over ``start_ramp`` (:func:`~dualarm_control.internal_force.ramp_fraction`)."""
        assert self._start is not None
        s = ramp_fraction(t, self.params.motion_start, self.params.start_ramp)
        if s >= 1.0:
            return list(self.base.tasks)
        tasks = list(self._start)
        for i in self._absolute:
            start, end = tasks[i], self.base.tasks[i]
            assert isinstance(start, AbsolutePoseTask) and isinstance(end, AbsolutePoseTask)
            position, rotation = blend_pose((start.position, start.rotation), (end.position, end.rotation), s)
            tasks[i] = dataclasses.replace(end, position=position, rotation=rotation)
        return tasks

    def _stop(self, q: FloatArray, t: float, reason: str) -> Cycle:
        self.stopped = reason
        out = self.controller.safe_command(q, reason)
        self._annotate(out, t)
        return out

    def _annotate(self, out: Cycle, t: float) -> None:
        out.measured_force = float(np.linalg.norm(self.internal[:3] - np.asarray(self.params.setpoint[:3])))
        out.normal_offset = float(np.linalg.norm(self.admittance.offset[:3]))
        out.internal_wrench = self.internal.copy()
        if self.stopped:
            out.stage = "stopped"
        elif self.plan is not None:
            out.stage = self.plan.stage(t)
        else:
            out.stage = "identify" if t < self.params.motion_start else "hold"

    def report(self, cycle: Cycle, t: float) -> dict[str, Any]:
        """The task cycle's /diagnostics values and the internal wrench [N, N m] in F1, the offset, the mass."""
        out = dict(self.base.report(cycle, t))
        out.update({"force": int(self.enabled),"internal_wrench": " ".join(repr(float(v)) for v in self.internal),
                    "relative_offset": " ".join(repr(float(v)) for v in self.admittance.offset),
                    "identified_mass_kg": repr(self.identification.mass), "wrench_stop": self.stopped})
        return out


def carry_plan(model: Any, tasks: list[Task], held_index: int, absolute_index: int, phases: CarryPhases,
               control: InternalForceParams, limits: MotionLimits, q0: FloatArray) -> CarryPlan:
    """The :class:`~dualarm_control.references.carry.CarryPlan` of a carry's tasks (the relative_pose task at
    ``held_index``, the absolute_pose one at ``absolute_index``: their poses are the grasp's) from q0 (n,) [rad]
    (the controller's, and the report's from a run's first joint positions)."""
    held, absolute = tasks[held_index], tasks[absolute_index]
    assert isinstance(held, RelativePoseTask) and isinstance(absolute, AbsolutePoseTask)
    conf = Configuration(model, q0)
    relative, state = conf.relative(), absolute.state(conf)
    return CarryPlan(phases, control, (relative.position.copy(), relative.rotation.copy()),
                     (np.asarray(held.target.position, float), np.asarray(held.target.rotation, float)),
                     (state.position.copy(), state.rotation.copy()),
                     (np.asarray(absolute.position, float), np.asarray(absolute.rotation, float)),
                     absolute.grasp, limits)


def carry_tasks(tasks: list[Task], plan: CarryPlan, t: float, held_index: int, absolute_index: int) -> list[Task]:
    """``tasks`` with the relative_pose task at ``held_index`` and the absolute_pose one at ``absolute_index`` on the
    carry plan's targets at t [s] (pose and feed-forward twist)."""
    out = list(tasks)
    rel, absolute = plan.relative(t), plan.absolute(t)
    held, moved = out[held_index], out[absolute_index]
    assert isinstance(held, RelativePoseTask) and isinstance(moved, AbsolutePoseTask)
    out[held_index] = dataclasses.replace(held, target=FixedTarget(rel.position, rel.rotation, rel.linear_velocity,
                                                                   rel.angular_velocity))
    out[absolute_index] = dataclasses.replace(moved, position=absolute.position, rotation=absolute.rotation,
                                              linear_velocity=absolute.linear_velocity,
                                              angular_velocity=absolute.angular_velocity)
    return out
