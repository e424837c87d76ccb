"""The cell a bag was recorded on (issue 40): its nodes' parameters and its hardware profile's streams.

Each node publishes its parameters, latched, on ``/dualarm/cell`` (:mod:`dualarm_control.ros.cell_topic`)
and every bag keeps them. From the controller's, :func:`recorded_topics` gives the hardware profile's
topics (docs/hardware.md): its joint-state topics and its command outputs. A bag without them (recorded
before, or by a tool that did not keep the topic) is read on the default profile (``/joint_states``,
``/velocity_controller/commands``), as before.

:class:`ProfileStreams` turns the profile's messages into what a report reads, in the robot
description's joint order:

* joint states: one topic's messages as they are; several topics' (``/left/joint_states`` and
  ``/right/joint_states``) assembled into consistent states by the controller's own
  :class:`~dualarm_control.hardware.StateAssembler` (every topic sampled since the last state, stamps
  within the profile's tolerance), velocities alike;
* commands: the k-th message of every output make cycle k's command (the controller publishes every
  output once per cycle, in order); a velocity output's values as they are; a position output's as the
  velocity that moves the position reference to them in one control period, the reference starting at
  the first state and then the last command: what the simulator's joint position controller does
  (``dualarm_sim/ports.py: CommandMerger``).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import yaml

from dualarm_control.arrays import FloatArray
from dualarm_control.errors import DualArmError, InputRejected
from dualarm_control.hardware import (
    HardwareProfile,
    OutputSpec,
    StateAssembler,
    StateSample,
    profile_from_values,
    profile_parameters,
)
from dualarm_control.joint_map import KEY as JOINT_MAP_KEY
from dualarm_control.joint_map import JointMap, parse_joint_map
from dualarm_control.params import parse_params_text, resolve
from dualarm_control.ros.cell_topic import CELL_TOPIC
from dualarm_control.ros.convert import stamp_ns

CONTROLLER = "controller_node"
DEFAULT_PERIOD_S = 0.005


def cell_parameters(documents: Iterable[str], where: str = CELL_TOPIC) -> dict[str, dict[str, Any]]:
    """Per node, the flat parameters of its first document on ``/dualarm/cell`` (``where`` names the
    source in errors); a document that is not a parameter file is skipped."""
    out: dict[str, dict[str, Any]] = {}
    for text in documents:
        try:
            nodes = yaml.safe_load(text)
        except yaml.YAMLError:
            continue
        if not isinstance(nodes, Mapping):
            continue
        for node in nodes:
            if isinstance(node, str) and node not in out:
                try:
                    out[node] = parse_params_text(text, node, source=where)
                except DualArmError:
                    continue
    return out


@dataclass(frozen=True)
class RecordedTopics:
    """The hardware profile's topics as the controller ran them (its resolved ``hardware.*`` values)."""

    values: Mapping[str, Any]
    joint_states: tuple[str, ...]
    outputs: tuple[str, ...]
    period: float

    def profile(self, joint_names: Sequence[str]) -> HardwareProfile:
        """The validated profile on a robot with ``joint_names`` (DualArmError if it does not fit it)."""
        return profile_from_values(self.values, joint_names, CONTROLLER)

    def joint_map(self, joint_names: Sequence[str]) -> JointMap:
        """The profile's ``hardware.joint_map`` on a robot with ``joint_names`` (empty for bags without one)."""
        return parse_joint_map(self.values.get(JOINT_MAP_KEY, [""]), joint_names, f"{CONTROLLER}.{JOINT_MAP_KEY}")


def recorded_topics(controller: Mapping[str, Any]) -> RecordedTopics:
    """The profile of the controller's parameters ``controller`` (flat, as on ``/dualarm/cell``; {}:
    the default profile)."""
    given = {k: v for k, v in controller.items() if k.startswith("hardware.")}
    values = resolve(profile_parameters(given), given, CONTROLLER)
    outputs = tuple(values[f"hardware.{name}.topic"] for name in values["hardware.outputs"] if name)
    period = controller.get("control_period", DEFAULT_PERIOD_S)
    return RecordedTopics(values, tuple(t for t in values["hardware.joint_states"] if t), outputs,
                          float(period) if isinstance(period, (int, float)) else DEFAULT_PERIOD_S)


@dataclass(frozen=True)
class AssembledState:
    """A joint state assembled from several topics: positions and velocities in the description's order
    (velocities empty when a topic's messages carry none), as a JointState's fields."""

    position: FloatArray
    velocity: FloatArray


State = tuple[int, int, list[str], Any]
"""(receive ns, header stamp ns, joint names, a message with ``position`` and ``velocity``)."""


@dataclass
class ProfileStreams:
    """The messages of a profile's joint-state and command topics (receive ns, message), read back in
    the description's order (module docstring)."""

    topics: RecordedTopics
    raw: dict[str, list[tuple[int, Any]]] = field(default_factory=dict)
    _states: dict[tuple[str, ...], list[State]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for topic in (*self.topics.joint_states, *self.topics.outputs):
            self.raw.setdefault(topic, [])

    def add(self, topic: str, t: int, msg: Any) -> bool:
        """Keep ``msg`` if ``topic`` is one of the profile's; whether it was."""
        if topic not in self.raw:
            return False
        self.raw[topic].append((t, msg))
        return True

    def states(self, joint_names: Sequence[str]) -> list[State]:
        """The joint states: one topic's messages as they are, in receive order; several topics' assembled
        (names ``joint_names``, the description's order) in the order of their stamps, so that the samples of
        one stamp meet however the recorder received them (a starved recorder takes one topic's backlog,
        then the other's: in receive order all but the last of those stamps were lost)."""
        key = tuple(joint_names)
        if key not in self._states:
            self._states[key] = self._assemble(key)
        return self._states[key]

    def _assemble(self, joint_names: tuple[str, ...]) -> list[State]:
        topics = self.topics.joint_states
        names = self.topics.joint_map(joint_names)  # the hardware's names back to the description's
        if len(topics) == 1:
            return [(t, stamp_ns(m.header.stamp), list(names.description(m.name)), m) for t, m in self.raw[topics[0]]]
        merged = sorted(((t, i, topic, m) for topic in topics for i, (t, m) in enumerate(self.raw[topic])),
                        key=lambda item: (stamp_ns(item[3].header.stamp), item[0], item[1]))
        index = {name: i for i, name in enumerate(names.hardware(joint_names))}
        n = len(joint_names)
        assembler = StateAssembler(topics, n, round(float(self.topics.values["hardware.stamp_tolerance"]) * 1e9))
        velocity: dict[str, tuple[np.ndarray, FloatArray | None]] = {}
        out: list[State] = []
        for t, _, topic, m in merged:
            mine = [k for k, name in enumerate(m.name) if name in index]
            idx = np.array([index[m.name[k]] for k in mine], dtype=int)
            positions = np.asarray(m.position, dtype=float)
            velocity[topic] = (idx, np.asarray(m.velocity, dtype=float)[mine] if len(m.velocity) == len(m.name)
                               else None)
            got = assembler.put(topic, StateSample(stamp_ns(m.header.stamp), t, idx, positions[mine]))
            if got is None:
                continue
            qd: FloatArray = np.zeros(n)
            for vidx, values in velocity.values():
                if values is None:
                    qd = np.zeros(0)
                    break
                qd[vidx] = values
            out.append((t, got[0], list(joint_names), AssembledState(got[1], qd)))
        return out

    def commands(self, joint_names: Sequence[str]) -> list[tuple[int, FloatArray]]:
        """Cycle by cycle, (receive ns of its last output message, joint velocities [rad/s] in the
        order of ``joint_names``); as many cycles as the output that sent the fewest messages.
        DualArmError when the profile does not fit the joints or a message has the wrong width."""
        profile = self.topics.profile(joint_names)
        per_output = [self.raw[o.topic] for o in profile.outputs]
        count = min((len(messages) for messages in per_output), default=0)
        reference: FloatArray | None = None
        if any(o.position for o in profile.outputs):
            states = self.states(joint_names)
            if states:
                reference = _ordered(states[0], joint_names).copy()
        out: list[tuple[int, FloatArray]] = []
        for k in range(count):
            row: FloatArray = np.zeros(len(joint_names))
            t = 0
            for o, idx, messages in zip(profile.outputs, profile.indices(joint_names), per_output, strict=True):
                stamp, msg = messages[k]
                t = max(t, stamp)
                values = command_values(o, msg)
                if len(values) != len(idx):
                    raise DualArmError(f"{o.topic}: a command of {len(values)} values for the {len(idx)} joints of "
                                       f"output {o.name}")
                if o.position:
                    if reference is None:  # no joint state before the commands: the velocity is unknown
                        row[idx] = np.nan
                        continue
                    row[idx] = (values - reference[idx]) / self.topics.period
                    reference[idx] = values
                else:
                    row[idx] = values
            out.append((t, row))
        return out


def command_values(output: OutputSpec, msg: Any) -> FloatArray:
    """A command message's values in the output's joint order (its registered message type's
    :meth:`~dualarm_control.outputs.OutputType.decode`: a Float64MultiArray's data, a one-point
    JointTrajectory's positions or velocities by joint name, ...); DualArmError naming the topic if the
    message is unusable."""
    try:
        return output.kind.decode(output, msg)
    except InputRejected as exc:
        raise DualArmError(f"{output.topic}: {exc.reason}") from exc


def _ordered(state: State, joint_names: Sequence[str]) -> FloatArray:
    """A state's positions in the order of ``joint_names``."""
    _, _, names, msg = state
    position = np.asarray(msg.position, dtype=float)
    return np.array([position[names.index(j)] for j in joint_names], dtype=float)
