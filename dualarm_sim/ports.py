"""The simulator's side of a hardware profile (issue 29): what ros2_control would do in front of the arms.

* :func:`state_layout`: the joint-state topics as joint_state_broadcaster publishes them: per topic
  its joints in the simulator's own order, the held (locked) joints and optional extra joints.
* :class:`CommandMerger`: the profile's command outputs (each its joints, velocity or position
  interface) merged into the cell's joint velocity command; per output, the decoder of its registered
  message type (:mod:`dualarm_control.outputs`), which the simulator's command subscriptions use.

ROS-free.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from dualarm_control.hardware import HardwareProfile
from dualarm_control.outputs import CommandDecoder

STATE_ORDERS = ("description", "reversed", "sorted")


def _namespace(topic: str) -> str:
    return topic.rsplit("/", 1)[0]


@dataclass(frozen=True)
class StateTopic:
    """One joint-state topic: its ``names`` and, per name, the index in the full state vector (the
    description's joints, then the held ones, then the extra ones, which read 0)."""

    topic: str
    names: tuple[str, ...]
    indices: np.ndarray


def state_layout(profile: HardwareProfile, joint_names: Sequence[str], held: Sequence[str],
                 extra: Sequence[str] = (), order: str = "description") -> list[StateTopic]:
    """The joint-state topics of ``profile``: a topic in a namespace (``/left/joint_states``) carries the
    joints of the outputs of that namespace (a controller manager per arm), a topic outside any
    namespace or the only topic carries every joint; each also the ``held`` and ``extra`` joints.
    ``order`` (:data:`STATE_ORDERS`): the description's order, reversed, or sorted by name."""
    if order not in STATE_ORDERS:
        raise ValueError(f"state order {order!r}: one of {', '.join(STATE_ORDERS)}")
    full = [*profile.hardware_names(joint_names), *held, *extra]  # as the hardware names them (joint_map)
    index = {n: i for i, n in enumerate(full)}
    out = []
    for topic in profile.joint_states:
        ns = _namespace(topic)
        mine = [j for o in profile.outputs if ns and _namespace(o.topic).startswith(ns) for j in o.joints]
        arms = list(full[:len(joint_names)]) if len(profile.joint_states) == 1 or not mine else \
            [j for j in full[:len(joint_names)] if j in set(mine)]
        names = [*arms, *held, *extra]
        if order == "reversed":
            names.reverse()
        elif order == "sorted":
            names.sort()
        out.append(StateTopic(topic, tuple(names), np.array([index[n] for n in names], dtype=int)))
    return out


class CommandMerger:
    """The cell's joint velocity command [rad/s] (the description's order) from the profile's outputs.

    A velocity output sets its joints' velocities; a position output the velocity that moves its
    joints' position reference (the cell's joint position controller, :attr:`DualArmCell.reference`)
    to the commanded positions in one ``period``. After the step the simulator stops the position
    joints (:attr:`position_mask`, :meth:`DualArmCell.hold`): the positions last commanded hold.
    :attr:`decoders`: per output name, how its messages are read (an unregistered message type is
    refused here, UnknownOutputError naming the known ones).
    """

    def __init__(self, profile: HardwareProfile, joint_names: Sequence[str], period: float) -> None:
        self.decoders = {o.name: CommandDecoder(o) for o in profile.outputs}
        self.outputs = {o.name: (o, idx) for o, idx in zip(profile.outputs, profile.indices(joint_names))}
        self.period = period
        self.velocity = np.zeros(len(joint_names))
        self.position_mask = np.zeros(len(joint_names), dtype=bool)
        for spec, idx in self.outputs.values():
            self.position_mask[idx] = spec.position
        self.received: set[str] = set()

    def put(self, output: str, values: np.ndarray, reference: np.ndarray) -> None:
        """A command of ``output`` (its joints, in its order); ``reference``: the cell's position reference [rad]."""
        spec, idx = self.outputs[output]
        self.velocity[idx] = (values - reference[idx]) / self.period if spec.position else values
        self.received.add(output)

    @property
    def complete(self) -> bool:
        """Every output sent a command since the last :meth:`take` (lockstep: the step may run)."""
        return len(self.received) == len(self.outputs)

    def take(self) -> np.ndarray:
        """The merged command; the next lockstep step waits for every output again."""
        self.received = set()
        return self.velocity.copy()
