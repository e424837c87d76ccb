"""Time, Duration and Clock with the parts of rclpy's API the nodes use.

The clock is ROS time = system (wall) time in nanoseconds since the epoch;
``use_sim_time`` is not supported by the Cyclone backend.
"""

from __future__ import annotations

import time as _time
from dataclasses import dataclass
from typing import Any

from dualarm_control.ros import msgs

_NS = 1_000_000_000


@dataclass(frozen=True, order=True)
class Duration:
    """A signed span of time in nanoseconds (``rclpy.duration.Duration``)."""

    nanoseconds: int = 0

    def __init__(self, *, seconds: float = 0, nanoseconds: int = 0) -> None:
        object.__setattr__(self, "nanoseconds", round(seconds * _NS) + int(nanoseconds))

    def to_msg(self) -> msgs.Duration:
        """builtin_interfaces/Duration (nanosec is always in [0, 1e9))."""
        sec, nanosec = divmod(self.nanoseconds, _NS)
        return msgs.Duration(sec=sec, nanosec=nanosec)

    @classmethod
    def from_msg(cls, msg: Any) -> Duration:
        """From a builtin_interfaces/Duration."""
        return cls(nanoseconds=int(msg.sec) * _NS + int(msg.nanosec))


@dataclass(frozen=True, order=True)
class Time:
    """A point in ROS time, nanoseconds since the epoch (``rclpy.time.Time``)."""

    nanoseconds: int = 0

    def __init__(self, *, seconds: float = 0, nanoseconds: int = 0) -> None:
        total = round(seconds * _NS) + int(nanoseconds)
        if total < 0:
            raise ValueError(f"Time must be non-negative, got {total} ns")
        object.__setattr__(self, "nanoseconds", total)

    def seconds_nanoseconds(self) -> tuple[int, int]:
        """(whole seconds, remaining nanoseconds)."""
        sec, nanosec = divmod(self.nanoseconds, _NS)
        return sec, nanosec

    def to_msg(self) -> msgs.Time:
        """builtin_interfaces/Time for a header stamp."""
        sec, nanosec = self.seconds_nanoseconds()
        return msgs.Time(sec=sec, nanosec=nanosec)

    @classmethod
    def from_msg(cls, msg: Any) -> Time:
        """From a builtin_interfaces/Time."""
        return cls(nanoseconds=int(msg.sec) * _NS + int(msg.nanosec))

    def __add__(self, other: Duration) -> Time:
        if not isinstance(other, Duration):
            return NotImplemented
        return Time(nanoseconds=self.nanoseconds + other.nanoseconds)

    def __sub__(self, other: Time | Duration) -> Any:
        if isinstance(other, Time):
            return Duration(nanoseconds=self.nanoseconds - other.nanoseconds)
        if isinstance(other, Duration):
            return Time(nanoseconds=self.nanoseconds - other.nanoseconds)
        return NotImplemented


class Clock:
    """ROS time source of a node: the system clock."""

    def now(self) -> Time:
        """Current time."""
        return Time(nanoseconds=_time.time_ns())
