"""A hardware profile on the wire (issue 29, :mod:`dualarm_control.hardware`): the joint-state topics in,
the command outputs out.

* :class:`JointStates` subscribes every joint-state topic of the profile (matched by name) and hands
  over each consistent state of both arms (:class:`~dualarm_control.hardware.StateAssembler`).
* :class:`CommandSink` sends a cycle's joint velocities (the description's order) to every output of
  the profile in one call: each output its joints, in its order, encoded by its registered message
  type (:mod:`dualarm_control.outputs`: Float64MultiArray, a one-point JointTrajectory, ...), as
  velocities or as integrated positions (:class:`~dualarm_control.hardware.PositionIntegrator`).
"""

from __future__ import annotations

import functools
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from dualarm_control.errors import InputRejected
from dualarm_control.hardware import (
    HARDWARE_PARAMETERS,
    HardwareProfile,
    OutputSpec,
    PositionIntegrator,
    StateAssembler,
    StateSample,
    TopicView,
    profile_parameters,
    waiting_reason,
)
from dualarm_control.outputs import OutputType
from dualarm_control.params import ParamSpec
from dualarm_control.ros import convert
from dualarm_control.ros.inputs import subscribe_checked, unsubscribe
from dualarm_control.ros.local_bus import LocalBus, local_publisher


def declare_with_profile(node: Any, specs: Sequence[ParamSpec]) -> dict[str, Any]:
    """Declare ``specs`` (which hold :data:`~dualarm_control.hardware.HARDWARE_PARAMETERS`) and the
    parameters of every command output ``hardware.outputs`` names (its value from the node's overrides:
    the outputs' keys depend on it), in one call; the validated values."""
    from dualarm_control.ros.node import declare

    overrides = getattr(node, "_parameter_overrides", {})
    key = HARDWARE_PARAMETERS[0].name
    given = {key: overrides[key].value} if key in overrides else {}
    return declare(node, [*specs, *profile_parameters(given)[len(HARDWARE_PARAMETERS):]])


OnState = Callable[[int, np.ndarray, int], None]
"""(stamp [ns], positions in the description's order [rad], receipt monotonic [ns])."""


class JointStates:
    """The profile's joint-state subscriptions; ``on_state`` per consistent state, ``on_reject(stamp,
    reason)`` per unusable sample, ``on_malformed(reason)`` per undecodable one."""

    def __init__(self, node: Any, profile: HardwareProfile, joint_names: Sequence[str], qos: Any,
                 on_state: OnState, on_reject: Callable[[int, str], None], on_malformed: Callable[[str], None],
                 bus: LocalBus | None = None) -> None:
        from sensor_msgs.msg import JointState

        self.node = node
        self.joint_names = tuple(joint_names)
        self.joint_map = profile.joint_map
        topics = profile.joint_states
        self.delivered = dict.fromkeys(topics, 0)
        self.rejection = dict.fromkeys(topics, "")
        self.assembler = StateAssembler(topics, len(joint_names), round(profile.stamp_tolerance * 1e9))
        self.on_state, self.on_reject = on_state, on_reject
        order = {name: i for i, name in enumerate(profile.hardware_names(joint_names))}  # matched by hardware name
        self.subscriptions = []
        self.decoders: dict[str, convert.JointStateInput] = {}
        partial = len(topics) > 1
        for topic in topics:
            make = functools.partial(convert.JointStateInput, order, partial=partial)
            # nodes of one process reading the same joints decode each sample once (LocalBus.shared)
            self.decoders[topic] = decoder = (bus.shared(("joint_states", topic, tuple(order.items()), partial), make)
                                              if bus is not None and bus.carries(topic) else make())
            self.subscriptions.append(subscribe_checked(
                node, JointState, topic, self.receiver(topic, decoder), qos, self.malformed(topic, on_malformed),
                decoder, bus, self.rejecter(topic)))

    def receiver(self, topic: str, decoder: convert.JointStateInput) -> Callable[[Any], None]:
        def receive(sample: tuple[int, tuple[np.ndarray, np.ndarray]]) -> None:
            stamp, decoded = sample
            self.delivered[topic] += 1
            now = time.monotonic_ns()
            self.rejection[topic] = ""
            state = self.assembler.put(topic, StateSample(stamp, now, decoder.present, decoded[0]))
            if state is not None:
                self.on_state(state[0], state[1], now)
        return receive

    def rejecter(self, topic: str) -> Callable[[InputRejected], None]:
        """A sample of ``topic`` its decoder rejected: counted, noted for the topic, reported at its stamp."""
        several = len(self.assembler.topics) > 1

        def reject(exc: InputRejected) -> None:
            self.delivered[topic] += 1
            self.rejection[topic] = exc.reason
            self.on_reject(exc.stamp or 0, f"{topic}: {exc.reason}" if several else exc.reason)
        return reject

    def malformed(self, topic: str, on_malformed: Callable[[str], None]) -> Callable[[str], None]:
        def note(reason: str) -> None:
            self.delivered[topic] += 1
            self.rejection[topic] = reason
            on_malformed(reason)
        return note

    def names_seen(self) -> dict[str, tuple[str, ...]]:
        """Per joint-state topic that delivered a message, the joint names of its last one."""
        return {t: d.names for t, d in self.decoders.items() if d.names is not None}

    def views(self) -> list[TopicView]:
        """Each joint-state topic as the graph and this node see it (its publishers: node and type)."""
        return [TopicView(t, tuple(f"{i.node_namespace.rstrip('/')}/{i.node_name} "
                                   f"[{i.topic_type}]" for i in self.node.get_publishers_info_by_topic(t)),
                          self.delivered[t], self.rejection[t]) for t in self.assembler.topics]

    def waiting_reason(self) -> str:
        """Why no consistent state has come (:func:`~dualarm_control.hardware.waiting_reason`); '' if
        nothing explains it."""
        return waiting_reason(self.views(), self.assembler, self.joint_names, self.joint_map)

    def close(self) -> None:
        for sub in self.subscriptions:
            unsubscribe(self.node, sub)
        self.subscriptions = []


class CommandSink:
    """Every command output of ``profile``; :meth:`send` publishes one cycle's command on all of them."""

    def __init__(self, node: Any, profile: HardwareProfile, joint_names: Sequence[str], limits: tuple[
                 np.ndarray, np.ndarray, np.ndarray], period: float, qos: Any, bus: LocalBus | None = None) -> None:
        self.period = period
        self.outputs: list[tuple[OutputSpec, np.ndarray, Any, OutputType]] = []
        for spec, idx in zip(profile.outputs, profile.indices(joint_names)):
            kind = spec.kind
            pub = node.create_publisher(kind.message_class(), spec.topic, qos)
            self.outputs.append((spec, idx, local_publisher(bus, pub, spec.topic), kind))
        self.integrator = PositionIntegrator(*limits, period)
        self.positions = any(spec.position for spec, _, _, _ in self.outputs)
        self.measured: np.ndarray | None = None

    def measure(self, q: np.ndarray) -> None:
        """The measured positions [rad] (description order) the next command is integrated from."""
        self.measured = q

    def send(self, velocities: np.ndarray, safe: bool) -> None:
        """One cycle's command on every output: ``velocities`` [rad/s] (description order); ``safe``: a
        safe stop (velocity outputs: zero; position outputs: hold the measured position, and the next
        cycle integrates from the measurement). Position outputs send nothing before a measurement."""
        positions = None
        if self.positions and self.measured is not None:
            positions = (self.integrator.hold(self.measured) if safe
                         else self.integrator.command(velocities, self.measured))
        for spec, idx, pub, kind in self.outputs:
            values = positions if spec.position else velocities
            if values is None:
                continue
            pub.publish(kind.encode(spec, values[idx], self.period))

    def get_subscription_count(self) -> int:
        """The fewest subscriptions matched on one output (0: some output has no reader)."""
        return min(pub.get_subscription_count() for _, _, pub, _ in self.outputs)
