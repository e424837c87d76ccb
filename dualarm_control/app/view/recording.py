"""What a viewer needs from a bag: the joint states as plain arrays and the cell's URDF."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from dualarm_control.app.record.bag import BagError, open_reader
from dualarm_control.link_frames import model_from_text
from dualarm_control.paths import urdf_path

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

JOINT_STATES_TOPIC = "/joint_states"
DESCRIPTION_TOPIC = "/robot_description"


@dataclass(frozen=True)
class JointRecording:
    """A run's joint states on their own clock.

    Attributes:
        stamps_ns: header stamps [ns], (N,), non-decreasing (simulation time for a lockstep run).
        positions: joint positions [rad], (N, n), columns in ``joint_names`` order.
        joint_names: the URDF's movable joints, (n,).
        urdf_text: the cell's URDF (the bag's /robot_description, else the package's cell URDF).
    """

    stamps_ns: IntArray
    positions: FloatArray
    joint_names: tuple[str, ...]
    urdf_text: str

    @property
    def duration_s(self) -> float:
        """Time from the first to the last joint state [s]."""
        return float(self.stamps_ns[-1] - self.stamps_ns[0]) / 1e9

    def at(self, times_s: FloatArray) -> FloatArray:
        """Joint positions (len(times_s), n) at ``times_s`` [s] after the first stamp, linearly
        interpolated per joint (held at the ends)."""
        t = (self.stamps_ns - self.stamps_ns[0]) / 1e9
        return np.column_stack([np.interp(times_s, t, self.positions[:, j]) for j in range(self.positions.shape[1])])


def read_joint_recording(bag: Path) -> JointRecording:
    """The joint states (header stamps, in the URDF's joint order) and URDF of a bag; BagError
    when it holds no /joint_states or they lack a joint of the URDF."""
    reader = open_reader(Path(bag))
    stamps: list[int] = []
    rows: list[list[float]] = []
    try:
        descriptions = [c for c in reader.connections if c.topic == DESCRIPTION_TOPIC]
        urdf_text = next((_message(reader, raw, c.msgtype).data
                          for c, _, raw in reader.messages(connections=descriptions)), None) if descriptions else None
        text = urdf_text if urdf_text is not None else urdf_path().read_text()
        model_names = joint_names(text)
        names: tuple[str, ...] = ()
        order: list[int] = []
        states = [c for c in reader.connections if c.topic == JOINT_STATES_TOPIC]
        for conn, _, raw in reader.messages(connections=states) if states else ():
            msg = _message(reader, raw, conn.msgtype)
            if tuple(msg.name) != names:
                names = tuple(msg.name)
                where = {n: i for i, n in enumerate(names)}
                missing = [n for n in model_names if n not in where]
                if missing:
                    raise BagError(f"{bag}: {JOINT_STATES_TOPIC} lacks the joints {missing}")
                order = [where[n] for n in model_names]
            stamps.append(msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec)
            rows.append([float(msg.position[i]) for i in order])
    finally:
        reader.close()
    if not rows:
        raise BagError(f"{bag}: no {JOINT_STATES_TOPIC} messages")
    stamp_array = np.array(stamps, dtype=np.int64)
    keep = np.argsort(stamp_array, kind="stable")
    return JointRecording(stamp_array[keep], np.array(rows)[keep], tuple(model_names), text)


def _message(reader: Any, raw: bytes, msgtype: str) -> Any:
    """A deserialized message (a rosbags dataclass, typed Any)."""
    return reader.deserialize(raw, msgtype)


def joint_names(urdf_text: str) -> list[str]:
    """Movable joints of a URDF in the model's (pinocchio's) order."""
    return model_from_text(urdf_text).joint_names
