"""The one registry of kinematic solvers, filled at import by ``@register(name)``."""

from __future__ import annotations

from collections.abc import Callable
from typing import TypeVar

from dualarm_control.errors import UnknownSolverError
from dualarm_control.registry import Registry

T = TypeVar("T")
SOLVERS: Registry[type] = Registry("solver", UnknownSolverError)


def register(name: str) -> Callable[[type[T]], type[T]]:
    """Class decorator adding a Solver subclass under ``name`` (and setting ``cls.name``)."""

    def add(cls: type[T]) -> type[T]:
        if name in SOLVERS:
            raise ValueError(f"solver {name!r} registered twice")
        cls.name = name  # type: ignore[attr-defined]
        SOLVERS.add(name, cls)
        return cls

    return add


def unregister(name: str) -> type:
    """Remove the class registered under ``name`` and return it (UnknownSolverError otherwise):
    for a solver registered for a while only, e.g. a test's deliberately wrong one."""
    return SOLVERS.remove(name)


def solver_names() -> list[str]:
    """Registered solver names, sorted."""
    return SOLVERS.names()


def solver_class(name: str) -> type:
    """Class registered under ``name``; UnknownSolverError lists the valid names."""
    return SOLVERS.get(name)
