"""QoS profiles with rclpy's names and defaults, and their Cyclone DDS translation.

The translation copies rmw_cyclonedds_cpp's ``create_readwrite_qos``: history and
depth, reliability (blocking time infinite), durability (transient-local also sets
the durability service history), automatic liveliness, autodispose off; and XCDR1
data representation as rmw_cyclonedds_cpp sends.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

from cyclonedds.core import Policy, Qos
from cyclonedds.util import duration


class ReliabilityPolicy(IntEnum):
    """Same names and values as ``rclpy.qos.ReliabilityPolicy``."""

    SYSTEM_DEFAULT = 0
    RELIABLE = 1
    BEST_EFFORT = 2


class DurabilityPolicy(IntEnum):
    """Same names and values as ``rclpy.qos.DurabilityPolicy``."""

    SYSTEM_DEFAULT = 0
    TRANSIENT_LOCAL = 1
    VOLATILE = 2


class HistoryPolicy(IntEnum):
    """Same names and values as ``rclpy.qos.HistoryPolicy``."""

    SYSTEM_DEFAULT = 0
    KEEP_LAST = 1
    KEEP_ALL = 2


@dataclass(frozen=True, kw_only=True)
class QoSProfile:
    """A QoS profile; ``QoSProfile(depth=10)`` is rclpy's default (reliable, volatile)."""

    depth: int = 10
    history: HistoryPolicy = HistoryPolicy.KEEP_LAST
    reliability: ReliabilityPolicy = ReliabilityPolicy.RELIABLE
    durability: DurabilityPolicy = DurabilityPolicy.VOLATILE

    def __post_init__(self) -> None:
        if self.history != HistoryPolicy.KEEP_ALL and self.depth < 1:
            raise ValueError(f"QoSProfile depth must be >= 1 with KEEP_LAST history, got {self.depth}")


#: rclpy's ``qos_profile_sensor_data``: best effort, keep-last 5, volatile.
qos_profile_sensor_data = QoSProfile(depth=5, reliability=ReliabilityPolicy.BEST_EFFORT)
#: rclpy's ``qos_profile_system_default`` as rmw_cyclonedds_cpp resolves it.
qos_profile_system_default = QoSProfile(depth=10)


def as_profile(qos: QoSProfile | int) -> QoSProfile:
    """Accept a profile or a bare history depth (rclpy's shorthand)."""
    if isinstance(qos, QoSProfile):
        return qos
    if isinstance(qos, bool) or not isinstance(qos, int):
        raise TypeError(f"qos must be a QoSProfile or an int depth, got {qos!r}")
    return QoSProfile(depth=qos)


def to_cyclone_qos(profile: QoSProfile) -> Qos:
    """The Cyclone DDS reader/writer QoS for ``profile`` (as rmw_cyclonedds_cpp sets it)."""
    if profile.history == HistoryPolicy.KEEP_ALL:
        history = Policy.History.KeepAll
    else:
        history = Policy.History.KeepLast(depth=profile.depth)
    policies = [
        history,
        Policy.WriterDataLifecycle(autodispose=False),
        Policy.Liveliness.Automatic(lease_duration=duration(infinite=True)),
        Policy.DataRepresentation(use_cdrv0_representation=True),
    ]
    if profile.reliability == ReliabilityPolicy.BEST_EFFORT:
        policies.append(Policy.Reliability.BestEffort)
    else:
        policies.append(Policy.Reliability.Reliable(max_blocking_time=duration(infinite=True)))
    if profile.durability == DurabilityPolicy.TRANSIENT_LOCAL:
        policies.append(Policy.Durability.TransientLocal)
        policies.append(
            Policy.DurabilityService(
                cleanup_delay=0, history=history, max_samples=-1, max_instances=-1,
                max_samples_per_instance=-1,
            )
        )
    else:
        policies.append(Policy.Durability.Volatile)
    return Qos(*policies)
