"""One registry type for every open set of the package: solvers, limits, task types, command output types.

Each kind keeps its entries in a :class:`Registry` of its own, filled when the module that defines an
entry is imported (a decorator or one call), so that a new entry is one file and one registration line,
in the package or in a user's plugin (docs/limits.md).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Generic, TypeVar

T = TypeVar("T")


class Registry(Generic[T]):
    """Entries of one kind by name.

    Args:
        kind: what an entry is, for messages ("solver", "limit", "task type", ...).
        unknown: the error for a name that is not registered, from the name and the registered ones.
    """

    def __init__(self, kind: str, unknown: Callable[[str, list[str]], Exception]) -> None:
        self.kind = kind
        self._unknown = unknown
        self._entries: dict[str, T] = {}

    def add(self, name: str, entry: T) -> T:
        """Register ``entry`` under ``name``; ValueError when another entry has the name (the same one again
        is accepted: a module imported twice)."""
        known = self._entries.get(name)
        if known is not None and known is not entry:
            raise ValueError(f"{self.kind} {name!r} registered twice")
        self._entries[name] = entry
        return entry

    def decorator(self, name: str) -> Callable[[T], T]:
        """``@registry.decorator(name)``: :meth:`add` the decorated object under ``name``."""
        return lambda entry: self.add(name, entry)

    def remove(self, name: str) -> T:
        """Remove and return the entry of ``name`` (the unknown-name error otherwise): for an entry registered
        for a while only, e.g. a test's."""
        entry = self.get(name)
        del self._entries[name]
        return entry

    def get(self, name: str) -> T:
        """The entry of ``name``; the unknown-name error names the registered ones."""
        try:
            return self._entries[name]
        except KeyError:
            raise self._unknown(name, self.names()) from None

    def names(self) -> list[str]:
        """Every registered name, sorted."""
        return sorted(self._entries)

    def __contains__(self, name: object) -> bool:
        return name in self._entries

    def __iter__(self) -> Iterator[str]:
        return iter(self.names())
