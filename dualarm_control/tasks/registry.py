"""The task types' registry: a task scenario names each task's ``type`` and the registry builds it
(docs/limits.md, "A task of your own").

A type is registered in the file that defines its task, with one line::

    @register_task("circle")
    def circle(spec: TaskSpec, context: TaskContext) -> CircleTask: ...

A user's own type registers the same way in a file the scenario's ``plugins`` key names
(:mod:`dualarm_control.plugins`); an unknown type is refused naming the registered ones.
"""

from __future__ import annotations

import builtins
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from dualarm_control.errors import ScenarioError
from dualarm_control.registry import Registry
from dualarm_control.scenario_keys import PREFIX, get, number
from dualarm_control.tasks.base import PRIORITIES, SecondPriority

if TYPE_CHECKING:
    from dualarm_control.tasks.base import Task


@dataclass(frozen=True)
class TaskSpec:
    """One task as written in the scenario file: its name, its type and its flattened parameters
    (``scenario.<name>.<key>``), validated when the task is built."""

    name: str
    type: str
    values: Mapping[str, Any]

    def value(self, key: str, kind: builtins.type, default: Any = None) -> Any:
        """``scenario.<name>.<key>`` as a number (``kind`` float), a string or a list; ScenarioError naming
        the key when it is missing (and ``default`` is None) or of another kind."""
        full = f"{self.name}.{key}"
        if kind is float:
            return number(self.values, full, default)
        value = get(self.values, full, default)
        if not isinstance(value, kind):
            raise ScenarioError(f"scenario parameter '{PREFIX}{full}': got {value!r}, expected a {kind.__name__}")
        return value


@dataclass(frozen=True)
class TaskContext:
    """What a run gives every task it builds.

    Attributes:
        gain: the task gain k [1/s] of the run.
        table_height: the scenario's table top, world z [m] (None: the scenario has no table).
        height_offset: a modelling error along the pan normal added to a circle's height [m] (force variant).
    """

    gain: float
    table_height: float | None
    height_offset: float = 0.0


TaskBuilder = Callable[[TaskSpec, TaskContext], "Task"]

TASK_TYPES: Registry[TaskBuilder] = Registry("task type", lambda name, known: ScenarioError(
    f"unknown task type {name!r}; registered: {', '.join(known)}"))


def register_task(type_name: str) -> Callable[[TaskBuilder], TaskBuilder]:
    """Decorator registering a builder for the scenario task type ``type_name`` (ValueError if taken)."""

    return TASK_TYPES.decorator(type_name)


def task_types() -> list[str]:
    """Every registered task type, sorted."""
    return TASK_TYPES.names()


def check_task_type(spec: TaskSpec) -> None:
    """ScenarioError naming the key, the value and the registered types when ``spec.type`` is unknown."""
    if spec.type not in TASK_TYPES:
        raise ScenarioError(f"scenario parameter '{PREFIX}{spec.name}.type': got {spec.type!r}, expected one of: "
                            f"{', '.join(task_types())}")


def build_task(spec: TaskSpec, context: TaskContext) -> Task:
    """The task ``spec`` describes; ScenarioError naming the task (and the key) on a bad value."""
    check_task_type(spec)
    priority = spec.value("priority", float, 1.0)
    if priority not in PRIORITIES:
        raise ScenarioError(f"scenario parameter '{PREFIX}{spec.name}.priority': got {priority:g}, expected 1 "
                            "(weighted beside the others) or 2 (under the priority-1 tasks)")
    try:
        task = TASK_TYPES.get(spec.type)(spec, context)
        return SecondPriority(task) if priority == 2 else task
    except ScenarioError:
        raise
    except ValueError as exc:
        raise ScenarioError(f"scenario task {spec.name!r}: {exc}") from None
