"""Conversions between the core's values and the standard ROS 2 messages (no control math here).

Only ``common_interfaces`` types, so any ROS tool reads what the nodes publish.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pinocchio as pin
from builtin_interfaces.msg import Duration, Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import (
    Point,
    Pose,
    PoseStamped,
    Quaternion,
    Transform,
    Twist,
    Vector3,
    Vector3Stamped,
    Wrench,
    WrenchStamped,
)
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, Header
from trajectory_msgs.msg import (
    JointTrajectory,
    JointTrajectoryPoint,
    MultiDOFJointTrajectory,
    MultiDOFJointTrajectoryPoint,
)

LEFT_FRAME = "left_tool"
RIGHT_FRAME = "right_tool"
NS = 1_000_000_000


def stamp(ns: int) -> Any:
    """builtin_interfaces/Time from integer nanoseconds."""
    return Time(sec=int(ns // NS), nanosec=int(ns % NS))


def stamp_ns(msg_stamp: Any) -> int:
    """Integer nanoseconds of a builtin_interfaces/Time."""
    return int(msg_stamp.sec) * NS + int(msg_stamp.nanosec)


def header(ns: int, frame_id: str = "") -> Any:
    return Header(stamp=stamp(ns), frame_id=frame_id)


def joint_state(names: Sequence[str], ns: int, q: np.ndarray, qd: np.ndarray) -> Any:
    """sensor_msgs/JointState with positions [rad] and velocities [rad/s]; effort left empty."""
    return JointState(header=header(ns), name=list(names), position=[float(v) for v in q],
                               velocity=[float(v) for v in qd], effort=[])


def joint_indices(names: Sequence[str], order: Mapping[str, int], what: str) -> list[int] | str:
    """Index in ``names`` of each of the model's joints (``order``: name -> model index), or why not.

    Order is mapped by name; extra names (joints the controller does not drive) are ignored;
    a missing or duplicated name makes the message unusable.
    """
    position = {name: i for i, name in enumerate(names)}
    if len(position) != len(names):
        duplicates = sorted({n for n in names if names.count(n) > 1})
        return f"{what} has duplicate joint names {duplicates[:3]}"
    missing = [n for n in order if n not in position]
    if missing:
        return f"{what} is missing {len(missing)} of the {len(order)} joints, e.g. {missing[:3]} (got {list(names)[:3]}...)"
    return [position[n] for n in order]


def joint_vectors(msg: Any, order: Mapping[str, int]) -> tuple[np.ndarray, np.ndarray] | str:
    """(q, qd) in the model's joint order from a JointState, or a reason string if unusable.

    Rejected: duplicate or missing names, a position count different from the name count, a
    velocity count that is neither 0 (then qd = 0) nor the name count, NaN or inf.
    """
    names = list(msg.name)
    idx = joint_indices(names, order, "joint_states")
    if isinstance(idx, str):
        return idx
    if len(msg.position) != len(names) or len(msg.velocity) not in (0, len(names)):
        return (f"joint_states with {len(names)} names but {len(msg.position)} positions and "
                f"{len(msg.velocity)} velocities")
    q = np.asarray(msg.position, dtype=float)[idx]
    qd = np.asarray(msg.velocity, dtype=float)[idx] if len(msg.velocity) else np.zeros(len(idx))
    if not (np.all(np.isfinite(q)) and np.all(np.isfinite(qd))):
        return "joint_states contains NaN or inf"
    return q, qd


def command_vector(msg: Any, size: int) -> np.ndarray | str:
    """The joint velocity command [rad/s], (size,), of a Float64MultiArray, or why it is unusable."""
    data = np.asarray(msg.data, dtype=float)
    if data.shape != (size,):
        return f"command with {data.size} values rejected: expected {size}"
    if not np.all(np.isfinite(data)):
        return f"command with NaN or inf at indices {np.flatnonzero(~np.isfinite(data))[:5].tolist()} rejected"
    return data


def float_array(values: np.ndarray) -> Any:
    """std_msgs/Float64MultiArray (JointGroupVelocityController convention: layout empty)."""
    return Float64MultiArray(data=[float(v) for v in values])


def quaternion(rotation: np.ndarray) -> Any:
    """geometry_msgs/Quaternion of a rotation matrix, normalised.

    Through ``SE3ToXYZQUAT``: building a ``pin.Quaternion`` from a 3x3 matrix leaks about 80 bytes
    per call (eigenpy 3.13 / pinocchio 4.1), which `dualarm soak` showed as RSS growing 1 MiB a
    minute in every node publishing poses at 200 Hz.
    """
    xyzw = pin.SE3ToXYZQUAT(pin.SE3(np.asarray(rotation, dtype=float), np.zeros(3)))[3:]
    x, y, z, w = (float(v) for v in xyzw / np.linalg.norm(xyzw))
    return Quaternion(x=x, y=y, z=z, w=w)


def rotation(q: Any) -> np.ndarray:
    """Rotation matrix of a geometry_msgs/Quaternion (normalised; NaN stays NaN)."""
    v = np.array([q.x, q.y, q.z, q.w], dtype=float)
    if not np.all(np.isfinite(v)) or np.linalg.norm(v) < 1e-9:
        return np.full((3, 3), np.nan)
    v /= np.linalg.norm(v)
    return pin.Quaternion(v[3], v[0], v[1], v[2]).toRotationMatrix()


def pose_stamped(ns: int, position: np.ndarray, rot: np.ndarray) -> Any:
    """Measured relative pose (right tool in left tool frame)."""
    p = Point(x=float(position[0]), y=float(position[1]), z=float(position[2]))
    return PoseStamped(header=header(ns, LEFT_FRAME), pose=Pose(position=p, orientation=quaternion(rot)))


def _vec3(v: np.ndarray) -> Any:
    return Vector3(x=float(v[0]), y=float(v[1]), z=float(v[2]))


@dataclass(frozen=True)
class TargetValue:
    """A relative target decoded from a message (fields as the controller's RelativeTarget)."""

    stamp_ns: int
    position: np.ndarray
    rotation: np.ndarray
    linear_velocity: np.ndarray
    angular_velocity: np.ndarray


def target_message(ns: int, elapsed_ns: int, sample: Any) -> Any:
    """trajectory_msgs/MultiDOFJointTrajectory carrying one sample atomically: pose, twist, acceleration."""
    transform = Transform(translation=_vec3(sample.position), rotation=quaternion(sample.rotation))
    twist = Twist(linear=_vec3(sample.linear_velocity), angular=_vec3(sample.angular_velocity))
    accel = Twist(linear=_vec3(sample.linear_acceleration), angular=_vec3(sample.angular_acceleration))
    point = MultiDOFJointTrajectoryPoint(
        transforms=[transform], velocities=[twist], accelerations=[accel],
        time_from_start=duration(elapsed_ns),
    )
    return MultiDOFJointTrajectory(header=header(ns, LEFT_FRAME), joint_names=[RIGHT_FRAME], points=[point])


def target_value(msg: Any, max_distance: float = float("inf")) -> TargetValue | str:
    """Decode a relative target message, or return why it is unusable.

    Rejected: not exactly one point with one transform and one velocity, NaN or inf, a zero
    quaternion, a relative position farther than ``max_distance`` [m] (the cell's reach,
    :meth:`DualArmModel.relative_reach`).
    """
    if len(msg.points) != 1 or len(msg.points[0].transforms) != 1 or len(msg.points[0].velocities) != 1:
        return "relative_target must carry exactly one point with one transform and one velocity"
    tr, tw = msg.points[0].transforms[0], msg.points[0].velocities[0]
    value = TargetValue(
        stamp_ns=stamp_ns(msg.header.stamp),
        position=np.array([tr.translation.x, tr.translation.y, tr.translation.z], dtype=float),
        rotation=rotation(tr.rotation),
        linear_velocity=np.array([tw.linear.x, tw.linear.y, tw.linear.z], dtype=float),
        angular_velocity=np.array([tw.angular.x, tw.angular.y, tw.angular.z], dtype=float),
    )
    parts = (value.position, value.rotation, value.linear_velocity, value.angular_velocity)
    if not all(np.all(np.isfinite(x)) for x in parts):
        return "relative_target contains NaN or inf (or a zero quaternion)"
    distance = float(np.linalg.norm(value.position))
    if distance > max_distance:
        return (f"relative_target position {distance:.3f} m from the left tool is beyond the cell's reach "
                f"{max_distance:.3f} m")
    return value


def diagnostics(ns: int, name: str, level: int, message: str, values: Mapping[str, Any]) -> Any:
    """diagnostic_msgs/DiagnosticArray with one status whose values are ``key: str(value)``."""
    status = DiagnosticStatus(
        level=bytes([level]), name=name, message=message, hardware_id="dualarm_cell",
        values=[KeyValue(key=k, value=str(v)) for k, v in values.items()],
    )
    return DiagnosticArray(header=header(ns), status=[status])


CONTACT_FRAME = "pan_normal"


def wrench_stamped(ns: int, wrench: np.ndarray, frame_id: str = RIGHT_FRAME) -> Any:
    return WrenchStamped(header=header(ns, frame_id), wrench=Wrench(force=_vec3(wrench[:3]), torque=_vec3(wrench[3:])))


def contact_force(ns: int, normal_force: float) -> Any:
    """geometry_msgs/Vector3Stamped of the simulator's brush-pan contact: ``vector.z`` is the
    normal contact force [N] (ground truth of the physics, not a sensor), x = y = 0."""
    return Vector3Stamped(header=header(ns, CONTACT_FRAME), vector=Vector3(x=0.0, y=0.0, z=float(normal_force)))


def wrench_vector(msg: Any) -> np.ndarray | str:
    """geometry_msgs/WrenchStamped -> [fx, fy, fz, tx, ty, tz] (6,), or why it is unusable."""
    f, t = msg.wrench.force, msg.wrench.torque
    values = np.array([f.x, f.y, f.z, t.x, t.y, t.z], dtype=float)
    if not np.all(np.isfinite(values)):
        return "wrench has non-finite values"
    return values


def clock(ns: int) -> Any:
    """rosgraph_msgs/Clock at ``ns`` (simulation time)."""
    return Clock(clock=stamp(ns))


def duration(ns: int) -> Any:
    """builtin_interfaces/Duration from integer nanoseconds."""
    return Duration(sec=int(ns // NS), nanosec=int(ns % NS))


def joint_reference_message(ns: int, elapsed_ns: int, names: Sequence[str], q: np.ndarray, qd: np.ndarray) -> Any:
    """trajectory_msgs/JointTrajectory with one point: the joint reference (positions, velocities) at a stamp."""
    point = JointTrajectoryPoint(positions=[float(v) for v in q], velocities=[float(v) for v in qd],
                                 time_from_start=duration(elapsed_ns))
    return JointTrajectory(header=header(ns), joint_names=list(names), points=[point])


def joint_reference(msg: Any, order: Mapping[str, int]) -> tuple[int, np.ndarray, np.ndarray] | str:
    """(stamp ns, q_ref, qd_ref) in the model's joint order, or why the message is unusable."""
    names = list(msg.joint_names)
    if len(msg.points) != 1:
        return "joint_reference must carry exactly one point"
    point = msg.points[0]
    idx = joint_indices(names, order, "joint_reference")
    if isinstance(idx, str):
        return idx
    if len(point.positions) != len(names) or len(point.velocities) != len(names):
        return (f"joint_reference with {len(names)} names but {len(point.positions)} positions and "
                f"{len(point.velocities)} velocities")
    q = np.asarray(point.positions, dtype=float)[idx]
    qd = np.asarray(point.velocities, dtype=float)[idx]
    if not (np.all(np.isfinite(q)) and np.all(np.isfinite(qd))):
        return "joint_reference contains NaN or inf"
    return stamp_ns(msg.header.stamp), q, qd
