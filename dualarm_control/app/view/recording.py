"""What a viewer needs from a bag: the joint states as plain arrays and the cell's URDF."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from dualarm_control.app.record.bag import (
    JOINT_STATES_TOPIC,
    BagError,
    FloatArray,
    IntArray,
    read_bag,
)
from dualarm_control.app.view.obstacles_view import ObstacleTrack, read_obstacles
from dualarm_control.link_frames import model_from_text
from dualarm_control.paths import urdf_path


@dataclass(frozen=True)
class JointRecording:
    """A run's joint states on their own clock.

    Attributes:
        stamps_ns: header stamps [ns], (N,), non-decreasing (simulation time for a lockstep run).
        positions: joint positions [rad], (N, n), columns in ``joint_names`` order.
        joint_names: the URDF's movable joints, (n,).
        urdf_text: the cell's URDF (the bag's /robot_description, else the package's cell URDF).
        obstacles: the obstacles the bag recorded (/dualarm/obstacles, /collision_objects), by name.
    """

    stamps_ns: IntArray
    positions: FloatArray
    joint_names: tuple[str, ...]
    urdf_text: str
    obstacles: dict[str, ObstacleTrack] = field(default_factory=dict)

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
    """The joint states (header stamps, in the URDF's joint order) and URDF of a bag, from the one
    bag reader (:func:`~dualarm_control.app.record.bag.read_bag`); BagError when it holds no
    /joint_states or they lack a joint of the URDF."""
    data = read_bag(Path(bag))
    if not data.states:
        raise BagError(f"{bag}: no {JOINT_STATES_TOPIC} messages")
    text = data.description if data.description is not None else urdf_path().read_text()
    names = model_from_text(text).joint_names
    positions, _ = data.joint_states(names)
    stamps = np.array([stamp for _, stamp, _, _ in data.states], dtype=np.int64)
    keep = np.argsort(stamps, kind="stable")
    return JointRecording(stamps[keep], positions.values[keep], tuple(names), text, read_obstacles(Path(bag)))
