"""The rclpy backend: ROS 2's own objects, plus two conveniences the nodes rely on.

``Node.declare_parameter(..., description=...)`` builds the ParameterDescriptor, and
``Node.undeclared_overrides()`` lists overrides the node did not declare. Messages
are the real ``sensor_msgs.msg`` etc. classes, gathered in :data:`msgs`.
"""

from __future__ import annotations

import importlib
import types
from typing import Any

import rclpy
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.duration import Duration
from rclpy.exceptions import (
    InvalidParameterTypeException,
    ParameterNotDeclaredException,
)
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.logging import get_logger
from rclpy.node import Node as _RclpyNode
from rclpy.parameter import Parameter
from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
    qos_profile_sensor_data,
)
from rclpy.time import Time
from rclpy.utilities import remove_ros_args

from dualarm_control.ros.catalog import MESSAGE_TYPES

init = rclpy.init
shutdown = rclpy.shutdown
try_shutdown = rclpy.try_shutdown
ok = rclpy.ok
spin = rclpy.spin
spin_once = rclpy.spin_once


class Node(_RclpyNode):
    """rclpy Node with ``description=`` on ``declare_parameter`` and ``undeclared_overrides()``."""

    def declare_parameter(self, name: str, value: Any = None, descriptor: ParameterDescriptor | None = None,
                          ignore_override: bool = False, *, description: str = "") -> Parameter:
        if descriptor is None:
            descriptor = ParameterDescriptor(description=description)
        return super().declare_parameter(name, value, descriptor, ignore_override)

    def undeclared_overrides(self) -> dict[str, Any]:
        """Overrides for this node that it did not declare."""
        overrides = getattr(self, "_parameter_overrides", {})
        return {k: p.value for k, p in overrides.items() if not self.has_parameter(k)}


def _load_msgs() -> types.SimpleNamespace:
    classes: dict[str, Any] = {}
    type_names: dict[type, str] = {}
    for full in MESSAGE_TYPES:
        pkg, _, typ = full.split("/")
        try:
            cls = getattr(importlib.import_module(f"{pkg}.msg"), typ)
        except (ImportError, AttributeError):  # e.g. a package missing from this ROS install
            continue
        classes[typ] = cls
        type_names[cls] = full
    by_name = {v: k for k, v in type_names.items()}

    def msg_type_by_name(name: str) -> type:
        if name in by_name:
            return by_name[name]
        from rosidl_runtime_py.utilities import get_message

        return get_message(name)

    return types.SimpleNamespace(**classes, ROS_TYPE_NAMES=type_names, msg_type_by_name=msg_type_by_name)


msgs = _load_msgs()

__all__ = [
    "DurabilityPolicy",
    "Duration",
    "ExternalShutdownException",
    "HistoryPolicy",
    "InvalidParameterTypeException",
    "Node",
    "Parameter",
    "ParameterNotDeclaredException",
    "QoSProfile",
    "ReliabilityPolicy",
    "SingleThreadedExecutor",
    "Time",
    "get_logger",
    "init",
    "msgs",
    "ok",
    "qos_profile_sensor_data",
    "remove_ros_args",
    "shutdown",
    "spin",
    "spin_once",
    "try_shutdown",
]
