"""ROS-style YAML parameter files and typed, validated parameter declarations.

A file holds ``<node name>:`` (or ``/**:``, or ``/ns/node``) -> ``ros__parameters:`` -> keys;
nested maps become dotted names (``scenario.limits.max_linear_velocity``), as in ROS 2.
Types follow ROS 2: a declared double refuses an integer (write ``200.0``, not ``200``).
The same declarations serve the in-process experiment (reading files directly) and the
nodes (declaring them through the middleware), so both validate identically.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from dualarm_control.errors import ParameterError

ParamValue = bool | int | float | str | list[Any]


class ParameterFileError(ParameterError):
    """A parameter file is missing or malformed."""

    def __init__(self, path: str | Path, reason: str) -> None:
        self.path = str(path)
        super().__init__(f"params file {path}", str(path), reason)
        self.args = (f"parameter file {path}: {reason}",)

    def __str__(self) -> str:
        return str(self.args[0])


def flatten(tree: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """Flatten nested maps into dotted parameter names (ROS 2 convention)."""
    out: dict[str, Any] = {}
    for key, value in tree.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            out.update(flatten(value, f"{name}."))
        else:
            out[name] = value
    return out


def _node_keys(node_name: str, namespace: str) -> list[str]:
    ns = "/" + namespace.strip("/") if namespace.strip("/") else ""
    return ["/**", f"{ns}/**" if ns else "/**", node_name, f"/{node_name}", f"{ns}/{node_name}"]


MAX_EXPANDED_VALUES = 1_000_000
"""A parameter file may hold this many values (map keys, values and list items) once its aliases (``*name``)
are expanded: far above any real file (a few thousand), far below an alias bomb (a few hundred bytes of nested
aliases expanding to 9^9 values, minutes and gigabytes to flatten)."""


def expanded_size(doc: Any) -> int | None:
    """How many values ``doc`` (from ``yaml.safe_load``, aliases shared) holds with every alias expanded,
    counted without expanding (each shared object once); None for a recursive alias."""
    sizes: dict[int, int] = {}
    busy: set[int] = set()

    def size(node: Any) -> int:
        if not isinstance(node, (Mapping, list)):
            return 1
        if id(node) in sizes:
            return sizes[id(node)]
        if id(node) in busy:
            raise RecursionError
        busy.add(id(node))
        items = [*node.keys(), *node.values()] if isinstance(node, Mapping) else node
        sizes[id(node)] = 1 + sum(size(item) for item in items)
        return sizes[id(node)]

    try:
        return size(doc)
    except RecursionError:
        return None


def read_params_file(path: str | Path, node_name: str, namespace: str = "/") -> dict[str, Any]:
    """Parameters that ``path`` gives to node ``node_name`` in ``namespace``, flattened.

    Sections are applied in ROS order: ``/**`` wildcards first, then the node's own.
    Raises ParameterFileError (missing or unreadable file, not UTF-8, bad YAML with its line,
    wrong layout).
    """
    p = Path(path)
    if not p.is_file():
        raise ParameterFileError(p, "file not found")
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ParameterFileError(p, f"unreadable ({exc})") from None
    return parse_params_text(text, node_name, namespace, p)


def parse_params_text(text: str, node_name: str, namespace: str = "/", source: str | Path = "<text>") -> dict[str, Any]:
    """:func:`read_params_file` on the text of a parameter file (``source`` names it in errors: a
    path, or where the text came from, e.g. a bag's topic)."""
    try:
        doc = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        raise ParameterFileError(source, f"malformed YAML{where}: {getattr(exc, 'problem', exc)}") from None
    if doc is None:
        return {}
    size = expanded_size(doc)
    if size is None or size > MAX_EXPANDED_VALUES:
        raise ParameterFileError(source, "its aliases expand to " + ("a recursive structure" if size is None else
                                 f"{size} values") + f", more than {MAX_EXPANDED_VALUES} (an alias bomb?)")
    if not isinstance(doc, Mapping):
        raise ParameterFileError(source, "expected a map of node names at the top level")
    out: dict[str, Any] = {}
    seen: set[str] = set()
    for key in _node_keys(node_name, namespace):
        if key in seen or key not in doc:
            continue
        seen.add(key)
        section = doc[key]
        if not isinstance(section, Mapping) or "ros__parameters" not in section:
            raise ParameterFileError(source, f"section '{key}' must contain 'ros__parameters:'")
        params = section["ros__parameters"] or {}
        if not isinstance(params, Mapping):
            raise ParameterFileError(source, f"'{key}: ros__parameters' must be a map")
        out.update(flatten(params))
    return out


def params_document(node_name: str, values: Mapping[str, Any]) -> str:
    """A ROS 2 parameter file (YAML) giving node ``node_name`` the flat ``values`` (dotted names
    nested again, keys sorted): :func:`parse_params_text` of it gives ``values`` back."""
    tree: dict[str, Any] = {}
    for name, value in values.items():
        *parents, leaf = name.split(".")
        branch = tree
        for part in parents:
            branch = branch.setdefault(part, {})
        branch[leaf] = list(value) if isinstance(value, (list, tuple)) else value
    return yaml.safe_dump({node_name: {"ros__parameters": tree}}, sort_keys=True, default_flow_style=None, width=100)


def read_params_files(paths: Iterable[str | Path], node_name: str, namespace: str = "/") -> dict[str, Any]:
    """Merge several files in order (later files win), like repeated ``--params-file``."""
    out: dict[str, Any] = {}
    for path in paths:
        out.update(read_params_file(path, node_name, namespace))
    return out


@dataclass(frozen=True)
class ParamSpec:
    """A declared parameter: name, default (fixes the ROS type), description, optional check.

    ``choices`` returns the valid values (evaluated lazily, e.g. the solver registry);
    ``check`` returns an error description for a bad value, or '' (its docstring states the
    rule, shown as the ROS parameter descriptor's ``additional_constraints``);
    ``read_only`` parameters cannot change on a running node (ROS descriptor ``read_only``);
    ``bounds`` (closed interval) becomes the descriptor's floating-point or integer range.
    """

    name: str
    default: ParamValue
    description: str
    choices: Callable[[], list[str]] | None = None
    check: Callable[[Any], str] | None = None
    read_only: bool = False
    bounds: tuple[float, float] | None = None

    @property
    def constraints(self) -> str:
        """Human-readable rule for valid values ('' when any value of the type is valid)."""
        if self.choices is not None:
            return "one of: " + ", ".join(self.choices())
        return (self.check.__doc__ or "").strip() if self.check is not None else ""

    @property
    def type_name(self) -> str:
        return _type_name(self.default)

    def validate(self, value: Any, node: str = "") -> ParamValue:
        """Return ``value`` if it has this parameter's type and passes the checks, else raise."""
        key = f"{node}.{self.name}" if node else self.name
        expected = self.type_name
        if _type_name(value) != expected:
            hint = ""
            if expected == "double" and _type_name(value) == "integer":
                hint = f" (write {value}.0, not {value})"
            raise ParameterError(key, value, f"a {expected}{hint}")
        if self.choices is not None:
            valid = self.choices()
            if value not in valid:
                raise ParameterError(key, value, "one of: " + ", ".join(valid))
        if self.check is not None:
            problem = self.check(value)
            if problem:
                raise ParameterError(key, value, problem)
        return value


def _type_name(value: Any) -> str:
    if isinstance(value, bool):
        return "bool"
    if isinstance(value, int):
        return "integer"
    if isinstance(value, float):
        return "double"
    if isinstance(value, str):
        return "string"
    if isinstance(value, list):
        inner = {_type_name(v) for v in value}
        return f"{inner.pop()} array" if len(inner) == 1 else ("double array" if not value else "mixed array")
    return type(value).__name__


def resolve(specs: Iterable[ParamSpec], given: Mapping[str, Any], node: str = "") -> dict[str, Any]:
    """Validated values of ``specs``: the given value when present, else the default."""
    return {s.name: s.validate(given[s.name], node) if s.name in given else s.default for s in specs}


def positive(value: Any) -> str:
    """a value > 0 (finite)"""
    return "" if 0 < value < float("inf") else "a value > 0 (finite)"


def non_negative(value: Any) -> str:
    """a value >= 0 (finite)"""
    return "" if 0 <= value < float("inf") else "a value >= 0 (finite)"


def unit_interval(value: Any) -> str:
    """a value in [0, 1]"""
    return "" if 0 <= value <= 1 else "a value in [0, 1]"


def open_unit_interval(value: Any) -> str:
    """a value in (0, 1]"""
    return "" if 0 < value <= 1 else "a value in (0, 1]"


LINK_PAIR_RULE = "'link_a link_b' strings (two link names separated by a space)"


def link_pairs(value: Any, key: str) -> tuple[tuple[str, str], ...]:
    """A list of ``"link_a link_b"`` strings (empty strings skipped: ROS's ``[""]`` for none) as link
    pairs (the robot's, the scenario's and the controller's allowed pairs). :class:`ParameterError`
    for parameter ``key`` otherwise, its ``expected`` saying what is wrong (``got [...], expected a
    list of ...`` or ``entry '...', expected ...``: the text the robot's and the scenario's errors quote)."""
    if not isinstance(value, list):
        raise ParameterError(key, value, f"got {value!r}, expected a list of {LINK_PAIR_RULE}")
    pairs = []
    for item in value:
        if item == "":
            continue
        parts = item.split() if isinstance(item, str) else []
        if len(parts) != 2:
            raise ParameterError(key, value, f"entry {item!r}, expected {LINK_PAIR_RULE}")
        pairs.append((parts[0], parts[1]))
    return tuple(pairs)


def params_files(argv: Sequence[str]) -> list[str]:
    """The ``--params-file`` arguments of a ``--ros-args`` command line, in order."""
    files: list[str] = []
    in_ros = False
    for i, arg in enumerate(argv):
        if arg == "--ros-args":
            in_ros = True
        elif arg == "--":
            in_ros = False
        elif in_ros and arg == "--params-file" and i + 1 < len(argv):
            files.append(argv[i + 1])
    return files
