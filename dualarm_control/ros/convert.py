"""Conversions between the core's values and the standard ROS 2 messages (no control math here).

Only ``common_interfaces`` types, so any ROS tool reads what the nodes publish. What the nodes
send or receive every control period is written and read as CDR bytes (:mod:`.cdr`,
``Publisher.publish(bytes)``): at 1 kHz rclpy's message objects cost more than the control
step (docs/bench.md). Inputs are decoded by :class:`JointStateInput` and
:class:`TargetInput`, which read the bytes directly and fall back to the rclpy message
(:func:`dualarm_control.ros.inputs.subscribe_checked`); both paths share the checks. An unusable
message raises :class:`~dualarm_control.errors.InputRejected` with the reason (and its stamp).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from builtin_interfaces.msg import Duration, Time
from std_msgs.msg import Header
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from dualarm_control.errors import InputRejected
from dualarm_control.outputs import CommandDecoder, OutputSpec
from dualarm_control.ros import cdr
from dualarm_control.ros.checks import finite, joint_indices

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


def joint_state(names: Sequence[str], ns: int, q: np.ndarray, qd: np.ndarray) -> bytes:
    """sensor_msgs/JointState (CDR) with positions [rad] and velocities [rad/s]; effort left empty."""
    return cdr.joint_state(ns, names, q, qd)


class JointStateInput:
    """/joint_states -> (stamp ns, (q, qd) in the model's joint order); an unusable message raises
    :class:`InputRejected` (its ``stamp`` set).

    Rejected: duplicate or missing names, a position count different from the name count, a
    velocity count that is neither 0 (then qd = 0) nor the name count, NaN or inf. The name ->
    index mapping is computed once per distinct names tuple (a stream repeats its names; names
    that cannot be mapped are mapped again at each message).
    ``partial`` (one of several joint-state topics, issue 29): the model's joints the message carries,
    in model order, their model indices in :attr:`present`; none of them makes it unusable.
    """

    def __init__(self, order: Mapping[str, int], partial: bool = False) -> None:
        self.order = order
        self.partial = partial
        self.read = cdr.JointStateReader()
        self._names: tuple[str, ...] | None = None
        self._idx: list[int] | None = None  # None: the names are not mapped
        self.present = np.arange(len(order))
        """Model index of each value decoded (``partial``: the model's joints the last message carried)."""
        self._last: tuple[bytes | None, Any] = (None, None)  # the last payload and its answer (from_bytes)

    @property
    def names(self) -> tuple[str, ...] | None:
        """The joint names of the last message decoded (None before one)."""
        return self._names

    def indices(self, names: tuple[str, ...]) -> list[int]:
        """Index in ``names`` of each joint decoded (``partial``: of the model's joints among ``names``,
        whose model indices become :attr:`present`); :class:`InputRejected` if the names are unusable."""
        if not self.partial:
            return joint_indices(list(names), self.order, "joint_states")
        carried = {n: i for n, i in self.order.items() if n in names}
        if not carried:
            raise InputRejected(f"joint_states carries none of the robot's joints (got {list(names)[:3]}...)",
                                "name", names)
        self.present = np.array(list(carried.values()), dtype=int)
        return joint_indices(list(names), carried, "joint_states")

    def from_bytes(self, data: bytes) -> tuple[int, tuple[np.ndarray, np.ndarray]]:
        """The fast path: the CDR payload (raises :class:`cdr.CdrError` if it cannot read it).

        The last payload's answer is kept (the value, or the error raised again): the nodes of one process
        share a decoder per topic (:meth:`~dualarm_control.ros.local_bus.LocalBus.shared`), and the bus hands
        them the same bytes object, decoded once. q and qd are read-only for that reason."""
        if data is self._last[0]:
            answer = self._last[1]
            if isinstance(answer, Exception):
                raise answer
            return answer
        try:
            stamp, names, position, velocity = self.read(data)
            try:
                q, qd = self.vectors(names, position, velocity)
            except InputRejected as exc:
                exc.stamp = stamp
                raise
        except (cdr.CdrError, InputRejected) as exc:
            self._last = (data, exc)
            raise
        q.flags.writeable = qd.flags.writeable = False
        answer = (stamp, (q, qd))
        self._last = (data, answer)
        return answer

    def from_message(self, msg: Any) -> tuple[int, tuple[np.ndarray, np.ndarray]]:
        stamp = stamp_ns(msg.header.stamp)
        try:
            return stamp, self.message_vectors(msg)
        except InputRejected as exc:
            exc.stamp = stamp
            raise

    def message_vectors(self, msg: Any) -> tuple[np.ndarray, np.ndarray]:
        """(q, qd) from a message's ``name``, ``position`` and ``velocity`` (:class:`InputRejected` if unusable)."""
        return self.vectors(tuple(msg.name), np.asarray(msg.position, dtype=float),
                            np.asarray(msg.velocity, dtype=float))

    def vectors(self, names: tuple[str, ...], position: np.ndarray,
                velocity: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(q, qd) [rad, rad/s] in the model's order from a message's fields (:class:`InputRejected` if unusable)."""
        idx = self._idx
        if idx is None or (names is not self._names and names != self._names):
            self._names, self._idx = names, None
            self._idx = idx = self.indices(names)  # InputRejected: not mapped, mapped again at the next message
        n = len(names)
        if len(position) != n or len(velocity) not in (0, n):
            raise InputRejected(f"joint_states with {n} names but {len(position)} positions and {len(velocity)} "
                                "velocities", "position" if len(position) != n else "velocity",
                                (len(position), len(velocity)))
        q = position[idx]
        qd = velocity[idx] if len(velocity) else np.zeros(len(idx))
        if not finite(q) or not finite(qd):
            raise InputRejected("joint_states contains NaN or inf", "position" if not finite(q) else "velocity")
        return q, qd


class CommandInput(CommandDecoder):
    """/velocity_controller/commands (Float64MultiArray) -> the joint velocity command [rad/s], (size,)
    (:class:`InputRejected` if unusable): the default profile's output (:class:`~dualarm_control.outputs.CommandDecoder`)."""

    def __init__(self, size: int) -> None:
        super().__init__(OutputSpec("velocity_controller", "/velocity_controller/commands", "float64_multi_array",
                                    "velocity", tuple(str(i) for i in range(size))))


def float_array(values: np.ndarray) -> bytes:
    """std_msgs/Float64MultiArray (CDR; JointGroupVelocityController convention: layout empty), (n,) values."""
    return cdr.float64_multi_array(values)


def quaternion_xyzw(rotation: np.ndarray) -> tuple[float, float, float, float]:
    """Unit quaternion (x, y, z, w) of a rotation matrix (3, 3), by Shepperd's method (the branch on
    the largest of the trace and the diagonal, as Eigen's ``Quaternion(Matrix3)``), on Python floats:
    a few µs per call where pinocchio's ``SE3ToXYZQUAT`` took about 5 (and building a
    ``pin.Quaternion`` from a matrix leaked 80 bytes per call, eigenpy 3.13). ``q`` and ``-q`` are the
    same rotation; NaN in gives NaN out. Tested against pinocchio on random rotations.
    """
    (m00, m01, m02), (m10, m11, m12), (m20, m21, m22) = np.asarray(rotation, dtype=float).tolist()
    trace = m00 + m11 + m22
    if trace > 0.0:
        s = _twice_root(trace + 1.0)  # 4 w
        x, y, z, w = (m21 - m12) / s, (m02 - m20) / s, (m10 - m01) / s, 0.25 * s
    elif m00 > m11 and m00 > m22:
        s = _twice_root(1.0 + m00 - m11 - m22)  # 4 x
        x, y, z, w = 0.25 * s, (m01 + m10) / s, (m02 + m20) / s, (m21 - m12) / s
    elif m11 > m22:
        s = _twice_root(1.0 + m11 - m00 - m22)  # 4 y
        x, y, z, w = (m01 + m10) / s, 0.25 * s, (m12 + m21) / s, (m02 - m20) / s
    else:
        s = _twice_root(1.0 + m22 - m00 - m11)  # 4 z
        x, y, z, w = (m02 + m20) / s, (m12 + m21) / s, 0.25 * s, (m10 - m01) / s
    norm = math.sqrt(x * x + y * y + z * z + w * w)
    return x / norm, y / norm, z / norm, w / norm


def _twice_root(r: float) -> float:
    """2 sqrt(r), NaN for r <= 0 or NaN (a matrix that is no rotation)."""
    return 2.0 * math.sqrt(r) if r > 0.0 else math.nan


def rotation_xyzw(v: np.ndarray) -> np.ndarray:
    """Rotation matrix (3, 3) of a quaternion (x, y, z, w), (4,), normalised; NaN if non-finite or zero.
    The closed form R = I + 2 w [u]x + 2 [u]x^2 with u = (x, y, z), as Eigen's ``toRotationMatrix``."""
    if not finite(v):
        return np.full((3, 3), np.nan)
    x, y, z, w = (float(c) for c in v)
    n2 = x * x + y * y + z * z + w * w
    if n2 < 1e-18:
        return np.full((3, 3), np.nan)
    s = 2.0 / n2
    xx, yy, zz, xy, xz, yz, wx, wy, wz = s * x * x, s * y * y, s * z * z, s * x * y, s * x * z, s * y * z, \
        s * w * x, s * w * y, s * w * z
    return np.array([[1.0 - yy - zz, xy - wz, xz + wy],
                     [xy + wz, 1.0 - xx - zz, yz - wx],
                     [xz - wy, yz + wx, 1.0 - xx - yy]])


def pose_stamped(ns: int, position: np.ndarray, rot: np.ndarray) -> bytes:
    """Measured relative pose (right tool in left tool frame), geometry_msgs/PoseStamped (CDR)."""
    return cdr.stamped_doubles(ns, LEFT_FRAME, [*position, *quaternion_xyzw(rot)])


@dataclass(frozen=True)
class TargetValue:
    """A relative target decoded from a message (fields as the controller's RelativeTarget).

    ``speed``: max(|linear velocity| [m/s], |angular velocity| [rad/s]), computed once.
    """

    stamp_ns: int
    position: np.ndarray
    rotation: np.ndarray
    linear_velocity: np.ndarray
    angular_velocity: np.ndarray
    speed: float
    absolute: TargetValue | None = None
    """The absolute frame's target riding the same message (its second joint, :data:`ABSOLUTE_JOINT`), or None."""


ABSOLUTE_JOINT = "absolute"
"""Name of /relative_target's second joint: the absolute frame's target (issue 41), pose and twist in the world."""


def target_message(ns: int, elapsed_ns: int, sample: Any, absolute: Any = None) -> bytes:
    """trajectory_msgs/MultiDOFJointTrajectory (CDR) carrying one sample atomically: pose, twist, acceleration;
    with ``absolute`` (the absolute frame's sample, in the world: issue 41) a second joint :data:`ABSOLUTE_JOINT`
    carries it in the same point."""
    samples = (sample,) if absolute is None else (sample, absolute)
    return cdr.multi_dof_joints(
        ns, LEFT_FRAME, [RIGHT_FRAME, ABSOLUTE_JOINT][:len(samples)],
        [np.concatenate((s.position, quaternion_xyzw(s.rotation))) for s in samples],  # arrays: no per-item unpacking
        [np.concatenate((s.linear_velocity, s.angular_velocity)) for s in samples],
        [np.concatenate((s.linear_acceleration, s.angular_acceleration)) for s in samples], elapsed_ns)


def _norm(v: np.ndarray) -> float:
    """||v|| of a short vector, as ``np.linalg.norm`` computes it (sqrt(v . v)), without its Python layer."""
    return math.sqrt(v.dot(v))


class TargetInput:
    """/relative_target -> (stamp ns, :class:`TargetValue`); an unusable message raises
    :class:`InputRejected` (its ``stamp`` set).

    Rejected: not exactly one point with one transform and one velocity, NaN or inf, a zero
    quaternion, a relative position farther than ``max_distance`` [m] (the cell's reach,
    :meth:`DualArmModel.relative_reach`).
    """

    def __init__(self, max_distance: float = float("inf")) -> None:
        self.max_distance = max_distance

    def from_bytes(self, data: bytes) -> tuple[int, TargetValue]:
        """The fast path: the CDR payload (raises :class:`cdr.CdrError` if it cannot read it)."""
        stamp, points, transforms, velocities = cdr.relative_target(data)
        return stamp, self.value(stamp, points, transforms, velocities)

    def from_message(self, msg: Any) -> tuple[int, TargetValue]:
        stamp = stamp_ns(msg.header.stamp)
        points = msg.points
        if not points:
            return stamp, self.value(stamp, 0, np.empty((0, 7)), np.empty((0, 6)))
        transforms = np.array([[t.translation.x, t.translation.y, t.translation.z, t.rotation.x, t.rotation.y,
                                t.rotation.z, t.rotation.w] for t in points[0].transforms], dtype=float)
        velocities = np.array([[v.linear.x, v.linear.y, v.linear.z, v.angular.x, v.angular.y, v.angular.z]
                               for v in points[0].velocities], dtype=float)
        return stamp, self.value(stamp, len(points), transforms, velocities)

    def value(self, stamp: int, points: int, transforms: np.ndarray, velocities: np.ndarray) -> TargetValue:
        """The checks on the first point's transforms (k, 7) [x y z qx qy qz qw] and velocities (m, 6);
        :class:`InputRejected` (at ``stamp`` [ns]) if they fail."""
        if points != 1 or len(transforms) not in (1, 2) or len(velocities) != len(transforms):
            raise InputRejected("relative_target must carry exactly one point with one transform and one velocity "
                                "(and the absolute frame's as a second)", "points",
                                (points, len(transforms), len(velocities)), stamp)
        position, rot, linear, angular = self._pose_twist(stamp, transforms[0], velocities[0])
        absolute = None
        if len(transforms) == 2:
            absolute = TargetValue(stamp, *self._pose_twist(stamp, transforms[1], velocities[1]), 0.0)
        distance = _norm(position)
        if distance > self.max_distance:
            raise InputRejected(f"relative_target position {distance:.3f} m from the left tool is beyond the "
                                f"cell's reach {self.max_distance:.3f} m", "points", distance, stamp)
        speed = max(_norm(linear), _norm(angular))
        if absolute is not None:
            speed = max(speed, _norm(absolute.linear_velocity), _norm(absolute.angular_velocity))
        return TargetValue(stamp, position, rot, linear, angular, speed, absolute)

    @staticmethod
    def _pose_twist(stamp: int, pose: np.ndarray, twist: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(position, rotation, linear, angular) of one joint's transform (7,) and velocity (6,); InputRejected
        when a value is not finite (or the quaternion is zero)."""
        rot = rotation_xyzw(pose[3:])  # NaN when the quaternion is not finite or zero
        values = pose.tolist() + twist.tolist()  # summed in Python: one check for both (finite() on each costs 3x)
        if not (math.isfinite(sum(values)) or all(map(math.isfinite, values))) or not finite(rot):
            raise InputRejected("relative_target contains NaN or inf (or a zero quaternion)", "points",
                                np.concatenate((pose, twist)), stamp)
        return pose[:3].copy(), rot, twist[:3].copy(), twist[3:].copy()


def diagnostics(ns: int, name: str, level: int, message: str, values: Mapping[str, Any]) -> bytes:
    """diagnostic_msgs/DiagnosticArray (CDR) with one status whose values are ``key: str(value)``."""
    return cdr.diagnostic_array(ns, level, name, message, "dualarm_cell", values)


CONTACT_FRAME = "pan_normal"


def world_pose_stamped(ns: int, pose: np.ndarray) -> bytes:
    """geometry_msgs/PoseStamped (CDR) in the frame ``world`` of ``pose`` = (x, y, z [m], qx, qy, qz, qw)."""
    return cdr.stamped_doubles(ns, "world", [float(v) for v in pose])


def wrench_stamped(ns: int, wrench: np.ndarray, frame_id: str = RIGHT_FRAME) -> bytes:
    """geometry_msgs/WrenchStamped (CDR), ``wrench`` = [fx, fy, fz, tx, ty, tz] [N, N m]."""
    return cdr.stamped_doubles(ns, frame_id, wrench)


def contact_force(ns: int, normal_force: float) -> bytes:
    """geometry_msgs/Vector3Stamped (CDR) of the simulator's brush-pan contact: ``vector.z`` is the
    normal contact force [N] (ground truth of the physics, not a sensor), x = y = 0."""
    return cdr.stamped_doubles(ns, CONTACT_FRAME, (0.0, 0.0, float(normal_force)))


def wrench_vector(msg: Any) -> np.ndarray:
    """geometry_msgs/WrenchStamped -> [fx, fy, fz, tx, ty, tz] (6,) [N, N m]; :class:`InputRejected`
    (at the message's stamp) if a value is not finite."""
    f, t = msg.wrench.force, msg.wrench.torque
    values = np.array([f.x, f.y, f.z, t.x, t.y, t.z], dtype=float)
    if not np.all(np.isfinite(values)):
        raise InputRejected("wrench has non-finite values", "wrench", values, stamp_ns(msg.header.stamp))
    return values


def clock(ns: int) -> bytes:
    """rosgraph_msgs/Clock (CDR) at ``ns`` (simulation time)."""
    return cdr.clock(ns)


def duration(ns: int) -> Any:
    """builtin_interfaces/Duration from integer nanoseconds."""
    return Duration(sec=int(ns // NS), nanosec=int(ns % NS))


def joint_reference_message(ns: int, elapsed_ns: int, names: Sequence[str], q: np.ndarray, qd: np.ndarray) -> Any:
    """trajectory_msgs/JointTrajectory with one point: the joint reference (positions, velocities) at a stamp."""
    point = JointTrajectoryPoint(positions=[float(v) for v in q], velocities=[float(v) for v in qd],
                                 time_from_start=duration(elapsed_ns))
    return JointTrajectory(header=header(ns), joint_names=list(names), points=[point])


def joint_reference(msg: Any, order: Mapping[str, int]) -> tuple[int, np.ndarray, np.ndarray]:
    """(stamp ns, q_ref [rad], qd_ref [rad/s]) in the model's joint order; :class:`InputRejected` (at
    the message's stamp) if the message is unusable."""
    stamp = stamp_ns(msg.header.stamp)
    try:
        return (stamp, *_joint_reference_vectors(msg, order))
    except InputRejected as exc:
        exc.stamp = stamp
        raise


def _joint_reference_vectors(msg: Any, order: Mapping[str, int]) -> tuple[np.ndarray, np.ndarray]:
    """(q_ref, qd_ref) of a /joint_reference message's one point, checked (:class:`InputRejected`)."""
    names = list(msg.joint_names)
    if len(msg.points) != 1:
        raise InputRejected("joint_reference must carry exactly one point", "points", len(msg.points))
    point = msg.points[0]
    idx = joint_indices(names, order, "joint_reference")
    if len(point.positions) != len(names) or len(point.velocities) != len(names):
        raise InputRejected(f"joint_reference with {len(names)} names but {len(point.positions)} positions and "
                            f"{len(point.velocities)} velocities", "points",
                            (len(point.positions), len(point.velocities)))
    q = np.asarray(point.positions, dtype=float)[idx]
    qd = np.asarray(point.velocities, dtype=float)[idx]
    if not (np.all(np.isfinite(q)) and np.all(np.isfinite(qd))):
        raise InputRejected("joint_reference contains NaN or inf", "points", np.concatenate((q, qd)))
    return q, qd
