"""Parse ROS 2 command-line arguments (``--ros-args ... [--]``) without ROS.

Supported, with rcl's meaning: ``--params-file F``, ``-p/--param name:=value``
(value read as a YAML scalar or list: ``200.0`` float, ``200`` int, ``true`` bool,
``[1.0, 2.0]`` list, anything else a string), ``-r/--remap [node:]from:=to``
including ``__node``/``__name`` and ``__ns``, ``--log-level [name:=]level``. Logging
and enclave flags are accepted and ignored. Everything outside ``--ros-args``
sections is kept, in order, in :attr:`RosArgs.non_ros_args`.

Parameter files use the ROS layout ``<node>: ros__parameters: {key: value}``; the
node key may be ``/**`` (all nodes), a plain node name (= ``/name``), a fully
qualified ``/ns/node``, nested namespace keys, or a pattern with ``*`` (one name
token) and ``**`` (any number of tokens). Nested parameter maps flatten to dotted
names (``limits.velocity``). Overrides apply in command-line order (later wins),
and inside a file in file order.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from dualarm_control.errors import DualArmError

ParameterValue = Any  # bool | int | float | str | list of one of these

_LOG_LEVELS = ("debug", "info", "warn", "warning", "error", "fatal", "unset")
_IGNORED_FLAGS = {
    "--enable-rosout-logs", "--disable-rosout-logs", "--enable-stdout-logs",
    "--disable-stdout-logs", "--enable-external-lib-logs", "--disable-external-lib-logs",
}
_IGNORED_WITH_VALUE = {"-e", "--enclave", "--log-config-file", "--log-file-name"}


class RosArgsError(DualArmError, ValueError):
    """A ROS argument or parameter file is malformed; the message names the culprit."""


class _Loader(yaml.SafeLoader):
    """YAML loader that also reads ``1e3`` and ``-2E-4`` as floats (YAML 1.2, like rcl)."""


_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(
        r"""^(?:[-+]?(?:[0-9][0-9_]*)\.[0-9_]*(?:[eE][-+]?[0-9]+)?
        |[-+]?(?:[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)
        |\.[0-9_]+(?:[eE][-+][0-9]+)?
        |[-+]?\.(?:inf|Inf|INF)
        |\.(?:nan|NaN|NAN))$""",
        re.VERBOSE,
    ),
    list("-+0123456789."),
)


@dataclass(frozen=True)
class Remap:
    """A remapping rule ``[node:]src:=dst`` (``node`` None = every node)."""

    src: str
    dst: str
    node: str | None = None


@dataclass(frozen=True)
class ParamRule:
    """Parameter overrides for the nodes matching ``node_pattern`` (from a file or ``-p``)."""

    node_pattern: str
    values: dict[str, ParameterValue]
    source: str


@dataclass
class RosArgs:
    """The parsed command line."""

    non_ros_args: list[str] = field(default_factory=list)
    param_rules: list[ParamRule] = field(default_factory=list)
    remaps: list[Remap] = field(default_factory=list)
    params_files: list[Path] = field(default_factory=list)
    log_levels: dict[str, str] = field(default_factory=dict)  # "" = default level

    def node_name_override(self, node_name: str) -> str | None:
        """New node name from ``-r __node:=x`` (or ``__name``), if any applies."""
        return self._special(node_name, ("__node", "__name"))

    def namespace_override(self, node_name: str) -> str | None:
        """New namespace from ``-r __ns:=/ns``, if any applies."""
        ns = self._special(node_name, ("__ns",))
        if ns is not None and not ns.startswith("/"):
            ns = "/" + ns
        return ns

    def topic_remaps(self, node_name: str) -> list[Remap]:
        """Topic remap rules that apply to the node originally named ``node_name``."""
        return [r for r in self.remaps if not r.src.startswith("__") and r.node in (None, node_name)]

    def parameter_overrides(self, fq_node_name: str) -> dict[str, ParameterValue]:
        """All overrides for the node ``/ns/name``, merged in command-line order."""
        merged: dict[str, ParameterValue] = {}
        for rule in self.param_rules:
            if node_pattern_matches(rule.node_pattern, fq_node_name):
                merged.update(rule.values)
        return merged

    def parameter_sources(self, fq_node_name: str) -> dict[str, str]:
        """Where each override for the node came from (file path or ``-p``), for messages."""
        sources: dict[str, str] = {}
        for rule in self.param_rules:
            if node_pattern_matches(rule.node_pattern, fq_node_name):
                sources.update(dict.fromkeys(rule.values, rule.source))
        return sources

    def _special(self, node_name: str, keys: tuple[str, ...]) -> str | None:
        found = None
        for rule in self.remaps:
            if rule.src in keys and rule.node in (None, node_name):
                found = rule.dst
        return found


def node_pattern_matches(pattern: str, fq_node_name: str) -> bool:
    """Whether a params-file node key matches ``/ns/name`` (``*`` one token, ``**`` any)."""
    pat = [tok for tok in pattern.split("/") if tok]
    name = [tok for tok in fq_node_name.split("/") if tok]

    def match(i: int, j: int) -> bool:
        if i == len(pat):
            return j == len(name)
        if pat[i] == "**":
            return any(match(i + 1, k) for k in range(j, len(name) + 1))
        if j == len(name):
            return False
        if pat[i] == "*" or re.fullmatch(re.escape(pat[i]).replace(r"\*", "[^/]*"), name[j]):
            return match(i + 1, j + 1)
        return False

    return match(0, 0)


def parse_value(text: str, what: str = "value") -> ParameterValue:
    """Read a parameter value as rcl does: a YAML scalar or a flat homogeneous list."""
    try:
        value = yaml.load(text, Loader=_Loader) if text.strip() else ""
    except yaml.YAMLError as exc:
        raise RosArgsError(f"{what}: cannot read {text!r} as YAML{_yaml_where(exc)}") from None
    return check_value(value, what)


def _yaml_where(exc: yaml.YAMLError) -> str:
    """`` at line L, column C: problem`` from a PyYAML error, on one line."""
    mark = getattr(exc, "problem_mark", None)
    problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
    context = getattr(exc, "context", None)
    context_mark = getattr(exc, "context_mark", None)
    if context and context_mark is not None:
        context += f" started at line {context_mark.line + 1}"
    where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
    return f"{where}: {problem}" + (f" ({context})" if context else "")


def check_value(value: Any, what: str) -> ParameterValue:
    """Validate a parameter value's type (scalar or homogeneous list); return it."""
    if isinstance(value, (bool, int, float, str)):
        return value
    if isinstance(value, list):
        kinds = {_kind(item, what) for item in value}
        if kinds == {"int", "float"}:
            raise RosArgsError(
                f"{what}: list {value!r} mixes integers and floats; write every item as a float "
                "(e.g. 1.0, not 1)"
            )
        if len(kinds) > 1:
            raise RosArgsError(f"{what}: list {value!r} mixes types {sorted(kinds)}; ROS lists are homogeneous")
        return value
    if value is None:
        raise RosArgsError(f"{what}: empty value (null); give a value")
    raise RosArgsError(f"{what}: unsupported value {value!r} (expected a scalar or a list of scalars)")


def _kind(item: Any, what: str) -> str:
    if isinstance(item, bool):
        return "bool"
    if isinstance(item, int):
        return "int"
    if isinstance(item, float):
        return "float"
    if isinstance(item, str):
        return "str"
    raise RosArgsError(f"{what}: list item {item!r} is not a scalar")


def load_params_file(path: str | Path) -> list[ParamRule]:
    """Read a ROS 2 parameter file into rules, one per node section, in file order."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise RosArgsError(f"--params-file {path}: cannot read: {exc.strerror or exc}") from None
    try:
        doc = yaml.load(text, Loader=_Loader)
    except yaml.YAMLError as exc:
        raise RosArgsError(f"--params-file {path}: malformed YAML{_yaml_where(exc)}") from None
    if doc is None:
        return []
    if not isinstance(doc, dict):
        raise RosArgsError(
            f"--params-file {path}: expected a mapping '<node>: ros__parameters: ...', got {type(doc).__name__}"
        )
    rules: list[ParamRule] = []
    _collect_sections(doc, [], path, rules)
    return rules


def _collect_sections(doc: dict[Any, Any], keys: list[str], path: Path, out: list[ParamRule]) -> None:
    for key, body in doc.items():
        key = str(key)
        where = "/".join([*keys, key])
        if key == "ros__parameters":
            if not keys:
                raise RosArgsError(f"--params-file {path}: 'ros__parameters' needs a node name above it")
            if body is None:
                body = {}
            if not isinstance(body, dict):
                raise RosArgsError(f"--params-file {path}: '{where}' must be a mapping of parameters")
            pattern = "/" + "/".join(k.strip("/") for k in keys)
            values: dict[str, ParameterValue] = {}
            _flatten(body, "", values, f"--params-file {path}: node '{pattern}'")
            out.append(ParamRule(pattern, values, str(path)))
        elif isinstance(body, dict):
            _collect_sections(body, [*keys, key], path, out)
        else:
            raise RosArgsError(
                f"--params-file {path}: '{where}' is not a node section; expected "
                f"'{where}: ros__parameters: {{...}}'"
            )


def _flatten(body: dict[Any, Any], prefix: str, out: dict[str, ParameterValue], what: str) -> None:
    for key, value in body.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            _flatten(value, name + ".", out, what)
        else:
            out[name] = check_value(value, f"{what}, parameter '{name}'")


def _split_assignment(text: str, flag: str) -> tuple[str | None, str, str]:
    """``[node:]name:=value`` -> (node, name, value)."""
    if ":=" not in text:
        raise RosArgsError(f"{flag} {text!r}: expected 'name:=value'")
    lhs, value = text.split(":=", 1)
    node = None
    if ":" in lhs:
        node, lhs = lhs.split(":", 1)
    if not lhs:
        raise RosArgsError(f"{flag} {text!r}: empty name before ':='")
    return node or None, lhs, value


def split_ros_args(argv: list[str] | None) -> tuple[list[str], list[str]]:
    """Split ``argv`` into (non-ROS arguments, tokens of all ``--ros-args`` sections)."""
    plain: list[str] = []
    ros: list[str] = []
    in_ros = False
    for arg in argv or []:
        if arg == "--ros-args":
            in_ros = True
        elif in_ros and arg == "--":
            in_ros = False
        elif in_ros:
            ros.append(arg)
        else:
            plain.append(arg)
    return plain, ros


def parse_ros_args(argv: list[str] | None) -> RosArgs:
    """Parse a full ``argv`` (including the program name, if any) into :class:`RosArgs`."""
    plain, args = split_ros_args(argv)
    result = RosArgs(non_ros_args=plain)
    i = 0
    while i < len(args):
        arg = args[i]
        nxt = args[i + 1] if i + 1 < len(args) else None

        def value_of(flag: str, nxt: str | None = nxt) -> str:
            if nxt is None:
                raise RosArgsError(f"{flag} needs a value")
            return nxt

        if arg in ("-p", "--param"):
            text = value_of(arg)
            node, name, raw = _split_assignment(text, arg)
            value = parse_value(raw, f"{arg} {name}")
            result.param_rules.append(ParamRule(f"/{node}" if node else "/**", {name: value}, f"{arg} {text}"))
            i += 2
        elif arg == "--params-file":
            path = Path(value_of(arg))
            result.params_files.append(path)
            result.param_rules.extend(load_params_file(path))
            i += 2
        elif arg in ("-r", "--remap"):
            text = value_of(arg)
            node, src, dst = _split_assignment(text, arg)
            if not dst:
                raise RosArgsError(f"{arg} {text!r}: empty target after ':='")
            result.remaps.append(Remap(src, dst, node))
            i += 2
        elif arg == "--log-level":
            text = value_of(arg)
            name, level = ("", text) if ":=" not in text else text.split(":=", 1)
            if level.lower() not in _LOG_LEVELS:
                raise RosArgsError(f"--log-level {text!r}: level must be one of {', '.join(_LOG_LEVELS)}")
            result.log_levels[name] = level.lower()
            i += 2
        elif arg in _IGNORED_FLAGS:
            i += 1
        elif arg in _IGNORED_WITH_VALUE:
            value_of(arg)
            i += 2
        else:
            raise RosArgsError(
                f"unknown ROS argument {arg!r} (supported: --params-file, -p, -r, --log-level; "
                "end ROS arguments with '--')"
            )
    return result


def remove_ros_args(argv: list[str]) -> list[str]:
    """``argv`` without its ``--ros-args`` sections (like ``rclpy.utilities.remove_ros_args``)."""
    return split_ros_args(argv)[0]
