"""Hardware profiles (issue 29): where the controller's commands go and where joint states come from.

A profile is ROS-style parameters under ``hardware.`` (one parser, :func:`load_profile`, for the
nodes and ``dualarm hardware check``)::

    hardware:
      robot: lwr4_cell                        # the cell's robot description (dualarm_control/cell_robot.py)
      joint_map: ["left_joint_1 lbr_left_A1", ...]   # description name -> hardware name (joint_map.py)
      outputs: [left_arm, right_arm]          # names of the command outputs
      left_arm:
        topic: /left/forward_position_controller/commands
        message: float64_multi_array          # or joint_trajectory (one point), any registered type
        interface: position                   # or velocity
        joints: [lbr_left_A1, ...]            # any subset and order of the joints (hardware names)
      right_arm: {...}
      joint_states: [/left/joint_states, /right/joint_states]
      stamp_tolerance: 0.0025                 # [s] stamps of one consistent state differ by at most this

An output's ``message`` is a key of the output registry (:mod:`dualarm_control.outputs`,
docs/outputs.md); an unknown one is refused naming the known ones. An output's ``topic`` defaults to ``/<name>/commands``, ``message`` to ``float64_multi_array``,
``interface`` to ``velocity``, ``joints`` to every joint of the description in its order. Every
joint of the description is commanded by exactly one output. The default profile (no
``hardware.`` keys) is one velocity output on ``/velocity_controller/commands`` with the
description's joints in order and ``/joint_states``: the simulator's graph.

Position outputs (:func:`position_command`) are integrated from the measured positions (at start
and after every safe stop), clamped to the joint limits and to one cycle at the velocity limit
around the measured position. ROS-free.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from dualarm_control.arrays import FloatArray
from dualarm_control.errors import ParameterError
from dualarm_control.joint_map import (
    IDENTITY,
    JointMap,
    joint_map_entries,
    parse_joint_map,
)
from dualarm_control.outputs import OutputSpec, output_names
from dualarm_control.params import ParamSpec, non_negative, positive, resolve

DEFAULT_MESSAGE = "float64_multi_array"
INTERFACES = ("velocity", "position")
DEFAULT_OUTPUT = "velocity_controller"


def _topic_list(value: Any) -> str:
    """absolute topic names ('/...'), at least one, no duplicates"""
    topics = [v for v in value if v]
    if not topics or any(not t.startswith("/") for t in topics) or len(set(topics)) != len(topics):
        return "absolute topic names ('/...'), at least one, no duplicates"
    return ""


RESERVED = ("outputs", "joint_states", "stamp_tolerance", "startup_check", "robot", "joint_map")


def _output_names(value: Any) -> str:
    """output names (letters, digits, '_'; not outputs, joint_states, stamp_tolerance, startup_check, robot,
    joint_map), at least one, no duplicates"""
    names = [v for v in value if v]
    if (not names or len(set(names)) != len(names) or not all(n.replace("_", "").isalnum() for n in names)
            or set(names) & set(RESERVED)):
        return f"output names (letters, digits, '_'; not {', '.join(RESERVED)}), at least one, no duplicates"
    return ""


HARDWARE_PARAMETERS = (
    ParamSpec("hardware.outputs", [DEFAULT_OUTPUT], "command outputs (names; each configured under "
              "hardware.<name>.topic|message|interface|joints)", check=_output_names, read_only=True),
    ParamSpec("hardware.joint_states", ["/joint_states"], "sensor_msgs/JointState topics, matched by joint name",
              check=_topic_list, read_only=True),
    ParamSpec("hardware.stamp_tolerance", 0.0025, "stamps of the joint-state topics of one cycle differ by at "
              "most this [s]", check=positive, read_only=True),
    ParamSpec("hardware.startup_check", 0.0, "controller: no command until the profile matches the graph (every "
              "joint-state topic published, every joint on one, every command topic subscribed with its type); "
              "refused (exit 2, the problems named) if it does not within this time [s] (0: no check)",
              check=non_negative, read_only=True),
    ParamSpec("hardware.robot", "", "the cell's robot description (config/robots/<name>.yaml or a YAML path): every "
              "node and tool on this profile runs on it; '': the robot parameter's, else the scenario's "
              "(dualarm_control/cell_robot.py)", read_only=True),
    ParamSpec("hardware.joint_map", [""], "'description_name hardware_name' strings: the description's joint as "
              "the hardware names it on joint states and commands (['']: the description's names)",
              check=joint_map_entries, read_only=True),
)


def output_parameters(name: str) -> tuple[ParamSpec, ...]:
    """The parameters of the command output ``name`` (``hardware.<name>.*``)."""
    key = f"hardware.{name}"
    return (
        ParamSpec(f"{key}.topic", f"/{name}/commands", "command topic of this output", read_only=True),
        ParamSpec(f"{key}.message", DEFAULT_MESSAGE, "command message type (a registered output type, "
                  "docs/outputs.md): float64_multi_array (std_msgs/Float64MultiArray), joint_trajectory (a one-point "
                  "trajectory_msgs/JointTrajectory), ...", choices=output_names, read_only=True),
        ParamSpec(f"{key}.interface", INTERFACES[0], "command interface of the controller it feeds",
                  choices=lambda: list(INTERFACES), read_only=True),
        ParamSpec(f"{key}.joints", [""], "joints of this output, in the controller's order (['']: every joint "
                  "of the robot description, in its order)", read_only=True),
    )


@dataclass(frozen=True)
class HardwareProfile:
    """Command outputs, joint-state topics and their stamp tolerance [s] (module docstring)."""

    outputs: tuple[OutputSpec, ...]
    joint_states: tuple[str, ...]
    stamp_tolerance: float
    joint_map: JointMap = IDENTITY

    def hardware_names(self, joint_names: Sequence[str]) -> tuple[str, ...]:
        """The description's ``joint_names`` as the hardware names them (``hardware.joint_map``): the one
        place the map is applied, by every reader of joint states and writer of commands."""
        return self.joint_map.hardware(joint_names)

    def indices(self, joint_names: Sequence[str]) -> list[np.ndarray]:
        """Per output, the index in ``joint_names`` (the description's names and order) of each of its
        joints (hardware names)."""
        order = {n: i for i, n in enumerate(self.hardware_names(joint_names))}
        return [np.array([order[j] for j in o.joints], dtype=int) for o in self.outputs]

    @property
    def topics(self) -> tuple[str, ...]:
        return tuple(o.topic for o in self.outputs)


def profile_parameters(given: Mapping[str, Any]) -> tuple[ParamSpec, ...]:
    """Every parameter of the profile ``given`` names (the static ones, then each output's)."""
    outputs = resolve(HARDWARE_PARAMETERS[:1], given)["hardware.outputs"]
    return HARDWARE_PARAMETERS + tuple(s for name in outputs if name for s in output_parameters(name))


def load_profile(given: Mapping[str, Any], joint_names: Sequence[str], node: str = "") -> HardwareProfile:
    """The validated profile of the flat parameters ``given`` (defaults for what is absent) on a robot
    with ``joint_names``. Raises ParameterError naming the key, the bad joint or topic."""
    values = resolve(profile_parameters(given), given, node)
    return profile_from_values(values, joint_names, node)


def profile_from_values(values: Mapping[str, Any], joint_names: Sequence[str], node: str = "") -> HardwareProfile:
    """The profile of resolved (declared) values; checks joint coverage and topics across outputs."""
    prefix = f"{node}." if node else ""
    joint_map = parse_joint_map(values.get("hardware.joint_map", [""]), joint_names, f"{prefix}hardware.joint_map")
    hardware = joint_map.hardware(joint_names)
    known = set(hardware)
    owner: dict[str, str] = {}
    outputs: list[OutputSpec] = []
    for name in [n for n in values["hardware.outputs"] if n]:
        key = f"hardware.{name}"
        joints = tuple(j for j in values[f"{key}.joints"] if j) or hardware
        for j in joints:
            if j not in known:
                what = "a joint of the hardware (hardware.joint_map applied)" if joint_map.to_hardware else \
                    "a joint of the robot description"
                raise ParameterError(f"{prefix}{key}.joints", j, f"{what} ({', '.join(hardware)})")
            if j in owner:
                raise ParameterError(f"{prefix}{key}.joints", j, f"a joint no other output commands "
                                     f"(already in hardware.{owner[j]}.joints)")
            owner[j] = name
        topic = values[f"{key}.topic"]
        if not topic.startswith("/"):
            raise ParameterError(f"{prefix}{key}.topic", topic, "an absolute topic name ('/...')")
        clash = [o.name for o in outputs if o.topic == topic]
        if clash:
            raise ParameterError(f"{prefix}{key}.topic", topic, f"a topic no other output uses "
                                 f"(hardware.{clash[0]}.topic)")
        outputs.append(OutputSpec(name, topic, values[f"{key}.message"], values[f"{key}.interface"], joints))
    missing = [j for j in hardware if j not in owner]
    if missing:
        raise ParameterError(f"{prefix}hardware.outputs", list(values["hardware.outputs"]),
                             f"outputs that command every joint: {', '.join(missing)} in none")
    states = tuple(t for t in values["hardware.joint_states"] if t)
    return HardwareProfile(tuple(outputs), states, float(values["hardware.stamp_tolerance"]), joint_map)


def position_command(reference: FloatArray, velocity: FloatArray, measured: FloatArray, period: float,
                     q_min: FloatArray, q_max: FloatArray, qd_max: FloatArray) -> FloatArray:
    """The next position command [rad]: ``reference + velocity * period``, clamped to
    [``q_min``, ``q_max``] and to ``measured ± qd_max * period`` (never farther than one cycle at
    the velocity limit from the measured position). All arrays (n,), in one joint order."""
    step = qd_max * period
    lo = np.maximum(q_min, measured - step)
    hi = np.minimum(q_max, measured + step)
    return np.minimum(np.maximum(reference + velocity * period, lo), hi)


class PositionIntegrator:
    """The position reference of the position outputs: restarted from the measured position at the
    first cycle and after every safe stop (:meth:`reset`), then integrated (:func:`position_command`)."""

    def __init__(self, q_min: FloatArray, q_max: FloatArray, qd_max: FloatArray, period: float) -> None:
        self.q_min, self.q_max, self.qd_max, self.period = q_min, q_max, qd_max, period
        self.reference: FloatArray | None = None

    def reset(self) -> None:
        self.reference = None

    def command(self, velocity: FloatArray, measured: FloatArray) -> FloatArray:
        """The position command of a cycle's ``velocity`` [rad/s] at ``measured`` [rad]."""
        start = measured if self.reference is None else self.reference
        self.reference = position_command(start, velocity, measured, self.period, self.q_min, self.q_max,
                                          self.qd_max)
        return self.reference

    def hold(self, measured: FloatArray) -> FloatArray:
        """A safe stop: hold ``measured`` (clamped to the limits); the next cycle restarts from the measurement."""
        self.reference = None
        return np.minimum(np.maximum(measured, self.q_min), self.q_max)


@dataclass(frozen=True)
class StateSample:
    """One joint-state topic's latest sample: stamp [ns], receipt (monotonic ns), model indices and values."""

    stamp: int
    received: int
    indices: np.ndarray
    positions: FloatArray


class StateAssembler:
    """A consistent joint state of both arms from one or several joint-state topics, matched by name.

    Each topic's latest sample is kept; :meth:`put` returns the assembled state (stamp = the newest
    of the samples, positions in the description's order) once every topic has a sample since the
    last assembled state, every joint is covered, and the stamps differ by at most ``tolerance_ns``.
    With one topic every sample is a state (today's behaviour).
    """

    def __init__(self, topics: Sequence[str], nq: int, tolerance_ns: int) -> None:
        self.topics, self.nq, self.tolerance_ns = tuple(topics), nq, tolerance_ns
        self.latest: dict[str, StateSample] = {}
        self.fresh: set[str] = set()

    def put(self, topic: str, sample: StateSample) -> tuple[int, FloatArray] | None:
        self.latest[topic] = sample
        self.fresh.add(topic)
        if len(self.fresh) < len(self.topics):
            return None
        if len(self.topics) == 1:
            self.fresh.clear()
            return sample.stamp, sample.positions
        if self.spread() > self.tolerance_ns:
            return None
        q = np.full(self.nq, np.nan)
        for s in self.latest.values():
            q[s.indices] = s.positions
        if np.isnan(q).any():
            return None
        self.fresh.clear()
        return max(s.stamp for s in self.latest.values()), q

    def spread(self) -> int:
        """Newest minus oldest stamp of the topics' latest samples [ns]."""
        stamps = [s.stamp for s in self.latest.values()]
        return max(stamps) - min(stamps)

    def stale_reason(self, now: int, timeout_ns: float) -> str:
        """Why there is no fresh consistent state ('' if there is): the topics silent for longer than
        ``timeout_ns`` (monotonic ``now``), or stamps beyond the tolerance."""
        silent = [t for t in self.topics if t not in self.latest or now - self.latest[t].received > timeout_ns]
        if silent:
            ages = ", ".join(f"{t} by {(now - self.latest[t].received) / 1e6:.1f} ms" if t in self.latest
                             else f"{t} (none yet)" for t in silent)
            return f"joint_states stale: {ages}"
        if len(self.topics) > 1 and self.spread() > self.tolerance_ns:
            return (f"joint_states inconsistent: stamps of {', '.join(self.topics)} differ by "
                    f"{self.spread() / 1e6:.1f} ms > {self.tolerance_ns / 1e6:.1f} ms")
        return ""


@dataclass(frozen=True)
class TopicView:
    """What a node knows of one joint-state topic while it waits for a consistent state (issue 38).

    ``publishers``: one ``"node [type]"`` per publisher endpoint the ROS graph shows on the topic
    (any type); ``delivered``: samples received (usable or not); ``rejection``: why the last
    unusable sample was refused ('' if none was)."""

    topic: str
    publishers: tuple[str, ...]
    delivered: int
    rejection: str


STATE_TYPE = "sensor_msgs/msg/JointState"


def waiting_reason(views: Sequence[TopicView], assembler: StateAssembler, joint_names: Sequence[str],
                   joint_map: JointMap = IDENTITY) -> str:
    """Why there is no consistent joint state yet, every cause found, '; '-separated: a topic with no
    publisher, a topic with more than one publisher or a publisher of another type (the node names
    and types), a topic that has delivered nothing, a topic whose samples are refused (the last reason),
    joints of the description that no topic carries, stamps beyond the tolerance (by how much).
    '' when nothing explains the wait (a state is on its way)."""
    causes: list[str] = []
    for v in views:
        if not v.publishers:
            causes.append(f"no publisher on {v.topic}")
            continue
        foreign = [p for p in v.publishers if not p.endswith(f"[{STATE_TYPE}]")]
        if len(v.publishers) > 1 or foreign:
            causes.append(f"{len(v.publishers)} publishers on {v.topic}" + (" (of another type)" if foreign else "")
                          + f": {', '.join(v.publishers)}")
        if v.delivered == 0:
            causes.append(f"{v.topic}: nothing delivered from {', '.join(v.publishers)}")
        elif v.rejection:
            causes.append(f"{v.topic}: samples refused: {v.rejection}")
    carried = np.zeros(len(joint_names), dtype=bool)
    for sample in assembler.latest.values():
        carried[sample.indices] = True
    if assembler.latest and not carried.all():
        missing = [joint_map.label(n) for n, c in zip(joint_names, carried, strict=True) if not c]
        causes.append(f"joints of the description missing from every topic: {', '.join(missing)}")
    if len(assembler.latest) > 1 and assembler.spread() > assembler.tolerance_ns:
        heard = [topic for topic in assembler.topics if topic in assembler.latest]  # the profile's order, not arrival's
        causes.append(f"stamps of {', '.join(heard)} differ by {assembler.spread() / 1e6:.1f} ms > "
                      f"{assembler.tolerance_ns / 1e6:.1f} ms")
    return "; ".join(causes)
