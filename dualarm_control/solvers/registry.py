"""The one registry of kinematic solvers, filled at import by ``@register(name)``."""

from __future__ import annotations

from collections.abc import Callable
from typing import TypeVar

from dualarm_control.errors import UnknownSolverError

T = TypeVar("T")
_REGISTRY: dict[str, type] = {}


def register(name: str) -> Callable[[type[T]], type[T]]:
    """Class decorator adding a Solver subclass under ``name`` (and setting ``cls.name``)."""

    def add(cls: type[T]) -> type[T]:
        if name in _REGISTRY:
            raise ValueError(f"solver {name!r} registered twice")
        cls.name = name  # type: ignore[attr-defined]
        _REGISTRY[name] = cls
        return cls

    return add


def unregister(name: str) -> type:
    """Remove the class registered under ``name`` and return it (UnknownSolverError otherwise):
    for a solver registered for a while only, e.g. a test's deliberately wrong one."""
    cls = solver_class(name)
    del _REGISTRY[name]
    return cls


def solver_names() -> list[str]:
    """Registered solver names, sorted."""
    return sorted(_REGISTRY)


def solver_class(name: str) -> type:
    """Class registered under ``name``; UnknownSolverError lists the valid names."""
    try:
        return _REGISTRY[name]
    except KeyError:
        raise UnknownSolverError(name, solver_names()) from None
