"""Reference source of issue 18: timed goals and twists (or live ones), replanned online by ruckig.

The relative target is the state of an :class:`~dualarm_control.online_trajectory.OnlineTrajectory`
started at the measured relative pose (it holds it until a command comes). Its commands are

* a script, the scenario file's ``goals:`` list (:mod:`dualarm_control.goal_script` gives the
  schema), fed at their cycles by a :class:`~dualarm_control.goal_script.ScriptDriver`: the run
  is deterministic, the same in one process and over ROS in lockstep; it ends ``settle_time``
  after the script's last command has ended and the generator is at rest (found by a dry run of
  the script from the same start pose, so both runs have the same number of cycles);
* or live commands (``GoalsSource(None)``: the trajectory node's interactive mode), given to the
  generator by the caller (:attr:`GoalsStream.generator`); the run has no end.

Keys of a scenario file: ``goals`` (the list) instead of ``segments`` or ``tasks``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

from dualarm_control.controller import ControllerParams, RelativeController
from dualarm_control.errors import ScenarioError
from dualarm_control.goal_script import (
    ScriptDriver,
    ScriptError,
    TimedCommand,
    parse_goals,
    script_duration,
)
from dualarm_control.kinematics import DualArmModel, FloatArray
from dualarm_control.online_trajectory import OnlineTrajectory
from dualarm_control.references.absolute import (
    HOLD_REASON,
    AbsoluteFrame,
    parse_absolute_frame,
)
from dualarm_control.references.base import (
    RELATIVE_TARGET,
    RelativeTracker,
    RunOptions,
    SourceDefaults,
    StreamSample,
)
from dualarm_control.trajectory import MotionLimits

MAX_SCRIPT_TIME = 600.0
"""Longest a script may take to come to rest after its last command [s] (a dry run's bound)."""


class GoalsStream:
    """The online generator (and the script's driver) sampled at the cycle times 0, T, 2T, ...

    Attributes:
        generator: the online generator (live commands go to it).
        driver: the script's driver, or None for live commands.
        end: time [s] of the first cycle with no target (script end at rest + settle), inf when live.
    """

    def __init__(self, generator: OnlineTrajectory, commands: Sequence[TimedCommand] | None, end: float,
                 absolute: OnlineTrajectory | None = None) -> None:
        self.generator = generator
        self.absolute = absolute
        self.driver = (ScriptDriver([c for c in commands if not c.absolute], generator)
                       if commands is not None else None)
        self.absolute_driver = (ScriptDriver([c for c in commands if c.absolute], absolute)
                                if commands is not None and absolute is not None else None)
        self.end = end

    @property
    def given(self) -> bool:
        """Every command of the script has been given (True when live)."""
        return all(d.given for d in (self.driver, self.absolute_driver) if d is not None)

    def at_rest(self) -> bool:
        """Both generators' targets are at rest (done)."""
        return self.generator.sample().done and (self.absolute is None or self.absolute.sample().done)

    def advance(self, t: float) -> None:
        """Step the generators (feeding the script first) until their time is ``t`` [s] (to half a period)."""
        gen = self.generator
        while gen.time < t - 0.5 * gen.period:
            if self.driver is not None:
                self.driver.feed()
            gen.step()
            if self.absolute is not None:
                if self.absolute_driver is not None:
                    self.absolute_driver.feed()
                self.absolute.step()

    def sample(self, t: float) -> StreamSample:
        """The target at ``t`` [s] (times must not decrease)."""
        self.advance(t)
        target = self.generator.sample()
        stage = f"{target.segment_name} {target.segment}"
        if self.absolute is None:
            return StreamSample(target, None, stage)
        absolute = self.absolute.sample()
        return StreamSample(target, None, f"{stage}; absolute {absolute.segment_name} {absolute.segment}", absolute)


@dataclass(frozen=True)
class GoalsSource(SourceDefaults):
    """Timed goals and twists (``commands``), or live ones (``commands`` None): a
    :class:`~dualarm_control.references.base.ReferenceSource` streaming /relative_target."""

    commands: tuple[TimedCommand, ...] | None
    frame: AbsoluteFrame | None = None
    kind: ClassVar[str] = "goals"
    streams: ClassVar[tuple[str, ...]] = (RELATIVE_TARGET,)

    def describe(self) -> str:
        if self.commands is None:
            return "live goals and twists"
        goals = sum(1 for c in self.commands if not hasattr(c, "duration"))
        return f"{goals} goals, {len(self.commands) - goals} twists"

    def generator(self, model: DualArmModel, q0: FloatArray, limits: MotionLimits, period: float) -> OnlineTrajectory:
        """A new generator holding the relative pose of q0 (n,) [rad]."""
        return OnlineTrajectory(*model.relative_pose(q0), limits=limits, period=period, reach=model.relative_reach())

    def goals_stream(self, model: DualArmModel, q0: FloatArray, limits: MotionLimits, period: float,
                     end: float) -> GoalsStream:
        """The generators from q0 (n,) [rad] (the absolute frame's too when the scenario has one) and the script."""
        absolute = self.frame.generator(model, q0, limits, period) if self.frame is not None else None
        return GoalsStream(self.generator(model, q0, limits, period), self.commands, end, absolute)

    def end_time(self, model: DualArmModel, q0: FloatArray, options: RunOptions, period: float) -> float:
        """Time [s] of the first cycle without target: a dry run of the script from q0's pose
        until its last command has ended and the generator is at rest, plus the settle time."""
        if self.commands is None:
            return math.inf
        stream = self.goals_stream(model, q0, options.limits, period, math.inf)
        last = script_duration(self.commands)
        gen = stream.generator
        while not stream.given or gen.time < last - 0.5 * period or not stream.at_rest():
            if gen.time > last + MAX_SCRIPT_TIME:
                raise RuntimeError(f"goals script not at rest {MAX_SCRIPT_TIME} s after its last command")
            stream.advance(gen.time + period)
        # on the nanosecond grid the trajectory node's clock gives (elapsed ns / 1e9): 2606 * 0.005 + 1.0 is
        # 14.030000000000001 > 14.03, one more cycle over ROS than in one process
        return round((gen.time + options.settle_time) * 1e9) / 1e9

    def end_pose(self, model: DualArmModel, q0: FloatArray, limits: MotionLimits,
                 period: float) -> tuple[FloatArray, FloatArray]:
        """Where the script leaves the target at rest (position [m] (3,), rotation (3, 3)), from q0's pose."""
        stream = self.goals_stream(model, q0, limits, period, math.inf)
        if self.commands is not None:
            end = self.end_time(model, q0, RunOptions(limits, 0.0), period)
            stream.advance(end)
        return stream.generator.p.copy(), stream.generator.r.copy()

    def stream(self, model: DualArmModel, q0: FloatArray, options: RunOptions, period: float) -> GoalsStream:
        """The targets of a run from the measured start configuration q0 (n,) [rad]."""
        end = self.end_time(model, q0, options, period)
        return self.goals_stream(model, q0, options.limits, period, end)

    def tracker(self, model: DualArmModel, params: ControllerParams, options: RunOptions) -> RelativeTracker:
        return RelativeTracker(RelativeController(model, params), self.frame)


def parse_goals_source(items: object, flat: Mapping[str, Any] | None = None) -> GoalsSource:
    """The ``scenario.goals`` list as a source, with the absolute frame of the flattened parameters ``flat``
    (:func:`~dualarm_control.references.absolute.parse_absolute_frame`); ScenarioError naming the bad entry, or a
    relative command while the relative pose is held."""
    try:
        commands = parse_goals(items, "scenario.goals")
    except ScriptError as exc:
        raise ScenarioError(str(exc)) from None
    frame = parse_absolute_frame(flat or {}, any(c.absolute for c in commands))
    if frame is not None and frame.hold:
        relative = [i for i, c in enumerate(commands) if not c.absolute]
        if relative:
            raise ScenarioError(f"scenario.goals: item {relative[0]} (t = {commands[relative[0]].t:g} s) is refused: "
                                f"{HOLD_REASON}")
    return GoalsSource(commands, frame)
