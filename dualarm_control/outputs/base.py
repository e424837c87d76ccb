"""The command output message types (issue 39): the protocol each type implements, and the one registry.

A hardware profile's output (:class:`OutputSpec`, docs/hardware.md) names its message type by the key
of its ``hardware.<name>.message`` parameter; :func:`output_type` gives the registered
:class:`OutputType` of a key, which knows the ROS message type, how the controller encodes a cycle's
command for it (:meth:`OutputType.encode`) and how a receiver (the simulator's command ports, the bag
reader) reads the values back (:meth:`OutputType.decode`, :meth:`OutputType.decode_bytes`). A new type
is a subclass in a file of its own, registered by ``@register`` (docs/outputs.md).

ROS-free: the rclpy message class is imported when asked for (:meth:`OutputType.message_class`).
"""

from __future__ import annotations

import functools
import importlib
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any, ClassVar, TypeVar

import numpy as np

from dualarm_control.arrays import FloatArray
from dualarm_control.errors import InputRejected, UnknownOutputError
from dualarm_control.registry import Registry
from dualarm_control.ros.cdr import CdrError
from dualarm_control.ros.checks import finite, joint_indices


@dataclass(frozen=True)
class OutputSpec:
    """One command output: ``joints`` (names) published on ``topic`` as ``message`` (a key of the
    registry, :func:`output_names`) for ``interface`` (velocity [rad/s] or position [rad])."""

    name: str
    topic: str
    message: str
    interface: str
    joints: tuple[str, ...]

    @property
    def position(self) -> bool:
        return self.interface == "position"

    @property
    def kind(self) -> OutputType:
        """The registered message type of this output (UnknownOutputError names the known ones)."""
        return output_type(self.message)


class OutputType(ABC):
    """One command message type: its registry key, ROS type, encoding and decoding.

    Values are always those of one output (``spec``): (len(spec.joints),) in ``spec.joints``' order,
    velocities [rad/s] or positions [rad] per ``spec.interface``. Stateless: one instance serves
    every output of its type.
    """

    key: ClassVar[str]
    """The ``hardware.<name>.message`` value that selects this type (what profiles and bags carry)."""
    type_name: ClassVar[str]
    """The ROS message type, ``package/msg/Name`` (what ``ros2 topic info`` shows)."""

    def message_class(self) -> Any:
        """The rclpy message class of :attr:`type_name`, imported now (the package stays ROS-free)."""
        package, _, name = self.type_name.split("/")
        return getattr(importlib.import_module(f"{package}.msg"), name)

    @abstractmethod
    def encode(self, spec: OutputSpec, values: FloatArray, period: float) -> bytes:
        """One cycle's command as the message's CDR bytes (``Publisher.publish(bytes)``): ``values``
        (len(spec.joints),) [rad/s or rad], ``period`` the control period [s]."""

    def message(self, spec: OutputSpec, values: FloatArray, period: float) -> Any:
        """The rclpy message of :meth:`encode` (for tools and tests; the nodes publish the bytes)."""
        from rclpy.serialization import deserialize_message

        return deserialize_message(self.encode(spec, values, period), self.message_class())

    @abstractmethod
    def decode(self, spec: OutputSpec, msg: Any) -> FloatArray:
        """A received message (rclpy's, or any object with its fields: a rosbags message) -> its values
        (k,) in ``spec.joints``' order [rad/s or rad]; raises :class:`~dualarm_control.errors.InputRejected`
        with the reason if it is unusable. The values' count and finiteness are checked by the caller
        (:class:`CommandDecoder`)."""

    def decode_bytes(self, spec: OutputSpec, data: bytes) -> FloatArray:
        """As :meth:`decode` from the CDR bytes (the fast path); raises
        :class:`~dualarm_control.ros.cdr.CdrError` for what it does not read, and then the receiver
        decodes the rclpy message. This default reads nothing: rclpy decodes every message."""
        raise CdrError(f"{self.type_name} is decoded by rclpy")


T = TypeVar("T", bound=OutputType)
OUTPUTS: Registry[OutputType] = Registry("output message type", UnknownOutputError)


def register(cls: type[T]) -> type[T]:
    """Class decorator: an instance of ``cls`` serves the outputs whose message is ``cls.key``."""
    if cls.key in OUTPUTS:
        raise ValueError(f"output message type {cls.key!r} registered twice")
    OUTPUTS.add(cls.key, cls())
    return cls


def unregister(key: str) -> OutputType:
    """Remove the type registered under ``key`` and return it (UnknownOutputError otherwise): for a
    type registered for a while only, e.g. a test's."""
    return OUTPUTS.remove(key)


def output_names() -> list[str]:
    """The registered keys, sorted (the valid values of ``hardware.<name>.message``)."""
    return OUTPUTS.names()


def output_type(key: str) -> OutputType:
    """The type registered under ``key``; UnknownOutputError names the known keys."""
    return OUTPUTS.get(key)


@functools.lru_cache(maxsize=64)
def joint_order(joints: tuple[str, ...]) -> dict[str, int]:
    """Name -> index in ``joints`` (cached: an output's joints repeat every cycle)."""
    return {name: i for i, name in enumerate(joints)}


def by_name(spec: OutputSpec, names: Any, values: Any, what: str) -> FloatArray:
    """``values`` (one per name of ``names``) in ``spec.joints``' order, matched by name (extra names
    ignored); :class:`~dualarm_control.errors.InputRejected` naming ``what`` for a missing or duplicated
    joint, or not one value per name."""
    idx = joint_indices(list(names), joint_order(spec.joints), what)
    array = np.asarray(values, dtype=float)
    if array.shape != (len(names),):
        raise InputRejected(f"{what} with {array.size} {spec.interface}s for {len(names)} joints rejected",
                            spec.interface, array)
    return array[idx]


def check_command(values: FloatArray, size: int) -> FloatArray:
    """A copy of ``values`` if it is (size,) and finite; else :class:`~dualarm_control.errors.InputRejected`
    saying why the command is rejected (``value``: the values)."""
    if values.shape != (size,):
        raise InputRejected(f"command with {values.size} values rejected: expected {size}", "data", values)
    if not finite(values):
        raise InputRejected(f"command with NaN or inf at indices {np.flatnonzero(~np.isfinite(values))[:5].tolist()}"
                            " rejected", "data", values)
    return values.copy()


class CommandDecoder:
    """The commands of one output as a receiver takes them (a
    :class:`~dualarm_control.ros.inputs.Decoder`: the simulator's command ports): the values
    (len(spec.joints),) in the output's joint order [rad/s or rad], checked (count, finite); an unusable
    command raises :class:`~dualarm_control.errors.InputRejected`. Refuses an unregistered message type
    (UnknownOutputError)."""

    def __init__(self, spec: OutputSpec) -> None:
        self.spec = spec
        self.kind = spec.kind
        self.size = len(spec.joints)

    def from_bytes(self, data: bytes) -> FloatArray:
        return check_command(self.kind.decode_bytes(self.spec, data), self.size)

    def from_message(self, msg: Any) -> FloatArray:
        return check_command(self.kind.decode(self.spec, msg), self.size)
