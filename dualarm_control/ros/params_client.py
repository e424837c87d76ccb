"""``dualarm param list|get|set|describe``: a running node's parameters through its parameter
services (rcl_interfaces), as ``ros2 param`` does, with rclpy's AsyncParameterClient.

Values given to ``set`` are read as YAML, like ``ros2 param set``: ``10.0`` is a double,
``10`` an integer, ``true`` a bool, anything else a string.

Each verb is a new process, so a new DDS participant that must discover the node first: it
polls for the node's parameter services up to ``timeout`` (default
:data:`~dualarm_control.ros.node.DISCOVERY_TIMEOUT_S`) and answers as soon as they are there,
then waits as long for the node's answer.
"""

from __future__ import annotations

import time
from typing import Any

import yaml

from dualarm_control.errors import DualArmError
from dualarm_control.ros.node import DISCOVERY_TIMEOUT_S, tool_node


class ParamClientError(DualArmError):
    """The node is not there, or a parameter call failed or was refused."""


def yaml_value(text: str) -> Any:
    """A command-line value as ``ros2 param set`` reads it (YAML scalar or list)."""
    try:
        value = yaml.safe_load(text)
    except yaml.YAMLError:
        return text
    return text if value is None or isinstance(value, dict) else value


def _call(executor: Any, future: Any, stop: Any, what: str, timeout: float) -> Any:
    end = time.monotonic() + timeout
    while not future.done():
        if stop.signal is not None or time.monotonic() > end:
            raise ParamClientError(f"{what}: no answer within {timeout:g} s")
        executor.spin_once(timeout_sec=0.05)
    return future.result()


def _client(node: Any, executor: Any, stop: Any, target: str, timeout: float) -> Any:
    from rclpy.parameter_client import AsyncParameterClient

    client = AsyncParameterClient(node, target)
    end = time.monotonic() + timeout
    while not client.services_are_ready():
        if stop.signal is not None or time.monotonic() > end:
            raise ParamClientError(f"node '{target}' not found (no parameter services within {timeout:g} s)")
        executor.spin_once(timeout_sec=0.05)
    return client


def list_parameters(target: str, timeout: float = DISCOVERY_TIMEOUT_S) -> list[str]:
    """Names of the parameters of node ``target`` (``/ns/name``), sorted."""
    with tool_node("_dualarm_param") as (node, executor, stop):
        client = _client(node, executor, stop, target, timeout)
        result = _call(executor, client.list_parameters(), stop, f"list {target}", timeout)
        return sorted(result.result.names)


def get_parameter(target: str, name: str, timeout: float = DISCOVERY_TIMEOUT_S) -> Any:
    """The value of parameter ``name`` of node ``target``."""
    from rclpy.parameter import parameter_value_to_python

    with tool_node("_dualarm_param") as (node, executor, stop):
        client = _client(node, executor, stop, target, timeout)
        names = _call(executor, client.list_parameters(), stop, f"list {target}", timeout).result.names
        if name not in names:
            raise ParamClientError(f"parameter '{name}' is not set on {target}")
        result = _call(executor, client.get_parameters([name]), stop, f"get {target} {name}", timeout)
        return parameter_value_to_python(result.values[0])


def set_parameter(target: str, name: str, value: Any, timeout: float = DISCOVERY_TIMEOUT_S) -> str:
    """Set parameter ``name`` of node ``target``; returns the node's answer, raises if refused."""
    from rclpy.parameter import Parameter

    with tool_node("_dualarm_param") as (node, executor, stop):
        client = _client(node, executor, stop, target, timeout)
        result = _call(executor, client.set_parameters([Parameter(name, value=value)]), stop,
                       f"set {target} {name}", timeout)
        answer = result.results[0]
        if not answer.successful:
            raise ParamClientError(f"setting parameter '{name}' to {value!r} refused by {target}: {answer.reason}")
        return "Set parameter successful"


def describe_parameter(target: str, name: str, timeout: float = DISCOVERY_TIMEOUT_S) -> str:
    """Type, description, constraints and read-only flag of ``name`` (``ros2 param describe``)."""
    from rcl_interfaces.msg import ParameterType

    types = {v: k.removeprefix("PARAMETER_").lower() for k, v in vars(ParameterType).items()
             if k.startswith("PARAMETER_")}
    with tool_node("_dualarm_param") as (node, executor, stop):
        client = _client(node, executor, stop, target, timeout)
        result = _call(executor, client.describe_parameters([name]), stop, f"describe {target} {name}", timeout)
        d = result.descriptors[0]
        lines = [f"Parameter name: {name}", f"  Type: {types.get(d.type, d.type)}",
                 f"  Description: {d.description}"]
        if d.additional_constraints:
            lines.append(f"  Constraints: {d.additional_constraints}")
        if d.read_only:
            lines.append("  Read only: true")
        return "\n".join(lines)
