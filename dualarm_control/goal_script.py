"""Timed goals and twists of a scenario (``goals:``), parsed and fed to the online generator.

Schema (YAML list under ``goals:``; times [s] from the start of the run, m, rad):

.. code-block:: yaml

    goals:
      - {t: 0.0, xyz: [0.0, 0.0, 0.15], rpy: [0.0, 0.0, 0.0]}      # a goal pose (roll, pitch, yaw)
      - {t: 1.5, xyz: [0.05, 0.0, 0.12], quat: [0, 0, 0.3827, 0.9239]}  # or a quaternion x y z w
      - {t: 2.0, twist: {linear: [0.0, 0.02, 0.0], angular: [0, 0, 0.2]}, duration: 0.5}

* a **goal** item has ``t``, ``xyz`` and exactly one of ``rpy`` / ``quat``;
* a **twist** item has ``t``, ``twist`` (``linear`` and/or ``angular``, 3 numbers each, missing
  ones zero) and ``duration`` > 0 s: the driver sends it every cycle in ``[t, t + duration)``,
  then the generator brakes after its ``jog_timeout``;
* either may have ``absolute: true`` (issue 41): a goal pose or twist of the absolute frame in the world
  (:mod:`dualarm_control.references.absolute`), given to the absolute frame's generator.

Items are applied in time order (stable for equal times). A goal may come mid-motion: it
preempts. Errors name the item and the key (``goals[2].rpy: expected 3 numbers``). Physical
checks (reach, quaternion norm) are the generator's: a refused command is recorded, not fatal.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from dualarm_control.drive_commands import rotation_from_rpy
from dualarm_control.errors import DualArmError
from dualarm_control.online_trajectory import CommandResult, OnlineTrajectory
from dualarm_control.trajectory import FloatArray, TargetSample


class ScriptError(DualArmError, ValueError):
    """A ``goals:`` entry is malformed (the message names the item and the key)."""


@dataclass(frozen=True, eq=False)
class TimedGoal:
    """Go to ``position`` [m] / ``orientation`` (quaternion x y z w (4,) or rotation (3, 3)) at ``t`` [s]."""

    t: float
    position: FloatArray
    orientation: FloatArray
    absolute: bool = False


@dataclass(frozen=True, eq=False)
class TimedTwist:
    """Follow ``(linear [m/s], angular [rad/s])`` from ``t`` [s] for ``duration`` [s]."""

    t: float
    linear: FloatArray
    angular: FloatArray
    duration: float
    absolute: bool = False


TimedCommand = TimedGoal | TimedTwist
_GOAL_KEYS = {"t", "xyz", "rpy", "quat", "absolute"}
_TWIST_KEYS = {"t", "twist", "duration", "absolute"}


def _number(value: object, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(float(value)):
        raise ScriptError(f"{where}: expected a finite number, got {value!r}")
    return float(value)


def _numbers(value: object, size: int, where: str) -> FloatArray:
    if not isinstance(value, Sequence) or isinstance(value, str) or len(value) != size:
        raise ScriptError(f"{where}: expected {size} numbers, got {value!r}")
    return np.array([_number(v, f"{where}[{i}]") for i, v in enumerate(value)])


def parse_item(item: object, where: str) -> TimedCommand:
    """One ``goals:`` entry as a :class:`TimedGoal` or :class:`TimedTwist` (ScriptError naming the key)."""
    if not isinstance(item, Mapping):
        raise ScriptError(f"{where}: expected a mapping like {{t: 0.5, xyz: [...], rpy: [...]}}, got {item!r}")
    keys = set(item)
    kind = _TWIST_KEYS if "twist" in keys else _GOAL_KEYS
    unknown = sorted(str(k) for k in keys - kind)
    if unknown:
        raise ScriptError(f"{where}: unknown key(s) {', '.join(unknown)} (a {'twist' if 'twist' in keys else 'goal'} "
                          f"takes {', '.join(sorted(kind))})")
    if "t" not in item:
        raise ScriptError(f"{where}: missing key t (time [s] from the start)")
    t = _number(item["t"], f"{where}.t")
    if t < 0.0:
        raise ScriptError(f"{where}.t: expected a time >= 0 s, got {t!r}")
    absolute = item.get("absolute", False)
    if not isinstance(absolute, bool):
        raise ScriptError(f"{where}.absolute: expected true or false, got {absolute!r}")
    if "twist" in keys:
        twist = item["twist"]
        if not isinstance(twist, Mapping) or not set(twist) <= {"linear", "angular"} or not twist:
            raise ScriptError(f"{where}.twist: expected {{linear: [x, y, z], angular: [x, y, z]}}, got {twist!r}")
        if "duration" not in item:
            raise ScriptError(f"{where}: missing key duration (seconds the twist is sent)")
        duration = _number(item["duration"], f"{where}.duration")
        if duration <= 0.0:
            raise ScriptError(f"{where}.duration: expected a duration > 0 s, got {duration!r}")
        linear = _numbers(twist.get("linear", [0.0] * 3), 3, f"{where}.twist.linear")
        angular = _numbers(twist.get("angular", [0.0] * 3), 3, f"{where}.twist.angular")
        return TimedTwist(t, linear, angular, duration, absolute)
    if "xyz" not in item:
        raise ScriptError(f"{where}: missing key xyz (goal position [m] in left_tool, or in world when absolute)")
    if ("rpy" in item) == ("quat" in item):
        raise ScriptError(f"{where}: give exactly one of rpy (roll pitch yaw [rad]) and quat (x y z w)")
    position = _numbers(item["xyz"], 3, f"{where}.xyz")
    if "rpy" in item:
        orientation = rotation_from_rpy(_numbers(item["rpy"], 3, f"{where}.rpy"))
    else:
        orientation = _numbers(item["quat"], 4, f"{where}.quat")
    return TimedGoal(t, position, orientation, absolute)


def parse_goals(items: object, where: str = "goals") -> tuple[TimedCommand, ...]:
    """The ``goals:`` list as timed commands sorted by time (stable); ScriptError naming the bad entry."""
    if not isinstance(items, Sequence) or isinstance(items, str) or not items:
        raise ScriptError(f"{where}: expected a non-empty list of goals and twists, got {items!r}")
    commands = [parse_item(item, f"{where}[{i}]") for i, item in enumerate(items)]
    return tuple(sorted(commands, key=lambda c: c.t))


def script_duration(commands: Sequence[TimedCommand]) -> float:
    """Time [s] of the last command's end (a twist's end is ``t + duration``)."""
    return max((c.t + c.duration if isinstance(c, TimedTwist) else c.t) for c in commands)


@dataclass
class ScriptDriver:
    """Feeds timed commands to an :class:`OnlineTrajectory` at their cycle, deterministically.

    Call :meth:`feed` once per cycle, before ``generator.step()``. A command at time ``t`` is
    given when ``generator.cycles == round(t / period)``, i.e. it shapes the sample of time
    ``(k + 1) * period``; its stamp is ``t`` (a twist's repeats: the cycle's time). A twist is
    repeated every cycle in ``[t, t + duration)`` unless a later command comes first.

    Attributes:
        results: ``(time [s], command, result)`` of every command given, in order.
    """

    commands: Sequence[TimedCommand]
    generator: OnlineTrajectory
    results: list[tuple[float, TimedCommand, CommandResult]] = field(default_factory=list)
    _next: int = 0
    _active: TimedTwist | None = None  # the twist being repeated (a later command ends it)

    @property
    def given(self) -> bool:
        """Every command has been given (a twist's repeats may still follow)."""
        return self._next >= len(self.commands)

    def feed(self) -> list[CommandResult]:
        """Give the commands due at the generator's current cycle; their results."""
        gen = self.generator
        k = gen.cycles
        now = k * gen.period
        out: list[CommandResult] = []
        while self._next < len(self.commands) and round(self.commands[self._next].t / gen.period) <= k:
            command = self.commands[self._next]
            self._next += 1
            if isinstance(command, TimedGoal):
                self._active = None
                result = gen.command_goal(command.position, command.orientation, stamp=now)
            else:
                self._active = command
                result = self._twist(command, now)
            self.results.append((now, command, result))
            out.append(result)
            if not result.accepted:
                self._active = None
        twist = self._active
        if twist is not None and out == [] and k < round((twist.t + twist.duration) / gen.period):
            out.append(self._twist(twist, now))
        return out

    def _twist(self, command: TimedTwist, now: float) -> CommandResult:
        return self.generator.command_twist(command.linear, command.angular, stamp=now)


def run_script(commands: Sequence[TimedCommand], generator: OnlineTrajectory,
               duration: float) -> list[TargetSample]:
    """Run the script for ``duration`` [s] (``round(duration / period)`` cycles); the samples."""
    driver = ScriptDriver(commands, generator)
    samples = []
    for _ in range(round(duration / generator.period)):
        driver.feed()
        samples.append(generator.step())
    return samples
