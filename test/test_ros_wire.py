"""Wire compatibility of the Cyclone message types with ROS 2 Jazzy CDR, checked against rosbags."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
import pytest
from rosbags.interfaces import Nodetype
from rosbags.typesys import Stores, get_typestore

from dualarm_control.ros import catalog, msgs
from dualarm_control.ros.discovery import gid_of  # noqa: F401  (import check: discovery needs only msgs)

TS = get_typestore(Stores.ROS2_JAZZY)

_DTYPES = {
    "bool": np.bool_, "byte": np.uint8, "char": np.uint8, "int8": np.int8, "uint8": np.uint8,
    "int16": np.int16, "uint16": np.uint16, "int32": np.int32, "uint32": np.uint32, "int64": np.int64,
    "uint64": np.uint64, "float32": np.float32, "float64": np.float64,
}


def to_rosbags(msg: Any, typename: str) -> Any:
    """Build the rosbags message equal to a Cyclone message, guided by rosbags' field definitions."""
    _, fields = TS.fielddefs[typename]
    kwargs = {name: _conv(getattr(msg, name), nodetype, desc) for name, (nodetype, desc) in fields}
    return TS.types[typename](**kwargs)


def _conv(value: Any, nodetype: int, desc: Any) -> Any:
    if nodetype == Nodetype.BASE:
        return value
    if nodetype == Nodetype.NAME:
        return to_rosbags(value, desc)
    (subtype, subdesc), _size = desc
    if subtype == Nodetype.BASE and subdesc[0] != "string":
        return np.array(list(value), dtype=_DTYPES[subdesc[0]])
    return [_conv(v, subtype, subdesc) for v in value]


def plain(obj: Any) -> Any:
    """Comparable Python structure of a Cyclone or rosbags message."""
    if dataclasses.is_dataclass(obj):
        return {  # rosbags lists message constants (OK, WARN...) as fields: skip them
            f.name: plain(getattr(obj, f.name)) for f in dataclasses.fields(obj)
            if f.name != "__msgtype__" and not f.name.isupper()
        }
    if isinstance(obj, np.ndarray):
        return [plain(v) for v in obj.tolist()]
    if isinstance(obj, (bytes, bytearray)):
        return list(obj)
    if isinstance(obj, (list, tuple)):
        return [plain(v) for v in obj]
    if isinstance(obj, np.generic):
        return obj.item()
    return obj


def _stamp(sec: int = 1_700_000_123, nanosec: int = 456_789) -> msgs.Header:
    return msgs.Header(stamp=msgs.Time(sec=sec, nanosec=nanosec), frame_id="left_tool")


def _joint_names() -> list[str]:
    return [f"{side}_joint_{i}" for side in ("left", "right") for i in range(1, 8)]


def samples() -> dict[str, Any]:
    """One realistic message per type the package sends (odd string lengths to test alignment)."""
    twist = msgs.Twist(linear=msgs.Vector3(x=0.1, y=-0.2, z=0.3), angular=msgs.Vector3(x=1e-3, y=2.5, z=-4.0))
    return {
        "sensor_msgs/msg/JointState": msgs.JointState(
            header=_stamp(), name=_joint_names(), position=[0.1 * i for i in range(14)],
            velocity=[-0.01 * i for i in range(14)], effort=[],
        ),
        "std_msgs/msg/Float64MultiArray": msgs.Float64MultiArray(
            layout=msgs.MultiArrayLayout(
                dim=[msgs.MultiArrayDimension(label="joints", size=14, stride=14)], data_offset=1
            ),
            data=[float(i) / 7.0 for i in range(14)],
        ),
        "geometry_msgs/msg/PoseStamped": msgs.PoseStamped(
            header=_stamp(),
            pose=msgs.Pose(position=msgs.Point(x=0.1, y=0.2, z=0.3),
                           orientation=msgs.Quaternion(x=0.0, y=0.7071, z=0.0, w=0.7071)),
        ),
        "trajectory_msgs/msg/MultiDOFJointTrajectory": msgs.MultiDOFJointTrajectory(
            header=_stamp(), joint_names=["right_tool"],
            points=[msgs.MultiDOFJointTrajectoryPoint(
                transforms=[msgs.Transform(translation=msgs.Vector3(x=0.0, y=0.0, z=0.15),
                                           rotation=msgs.Quaternion(x=0.0, y=0.0, z=0.3827, w=0.9239))],
                velocities=[twist], accelerations=[msgs.Twist()],
                time_from_start=msgs.Duration(sec=2, nanosec=500_000_000),
            )],
        ),
        "diagnostic_msgs/msg/DiagnosticArray": msgs.DiagnosticArray(
            header=_stamp(),
            status=[
                msgs.DiagnosticStatus(
                    level=msgs.DiagnosticStatus.WARN, name="controller_node: solver", message="slow solve",
                    hardware_id="dualarm",
                    values=[msgs.KeyValue(key="solver", value="sparse_qp"),
                            msgs.KeyValue(key="solve_time_ms", value="1.25")],
                ),
                msgs.DiagnosticStatus(level=msgs.DiagnosticStatus.OK, name="x"),
            ],
        ),
        "geometry_msgs/msg/WrenchStamped": msgs.WrenchStamped(
            header=_stamp(),
            wrench=msgs.Wrench(force=msgs.Vector3(x=1.0, y=-2.0, z=9.81), torque=msgs.Vector3(x=0.01, y=0.0, z=-0.5)),
        ),
        "rmw_dds_common/msg/ParticipantEntitiesInfo": msgs.ParticipantEntitiesInfo(
            gid=msgs.Gid(data=bytes(range(1, 17))),
            node_entities_info_seq=[
                msgs.NodeEntitiesInfo(
                    node_namespace="/", node_name="controller_node",
                    reader_gid_seq=[msgs.Gid(data=bytes([7] * 16))],
                    writer_gid_seq=[msgs.Gid(data=bytes(range(16, 32))), msgs.Gid(data=bytes(16))],
                ),
                msgs.NodeEntitiesInfo(node_namespace="/cell", node_name="sim"),
            ],
        ),
        "std_msgs/msg/String": msgs.String(data="abc"),
        "rosgraph_msgs/msg/Clock": msgs.Clock(clock=msgs.Time(sec=3, nanosec=4)),
    }


SAMPLES = samples()


def test_catalog_matches_types() -> None:
    assert sorted(msgs.ROS_TYPE_NAMES.values()) == sorted(catalog.MESSAGE_TYPES)
    assert msgs.msg_type_by_name("sensor_msgs/msg/JointState") is msgs.JointState
    assert msgs.msg_type_by_name("sensor_msgs::msg::dds_::JointState_") is msgs.JointState
    assert msgs.dds_type_name(msgs.JointState) == "sensor_msgs::msg::dds_::JointState_"
    with pytest.raises(KeyError, match="unknown message type"):
        msgs.msg_type_by_name("foo_msgs/msg/Bar")


@pytest.mark.parametrize("cls", msgs.ALL_TYPES, ids=lambda c: c.__name__)
def test_fields_match_jazzy_definitions(cls: type) -> None:
    """Every type has the field names, in order, of the Jazzy .msg (rosbags' store)."""
    typename = msgs.ROS_TYPE_NAMES[cls]
    _, fields = TS.fielddefs[typename]
    assert [f.name for f in dataclasses.fields(cls)] == [name for name, _ in fields]
    default = cls()  # keyword construction with defaults, like rclpy
    assert bytes(TS.serialize_cdr(to_rosbags(default, typename), typename)) == default.serialize()


@pytest.mark.parametrize("typename", sorted(SAMPLES))
def test_byte_identical_and_decodable(typename: str) -> None:
    msg = SAMPLES[typename]
    ours = msg.serialize()
    assert ours[:4] == b"\x00\x01\x00\x00"  # CDR little endian encapsulation header, like rosbags/rmw
    theirs = bytes(TS.serialize_cdr(to_rosbags(msg, typename), typename))
    assert ours == theirs
    decoded = TS.deserialize_cdr(ours, typename)
    assert plain(decoded) == plain(msg)
    assert plain(type(msg).deserialize(theirs)) == plain(msg)


def test_diagnostic_levels() -> None:
    s = msgs.DiagnosticStatus
    assert (s.OK, s.WARN, s.ERROR, s.STALE) == (0, 1, 2, 3)
    consts = {name: value for name, _, value in TS.fielddefs["diagnostic_msgs/msg/DiagnosticStatus"][0]}
    assert consts == {"OK": 0, "WARN": 1, "ERROR": 2, "STALE": 3}
