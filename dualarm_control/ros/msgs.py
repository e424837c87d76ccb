"""ROS 2 Jazzy message types as Cyclone DDS IDL structs, byte-compatible with rmw_cyclonedds_cpp.

Each class is a final (XCDR1, little endian) ``IdlStruct`` dataclass whose DDS type
name is the one ``rmw_cyclonedds_cpp`` uses (``pkg::msg::dds_::Type_``) and whose
fields follow the ``.msg`` definitions in name, order and type, so samples
interoperate with a ROS 2 machine and decode with ``rosbags``. They construct like
rclpy messages: ``JointState()`` or ``JointState(name=[...], position=[...])``.

Differences from rclpy messages (documented, on purpose):
- ``byte`` fields (``DiagnosticStatus.level``) hold ``int``; rclpy uses 1-byte
  ``bytes``. Use the class constants (``DiagnosticStatus.ERROR``) to stay portable.
- ``char[16]`` (``Gid.data``) holds ``bytes``.
- Numeric sequences hold lists; the publisher converts numpy arrays on the fly.
- No type checks on assignment.
"""

from dataclasses import dataclass, field

from cyclonedds.idl import IdlStruct
from cyclonedds.idl import types as t
from cyclonedds.idl.annotations import final

# ---------------------------------------------------------------- builtin_interfaces


@final
@dataclass
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    """builtin_interfaces/msg/Time: seconds and nanoseconds since the epoch."""

    sec: t.int32 = 0
    nanosec: t.uint32 = 0


@final
@dataclass
class Duration(IdlStruct, typename="builtin_interfaces::msg::dds_::Duration_"):
    """builtin_interfaces/msg/Duration."""

    sec: t.int32 = 0
    nanosec: t.uint32 = 0


# ---------------------------------------------------------------- std_msgs


@final
@dataclass
class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    """std_msgs/msg/Header."""

    stamp: Time = field(default_factory=Time)
    frame_id: str = ""


@final
@dataclass
class MultiArrayDimension(IdlStruct, typename="std_msgs::msg::dds_::MultiArrayDimension_"):
    """std_msgs/msg/MultiArrayDimension."""

    label: str = ""
    size: t.uint32 = 0
    stride: t.uint32 = 0


@final
@dataclass
class MultiArrayLayout(IdlStruct, typename="std_msgs::msg::dds_::MultiArrayLayout_"):
    """std_msgs/msg/MultiArrayLayout."""

    dim: t.sequence[MultiArrayDimension] = field(default_factory=list)
    data_offset: t.uint32 = 0


@final
@dataclass
class Float64MultiArray(IdlStruct, typename="std_msgs::msg::dds_::Float64MultiArray_"):
    """std_msgs/msg/Float64MultiArray (ros2_control JointGroupVelocityController commands)."""

    layout: MultiArrayLayout = field(default_factory=MultiArrayLayout)
    data: t.sequence[t.float64] = field(default_factory=list)


@final
@dataclass
class String(IdlStruct, typename="std_msgs::msg::dds_::String_"):
    """std_msgs/msg/String."""

    data: str = ""


# ---------------------------------------------------------------- sensor_msgs


@final
@dataclass
class JointState(IdlStruct, typename="sensor_msgs::msg::dds_::JointState_"):
    """sensor_msgs/msg/JointState (effort may be empty)."""

    header: Header = field(default_factory=Header)
    name: t.sequence[str] = field(default_factory=list)
    position: t.sequence[t.float64] = field(default_factory=list)
    velocity: t.sequence[t.float64] = field(default_factory=list)
    effort: t.sequence[t.float64] = field(default_factory=list)


# ---------------------------------------------------------------- geometry_msgs


@final
@dataclass
class Vector3(IdlStruct, typename="geometry_msgs::msg::dds_::Vector3_"):
    """geometry_msgs/msg/Vector3."""

    x: t.float64 = 0.0
    y: t.float64 = 0.0
    z: t.float64 = 0.0


@final
@dataclass
class Point(IdlStruct, typename="geometry_msgs::msg::dds_::Point_"):
    """geometry_msgs/msg/Point."""

    x: t.float64 = 0.0
    y: t.float64 = 0.0
    z: t.float64 = 0.0


@final
@dataclass
class Quaternion(IdlStruct, typename="geometry_msgs::msg::dds_::Quaternion_"):
    """geometry_msgs/msg/Quaternion (identity by default, w = 1, as in ROS)."""

    x: t.float64 = 0.0
    y: t.float64 = 0.0
    z: t.float64 = 0.0
    w: t.float64 = 1.0


@final
@dataclass
class Pose(IdlStruct, typename="geometry_msgs::msg::dds_::Pose_"):
    """geometry_msgs/msg/Pose."""

    position: Point = field(default_factory=Point)
    orientation: Quaternion = field(default_factory=Quaternion)


@final
@dataclass
class PoseStamped(IdlStruct, typename="geometry_msgs::msg::dds_::PoseStamped_"):
    """geometry_msgs/msg/PoseStamped."""

    header: Header = field(default_factory=Header)
    pose: Pose = field(default_factory=Pose)


@final
@dataclass
class Transform(IdlStruct, typename="geometry_msgs::msg::dds_::Transform_"):
    """geometry_msgs/msg/Transform."""

    translation: Vector3 = field(default_factory=Vector3)
    rotation: Quaternion = field(default_factory=Quaternion)


@final
@dataclass
class Twist(IdlStruct, typename="geometry_msgs::msg::dds_::Twist_"):
    """geometry_msgs/msg/Twist."""

    linear: Vector3 = field(default_factory=Vector3)
    angular: Vector3 = field(default_factory=Vector3)


@final
@dataclass
class Wrench(IdlStruct, typename="geometry_msgs::msg::dds_::Wrench_"):
    """geometry_msgs/msg/Wrench."""

    force: Vector3 = field(default_factory=Vector3)
    torque: Vector3 = field(default_factory=Vector3)


@final
@dataclass
class WrenchStamped(IdlStruct, typename="geometry_msgs::msg::dds_::WrenchStamped_"):
    """geometry_msgs/msg/WrenchStamped."""

    header: Header = field(default_factory=Header)
    wrench: Wrench = field(default_factory=Wrench)


# ---------------------------------------------------------------- trajectory_msgs


@final
@dataclass
class MultiDOFJointTrajectoryPoint(
    IdlStruct, typename="trajectory_msgs::msg::dds_::MultiDOFJointTrajectoryPoint_"
):
    """trajectory_msgs/msg/MultiDOFJointTrajectoryPoint."""

    transforms: t.sequence[Transform] = field(default_factory=list)
    velocities: t.sequence[Twist] = field(default_factory=list)
    accelerations: t.sequence[Twist] = field(default_factory=list)
    time_from_start: Duration = field(default_factory=Duration)


@final
@dataclass
class MultiDOFJointTrajectory(IdlStruct, typename="trajectory_msgs::msg::dds_::MultiDOFJointTrajectory_"):
    """trajectory_msgs/msg/MultiDOFJointTrajectory (``/relative_target`` carries one point)."""

    header: Header = field(default_factory=Header)
    joint_names: t.sequence[str] = field(default_factory=list)
    points: t.sequence[MultiDOFJointTrajectoryPoint] = field(default_factory=list)


# ---------------------------------------------------------------- diagnostic_msgs


@final
@dataclass
class KeyValue(IdlStruct, typename="diagnostic_msgs::msg::dds_::KeyValue_"):
    """diagnostic_msgs/msg/KeyValue."""

    key: str = ""
    value: str = ""


@final
@dataclass
class DiagnosticStatus(IdlStruct, typename="diagnostic_msgs::msg::dds_::DiagnosticStatus_"):
    """diagnostic_msgs/msg/DiagnosticStatus; ``level`` is a ROS ``byte`` (IDL octet, 1 byte)."""

    OK = 0
    WARN = 1
    ERROR = 2
    STALE = 3

    level: t.byte = 0
    name: str = ""
    message: str = ""
    hardware_id: str = ""
    values: t.sequence[KeyValue] = field(default_factory=list)


@final
@dataclass
class DiagnosticArray(IdlStruct, typename="diagnostic_msgs::msg::dds_::DiagnosticArray_"):
    """diagnostic_msgs/msg/DiagnosticArray."""

    header: Header = field(default_factory=Header)
    status: t.sequence[DiagnosticStatus] = field(default_factory=list)


# ---------------------------------------------------------------- rosgraph_msgs


@final
@dataclass
class Clock(IdlStruct, typename="rosgraph_msgs::msg::dds_::Clock_"):
    """rosgraph_msgs/msg/Clock."""

    clock: Time = field(default_factory=Time)


# ---------------------------------------------------------------- rmw_dds_common (graph)


@final
@dataclass
class Gid(IdlStruct, typename="rmw_dds_common::msg::dds_::Gid_"):
    """rmw_dds_common/msg/Gid: ``char[16]`` (Iron and later), the 16-byte DDS GUID."""

    data: t.array[t.uint8, 16] = field(default_factory=lambda: bytes(16))


@final
@dataclass
class NodeEntitiesInfo(IdlStruct, typename="rmw_dds_common::msg::dds_::NodeEntitiesInfo_"):
    """rmw_dds_common/msg/NodeEntitiesInfo."""

    node_namespace: t.bounded_str[256] = ""
    node_name: t.bounded_str[256] = ""
    reader_gid_seq: t.sequence[Gid] = field(default_factory=list)
    writer_gid_seq: t.sequence[Gid] = field(default_factory=list)


@final
@dataclass
class ParticipantEntitiesInfo(IdlStruct, typename="rmw_dds_common::msg::dds_::ParticipantEntitiesInfo_"):
    """rmw_dds_common/msg/ParticipantEntitiesInfo, published on ``ros_discovery_info``."""

    gid: Gid = field(default_factory=Gid)
    node_entities_info_seq: t.sequence[NodeEntitiesInfo] = field(default_factory=list)


# ---------------------------------------------------------------- registry

ALL_TYPES: tuple[type[IdlStruct], ...] = (
    Time, Duration, Header, MultiArrayDimension, MultiArrayLayout, Float64MultiArray, String,
    JointState, Vector3, Point, Quaternion, Pose, PoseStamped, Transform, Twist, Wrench,
    WrenchStamped, MultiDOFJointTrajectoryPoint, MultiDOFJointTrajectory, KeyValue,
    DiagnosticStatus, DiagnosticArray, Clock, Gid, NodeEntitiesInfo, ParticipantEntitiesInfo,
)


def dds_type_name(cls: type) -> str:
    """DDS type name of a message class, e.g. ``sensor_msgs::msg::dds_::JointState_``."""
    return str(cls.__idl_typename__)  # type: ignore[attr-defined]


def ros_type_name_from_dds(dds_name: str) -> str:
    """``sensor_msgs::msg::dds_::JointState_`` -> ``sensor_msgs/msg/JointState``."""
    parts = dds_name.split("::")
    if len(parts) != 4 or parts[2] != "dds_" or not parts[3].endswith("_"):
        raise ValueError(f"not a ROS 2 DDS type name: {dds_name!r}")
    return f"{parts[0]}/{parts[1]}/{parts[3][:-1]}"


#: Message class -> ROS type name (``sensor_msgs/msg/JointState``), for bags and ``topic list``.
ROS_TYPE_NAMES: dict[type[IdlStruct], str] = {
    cls: ros_type_name_from_dds(dds_type_name(cls)) for cls in ALL_TYPES
}
_BY_NAME: dict[str, type[IdlStruct]] = {name: cls for cls, name in ROS_TYPE_NAMES.items()}


def msg_type_by_name(name: str) -> type[IdlStruct]:
    """Message class for ``pkg/msg/Type`` (also accepts ``pkg/Type`` and the DDS name)."""
    key = name.strip()
    if "::" in key:
        key = ros_type_name_from_dds(key)
    elif key.count("/") == 1:
        pkg, typ = key.split("/")
        key = f"{pkg}/msg/{typ}"
    try:
        return _BY_NAME[key]
    except KeyError:
        known = ", ".join(sorted(_BY_NAME))
        raise KeyError(f"unknown message type {name!r}; known: {known}") from None


__all__ = [cls.__name__ for cls in ALL_TYPES] + [
    "ALL_TYPES", "ROS_TYPE_NAMES", "dds_type_name", "msg_type_by_name", "ros_type_name_from_dds",
]
