"""The recorder's ``/tf`` and ``/tf_static``: link frames computed from each recorded ``/joint_states``.

On a pip machine no robot_state_publisher runs (tf2_msgs is not among the PyPI ROS wheels), so
``dualarm bag record`` writes what it would have published, into the bag only: for every
``/joint_states`` message a ``/tf`` message (one transform per movable URDF joint, stamped with
the joint state's header stamp) and, with the first one, a ``/tf_static`` message (the fixed
joints, offered transient local), both at the joint state's receive time. The URDF is the
recorded ``/robot_description`` if any, else the package's cell URDF. The frames are computed
when the bag closes, from the joint states kept as received.
See :mod:`dualarm_control.link_frames` for the frames.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Final

import numpy as np
from rosbags.interfaces import (
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)

from dualarm_control.link_frames import TF_TYPE, LinkFrames, TfSerializer
from dualarm_control.paths import urdf_path
from dualarm_control.ros.cdr import JointStateReader, Reader

TF_TOPIC: Final = "/tf"
TF_STATIC_TOPIC: Final = "/tf_static"
DESCRIPTION_TOPIC: Final = "/robot_description"
JOINT_STATES_TOPIC: Final = "/joint_states"
NOTE_KEY: Final = "dualarm.tf"
"""metadata.yaml ``custom_data`` key saying where the bag's /tf comes from (``dualarm bag info`` prints it)."""
NOTE: Final = f"{TF_TOPIC}: computed by the recorder from {JOINT_STATES_TOPIC}"

_INFINITE = QosTime(sec=2147483647, nsec=4294967295)


def _qos(depth: int, durability: QosDurability) -> Qos:
    return Qos(history=QosHistory.KEEP_LAST, depth=depth, reliability=QosReliability.RELIABLE,
               durability=durability, deadline=_INFINITE, lifespan=_INFINITE, liveliness=QosLiveliness.AUTOMATIC,
               liveliness_lease_duration=_INFINITE, avoid_ros_namespace_conventions=False)


TF_QOS: Final = _qos(100, QosDurability.VOLATILE)
"""tf2_ros' dynamic broadcaster QoS (keep-last 100, reliable, volatile)."""
TF_STATIC_QOS: Final = _qos(1, QosDurability.TRANSIENT_LOCAL)
"""tf2_ros' static broadcaster QoS (keep-last 1, reliable, transient local)."""


def string_data(data: bytes) -> str:
    """The text of a CDR std_msgs/msg/String."""
    return Reader(data).string()


class ComputedTf:
    """Turns recorded /joint_states into /tf and /tf_static messages for a bag.

    The joint states are kept as received and the frames computed when the bag closes
    (:meth:`finish`): the recording callbacks stay as cheap as without /tf, so a recorder of a
    lockstep run does not fall behind. ``write(topic, type_name, qos, data, stamp_ns)`` adds a
    message to the bag (creating the topic's connection on first use)."""

    def __init__(self, write: Callable[[str, str, Qos, bytes, int], None], log: Callable[[str], None]) -> None:
        self._write = write
        self._log = log
        self._description: str | None = None
        self._joint_states: list[tuple[bytes, int]] = []
        self.enabled = True
        self.written = 0

    def on_description(self, data: bytes) -> None:
        """A /robot_description message: its URDF gives the frames (the first one)."""
        if self._description is None:
            self._description = string_data(data)

    def on_joint_state(self, data: bytes, receive_ns: int) -> None:
        """A recorded /joint_states message (CDR) received at ``receive_ns``."""
        if self.enabled:
            self._joint_states.append((data, receive_ns))

    def disable(self, reason: str) -> None:
        """Compute no /tf, saying why."""
        if self.enabled:
            self.enabled = False
            self._joint_states = []
            self._log(f"{TF_TOPIC} not computed: {reason}")

    def finish(self) -> int:
        """Write /tf_static once (at the first joint state) and one /tf per joint state; returns
        the number of /tf messages. The URDF is the recorded /robot_description, else the cell's."""
        if not self.enabled or not self._joint_states:
            return 0
        frames = LinkFrames(self._description if self._description is not None else urdf_path().read_text())
        serializer = TfSerializer()
        reader = JointStateReader()
        order: tuple[tuple[str, ...], np.ndarray] | None = None
        for data, receive_ns in self._joint_states:
            stamp, names, position, _ = reader(data)
            if order is None or order[0] is not names:
                where = {n: i for i, n in enumerate(names)}
                missing = [n for n in frames.joint_names if n not in where]
                if missing:
                    self._log(f"{TF_TOPIC} not computed from a {JOINT_STATES_TOPIC} without the URDF's joints {missing}")
                    continue
                order = (names, np.array([where[n] for n in frames.joint_names]))
            q = position[order[1]]
            if self.written == 0:
                self._write(TF_STATIC_TOPIC, TF_TYPE, TF_STATIC_QOS,
                            serializer.tf_message(stamp, frames.transforms(q, fixed=True)), receive_ns)
            self._write(TF_TOPIC, TF_TYPE, TF_QOS, serializer.tf_message(stamp, frames.transforms(q)), receive_ns)
            self.written += 1
        self._joint_states = []
        return self.written
