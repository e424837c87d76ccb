"""Exceptions that carry the offending value, so a message can name it."""

from __future__ import annotations


class DualArmError(Exception):
    """Base class of the package's errors."""


class ParameterError(DualArmError, ValueError):
    """A parameter has a wrong value or type.

    Attributes:
        key: fully qualified parameter name (``node.key``).
        value: the value that was given.
        expected: human-readable description of the valid values.
    """

    def __init__(self, key: str, value: object, expected: str) -> None:
        self.key = key
        self.value = value
        self.expected = expected
        super().__init__(f"parameter '{key}': got {value!r}, expected {expected}")


class ScenarioError(DualArmError, ValueError):
    """A scenario file is malformed or names an unknown scenario."""


class UnknownSolverError(DualArmError, KeyError):
    """A solver name is not in the registry."""

    def __init__(self, name: str, known: list[str]) -> None:
        self.name = name
        self.known = known
        super().__init__(f"unknown solver {name!r}; valid choices: {', '.join(known)}")

    def __str__(self) -> str:  # KeyError quotes its message otherwise
        return str(self.args[0])


class UnknownOutputError(DualArmError, KeyError):
    """A command output's message type is not in the registry (:mod:`dualarm_control.outputs`)."""

    def __init__(self, name: str, known: list[str]) -> None:
        self.name = name
        self.known = known
        super().__init__(f"unknown output message type {name!r}; known: {', '.join(known)}")

    def __str__(self) -> str:  # KeyError quotes its message otherwise
        return str(self.args[0])


class DimensionError(DualArmError, ValueError):
    """An array has the wrong shape (e.g. a joint vector with the wrong joint count)."""


class InputRejected(DualArmError, ValueError):
    """A received message (a joint state, a target, a command, ...) is unusable: the node drops it,
    counts it and reports ``reason`` (the log line, the /diagnostics text).

    Raised only for a bad message (the good path does no extra work). The decoders that read a
    stamp set :attr:`stamp` before the exception leaves them, so that the rejection is reported at
    the message's stamp.

    Attributes:
        reason: why the message is unusable, the text the node logs and reports.
        field: the message field at fault (``name``, ``position``, ``points``, ...); '' if none.
        value: the offending value (the joint names, the distance [m], ...); None if none.
        stamp: the message's header stamp [ns]; None where the decoder reads none (a command).
    """

    def __init__(self, reason: str, field: str = "", value: object = None, stamp: int | None = None) -> None:
        self.reason = reason
        self.field = field
        self.value = value
        self.stamp = stamp
        super().__init__(reason)
