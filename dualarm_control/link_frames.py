"""Link frames of the cell as robot_state_publisher gives them: one transform per URDF joint.

For each joint of the URDF, the transform from its parent link's frame to its child link's
frame at the joint's position (``header.frame_id`` = parent link, ``child_frame_id`` = child
link). Movable joints go to ``/tf`` with each joint state's stamp, fixed joints once to
``/tf_static`` (transient local), as robot_state_publisher does. The poses come from the
package's forward kinematics (pinocchio, :class:`dualarm_control.kinematics.DualArmModel`):
T_parent^child = (oMf[parent])^-1 oMf[child], with oMf the world placement of each link's
body frame. Messages are tf2_msgs/msg/TFMessage serialized to CDR with the ``rosbags``
typestore (tf2_msgs is not among the PyPI ROS wheels; no rclpy needed).
"""

from __future__ import annotations

import tempfile
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from dualarm_control.arrays import FloatArray

TF_TYPE = "tf2_msgs/msg/TFMessage"
STRING_TYPE = "std_msgs/msg/String"


@dataclass(frozen=True)
class UrdfJoint:
    """One ``<joint>`` of a URDF: its name, type and the links it connects."""

    name: str
    type: str
    parent: str
    child: str

    @property
    def fixed(self) -> bool:
        return self.type == "fixed"


def urdf_joints(urdf_text: str) -> list[UrdfJoint]:
    """The joints of a URDF document, in file order."""
    root = ET.fromstring(urdf_text)
    out = []
    for joint in root.findall("joint"):
        parent, child = joint.find("parent"), joint.find("child")
        if parent is None or child is None:
            raise ValueError(f"URDF joint {joint.get('name')!r} lacks its parent or child link")
        out.append(UrdfJoint(str(joint.get("name")), str(joint.get("type")), str(parent.get("link")),
                             str(child.get("link"))))
    return out


@dataclass(frozen=True)
class LinkTransform:
    """Pose of ``child`` in ``parent``: translation [m] (3,), quaternion (x, y, z, w) (4,)."""

    parent: str
    child: str
    translation: FloatArray
    quaternion: FloatArray


class UrdfKinematics:
    """The pinocchio model of a whole URDF given as text (e.g. a /robot_description): every movable
    joint (the arms' and the locked ones, as a joint_state_broadcaster publishes them)."""

    def __init__(self, urdf_text: str) -> None:
        with tempfile.TemporaryDirectory(prefix="dualarm_urdf_") as tmp:
            path = Path(tmp) / "robot_description.urdf"
            path.write_text(urdf_text)
            self.model = pin.buildModelFromUrdf(str(path))
        self.data = self.model.createData()
        self.joint_names: list[str] = [self.model.names[i] for i in range(1, self.model.njoints)]
        self.nq = self.model.nq

    def frame_id(self, link: str) -> int:
        if not self.model.existFrame(link):
            raise KeyError(f"unknown link {link!r} in the URDF")
        return int(self.model.getFrameId(link))

    def check_q(self, q: FloatArray) -> FloatArray:
        q = np.asarray(q, dtype=float)
        if q.shape != (self.nq,):
            raise ValueError(f"joint positions: expected {self.nq} values (the URDF's movable joints), got {q.shape}")
        return q


def model_from_text(urdf_text: str) -> UrdfKinematics:
    """The pinocchio model of a URDF given as text (:class:`UrdfKinematics`)."""
    return UrdfKinematics(urdf_text)


class LinkFrames:
    """Parent -> child link transforms of every URDF joint at a joint configuration."""

    def __init__(self, urdf_text: str) -> None:
        self.model = model_from_text(urdf_text)
        self.joints = urdf_joints(urdf_text)
        self.moving = [j for j in self.joints if not j.fixed]
        self.fixed = [j for j in self.joints if j.fixed]
        self._ids = {link: self.model.frame_id(link) for j in self.joints for link in (j.parent, j.child)}

    @property
    def joint_names(self) -> list[str]:
        """The model's movable joints, in the order of its joint vector."""
        return self.model.joint_names

    def transforms(self, q: FloatArray, fixed: bool = False) -> list[LinkTransform]:
        """Transforms of the movable joints (``fixed``: of the fixed joints) at q [rad] (nq,)."""
        m = self.model
        pin.framesForwardKinematics(m.model, m.data, m.check_q(q))
        placements = m.data.oMf
        out = []
        for joint in self.fixed if fixed else self.moving:
            rel = placements[self._ids[joint.parent]].actInv(placements[self._ids[joint.child]])
            quat = pin.Quaternion(rel.rotation).coeffs()  # (x, y, z, w)
            out.append(LinkTransform(joint.parent, joint.child, rel.translation.copy(), np.array(quat)))
        return out


class TfSerializer:
    """tf2_msgs/msg/TFMessage and std_msgs/msg/String as CDR bytes (rosbags' Jazzy typestore)."""

    def __init__(self) -> None:
        from rosbags.typesys import Stores, get_typestore

        self.store: Any = get_typestore(Stores.ROS2_JAZZY)
        t = self.store.types
        self._msg = t[TF_TYPE]
        self._stamped = t["geometry_msgs/msg/TransformStamped"]
        self._transform = t["geometry_msgs/msg/Transform"]
        self._vector = t["geometry_msgs/msg/Vector3"]
        self._quaternion = t["geometry_msgs/msg/Quaternion"]
        self._header = t["std_msgs/msg/Header"]
        self._time = t["builtin_interfaces/msg/Time"]
        self._string = t[STRING_TYPE]

    def msgdef(self, type_name: str) -> str:
        """The ROS 2 message definition text of ``type_name`` (with its dependencies)."""
        return str(self.store.generate_msgdef(type_name, ros_version=2)[0])

    def tf_message(self, stamp_ns: int, transforms: list[LinkTransform]) -> bytes:
        """One TFMessage holding ``transforms``, each stamped ``stamp_ns``."""
        sec, nsec = divmod(int(stamp_ns), 1_000_000_000)
        stamp = self._time(sec=sec, nanosec=nsec)
        items = []
        for tf in transforms:
            x, y, z = tf.translation.tolist()
            qx, qy, qz, qw = tf.quaternion.tolist()
            items.append(self._stamped(
                header=self._header(stamp=stamp, frame_id=tf.parent), child_frame_id=tf.child,
                transform=self._transform(translation=self._vector(x=x, y=y, z=z),
                                          rotation=self._quaternion(x=qx, y=qy, z=qz, w=qw))))
        return bytes(self.store.serialize_cdr(self._msg(transforms=items), TF_TYPE))

    def string(self, text: str) -> bytes:
        """A std_msgs/msg/String holding ``text``."""
        return bytes(self.store.serialize_cdr(self._string(data=text), STRING_TYPE))
