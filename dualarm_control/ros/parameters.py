"""Declared node parameters with ROS 2 static typing.

A parameter declared with a default value takes that value's type; an override
(params file or ``-p``) of another type is an error, as in rclpy
(``InvalidParameterTypeException``), including an integer for a double parameter
(``200`` for ``200.0``). Overrides for names the node never declares are ignored
like ROS does and listed by :meth:`ParameterStore.undeclared_overrides`.
Declaring with no default (``None``) or an empty list leaves the type open: the
override decides it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from enum import IntEnum
from typing import Any

from dualarm_control.errors import DualArmError, ParameterError


class ParameterType(IntEnum):
    """Same names and values as ``rclpy.Parameter.Type``."""

    NOT_SET = 0
    BOOL = 1
    INTEGER = 2
    DOUBLE = 3
    STRING = 4
    BYTE_ARRAY = 5
    BOOL_ARRAY = 6
    INTEGER_ARRAY = 7
    DOUBLE_ARRAY = 8
    STRING_ARRAY = 9


_TYPE_WORDS = {
    ParameterType.NOT_SET: "not set", ParameterType.BOOL: "bool", ParameterType.INTEGER: "integer",
    ParameterType.DOUBLE: "double", ParameterType.STRING: "string", ParameterType.BYTE_ARRAY: "byte array",
    ParameterType.BOOL_ARRAY: "bool array", ParameterType.INTEGER_ARRAY: "integer array",
    ParameterType.DOUBLE_ARRAY: "double array", ParameterType.STRING_ARRAY: "string array",
}
_ARRAY_OF = {
    bool: ParameterType.BOOL_ARRAY, int: ParameterType.INTEGER_ARRAY,
    float: ParameterType.DOUBLE_ARRAY, str: ParameterType.STRING_ARRAY,
}


class InvalidParameterTypeException(ParameterError, TypeError):
    """An override's type differs from the declared type (rclpy's exception of that name)."""


class InvalidParameterValueException(ParameterError):
    """A value that no ROS parameter type can hold."""


class ParameterNotDeclaredException(DualArmError, KeyError):
    """``get_parameter`` of a name the node did not declare."""

    def __str__(self) -> str:
        return str(self.args[0])


class ParameterAlreadyDeclaredException(DualArmError, KeyError):
    """``declare_parameter`` twice with the same name."""

    def __str__(self) -> str:
        return str(self.args[0])


def parameter_type_of(value: Any, name: str = "?") -> ParameterType:
    """The ROS parameter type of a Python value (lists must be homogeneous)."""
    if value is None:
        return ParameterType.NOT_SET
    if isinstance(value, bool):
        return ParameterType.BOOL
    if isinstance(value, int):
        return ParameterType.INTEGER
    if isinstance(value, float):
        return ParameterType.DOUBLE
    if isinstance(value, str):
        return ParameterType.STRING
    if isinstance(value, (bytes, bytearray)):
        return ParameterType.BYTE_ARRAY
    if isinstance(value, (list, tuple)):
        if not value:
            return ParameterType.NOT_SET
        kinds = {bool if isinstance(v, bool) else type(v) for v in value}
        if len(kinds) == 1 and (kind := kinds.pop()) in _ARRAY_OF:
            return _ARRAY_OF[kind]
    raise InvalidParameterValueException(
        name, value, "a bool, int, float, str, or a list of one of these (all items the same type)"
    )


def _normalize(value: Any) -> Any:
    """Tuples and numpy arrays become lists of Python scalars."""
    if hasattr(value, "tolist") and not isinstance(value, (list, tuple, str, bytes)):
        value = value.tolist()
    if isinstance(value, tuple):
        value = list(value)
    return value


@dataclass(frozen=True)
class Parameter:
    """A parameter's name, value and type (``.name``, ``.value``, ``.type_``)."""

    name: str
    value: Any = None
    type_: ParameterType = ParameterType.NOT_SET
    description: str = ""

    Type = ParameterType

    def get_parameter_value(self) -> Any:
        """The value (rclpy returns a ParameterValue message; the plain value is enough here)."""
        return self.value


class ParameterStore:
    """The parameters of one node: declared values plus the command-line overrides."""

    def __init__(self, node_name: str, overrides: dict[str, Any], sources: dict[str, str] | None = None) -> None:
        self._node = node_name
        self._overrides = dict(overrides)
        self._sources = dict(sources or {})
        self._params: dict[str, Parameter] = {}

    def declare(self, name: str, value: Any = None, description: str = "",
                ignore_override: bool = False) -> Parameter:
        """Declare ``name``; the override (if any) replaces ``value`` after a type check."""
        if not name or name.startswith(".") or name.endswith("."):
            raise InvalidParameterValueException(f"{self._node}.{name}", name, "a non-empty dotted name")
        if name in self._params:
            raise ParameterAlreadyDeclaredException(f"parameter '{name}' of node '{self._node}' is already declared")
        value = _normalize(value)
        declared_type = parameter_type_of(value, f"{self._node}.{name}")
        if not ignore_override and name in self._overrides:
            override = _normalize(self._overrides[name])
            override_type = parameter_type_of(override, f"{self._node}.{name}")
            self._check_type(name, declared_type, override, override_type)
            value = override
            declared_type = override_type if declared_type == ParameterType.NOT_SET else declared_type
        param = Parameter(name, value, declared_type, description)
        self._params[name] = param
        return param

    def get(self, name: str) -> Parameter:
        """The declared parameter ``name``."""
        try:
            return self._params[name]
        except KeyError:
            raise ParameterNotDeclaredException(
                f"parameter '{name}' of node '{self._node}' is not declared; declare it first "
                f"(declared: {', '.join(sorted(self._params)) or 'none'})"
            ) from None

    def has(self, name: str) -> bool:
        """Whether ``name`` is declared."""
        return name in self._params

    def names(self) -> list[str]:
        """Declared names, sorted."""
        return sorted(self._params)

    def undeclared_overrides(self) -> dict[str, Any]:
        """Overrides given for this node that no ``declare_parameter`` consumed (yet)."""
        return {k: v for k, v in self._overrides.items() if k not in self._params}

    def _check_type(self, name: str, declared: ParameterType, value: Any, given: ParameterType) -> None:
        if declared in (ParameterType.NOT_SET, given):
            return
        hint = ""
        if declared == ParameterType.DOUBLE and given == ParameterType.INTEGER:
            hint = f" (write {float(value)!r}, not {value!r})"
        elif declared == ParameterType.DOUBLE_ARRAY and given == ParameterType.INTEGER_ARRAY:
            hint = f" (write {[float(v) for v in value]!r}, not {value!r})"
        source = self._sources.get(name)
        where = f"; value from {source}" if source else ""
        raise InvalidParameterTypeException(
            f"{self._node}.{name}", value,
            f"type {_TYPE_WORDS[declared]} as declared by the node, not {_TYPE_WORDS[given]}{hint}{where}",
        )


def declare_many(store: ParameterStore, namespace: str,
                 parameters: Sequence[tuple[str, Any] | tuple[str, Any, str]]) -> list[Parameter]:
    """rclpy's ``declare_parameters(namespace, [(name, value[, description]), ...])``."""
    prefix = f"{namespace}." if namespace else ""
    result = []
    for item in parameters:
        name, value, *rest = item
        result.append(store.declare(prefix + name, value, rest[0] if rest else ""))
    return result
