"""The CDR writers and readers of dualarm_control.ros.cdr against rclpy's own (de)serialization.

Independent reference: ``rclpy.serialization`` (Fast DDS type support). Every writer's bytes
must deserialize with rclpy to the values written; every reader must return, from rclpy's
bytes, the values of the message rclpy serialized; a truncated or foreign payload must raise
CdrError (then the node falls back to rclpy, which decides whether it is malformed).
Padding bytes are compared through values only: rclpy leaves them undefined.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import (
    PoseStamped,
    Transform,
    Twist,
    Vector3Stamped,
    WrenchStamped,
)
from hypothesis import given, settings
from hypothesis import strategies as st
from rclpy.serialization import deserialize_message, serialize_message
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, MultiArrayDimension
from trajectory_msgs.msg import MultiDOFJointTrajectory, MultiDOFJointTrajectoryPoint

from dualarm_control.errors import InputRejected
from dualarm_control.ros import cdr, convert
from dualarm_control.status import Status

NS = cdr.NS
texts = st.text(st.characters(blacklist_characters="\x00", blacklist_categories=("Cs",)), max_size=12)
"""Any unicode but NUL (a C string ends there) and lone surrogates, 0..12 characters: every alignment."""
floats = st.floats(allow_nan=False, width=64)
stamps = st.integers(min_value=0, max_value=2**31 * NS - 1)


def ns_of(stamp: object) -> int:
    return int(stamp.sec) * NS + int(stamp.nanosec)  # type: ignore[attr-defined]


# ---- writers -> rclpy -----------------------------------------------------------------------------


@settings(max_examples=60, deadline=None)
@given(stamps, st.lists(texts, max_size=16), st.data())
def test_joint_state_writer_reads_back_in_rclpy(ns: int, names: list[str], data: st.DataObject) -> None:
    q = np.array(data.draw(st.lists(floats, min_size=len(names), max_size=len(names))), dtype=float)
    qd = np.array(data.draw(st.lists(floats, min_size=len(names), max_size=len(names))), dtype=float)
    msg = deserialize_message(cdr.joint_state(ns, names, q, qd), JointState)
    assert ns_of(msg.header.stamp) == ns and msg.header.frame_id == ""
    assert list(msg.name) == names and list(msg.effort) == []
    np.testing.assert_array_equal(msg.position, q)
    np.testing.assert_array_equal(msg.velocity, qd)


@settings(max_examples=60, deadline=None)
@given(stamps, st.integers(0, 2), texts, texts, texts, st.dictionaries(texts, st.one_of(texts, st.integers(), floats),
                                                                       max_size=30))
def test_diagnostic_array_writer_reads_back_in_rclpy(ns: int, level: int, name: str, message: str, hw: str,
                                                     values: dict[str, object]) -> None:
    msg = deserialize_message(cdr.diagnostic_array(ns, level, name, message, hw, values), DiagnosticArray)
    assert ns_of(msg.header.stamp) == ns and len(msg.status) == 1
    status = msg.status[0]
    assert (status.level, status.name, status.message, status.hardware_id) == (bytes([level]), name, message, hw)
    assert [(kv.key, kv.value) for kv in status.values] == [(k, str(v)) for k, v in values.items()]


@settings(max_examples=40, deadline=None)
@given(stamps, texts, st.lists(floats, min_size=7, max_size=7), st.lists(floats, min_size=6, max_size=6),
       st.lists(floats, max_size=20))
def test_fixed_layout_writers_read_back_in_rclpy(ns: int, frame: str, seven: list[float], six: list[float],
                                                 values: list[float]) -> None:
    pose = deserialize_message(cdr.stamped_doubles(ns, frame, seven), PoseStamped)
    p, o = pose.pose.position, pose.pose.orientation
    assert (ns_of(pose.header.stamp), pose.header.frame_id) == (ns, frame)
    assert [p.x, p.y, p.z, o.x, o.y, o.z, o.w] == seven
    wrench = deserialize_message(cdr.stamped_doubles(ns, frame, six), WrenchStamped).wrench
    assert [wrench.force.x, wrench.force.y, wrench.force.z, wrench.torque.x, wrench.torque.y, wrench.torque.z] == six
    vector = deserialize_message(cdr.stamped_doubles(ns, frame, six[:3]), Vector3Stamped).vector
    assert [vector.x, vector.y, vector.z] == six[:3]
    assert ns_of(deserialize_message(cdr.clock(ns), Clock).clock) == ns
    array = deserialize_message(cdr.float64_multi_array(values), Float64MultiArray)
    assert list(array.data) == values and list(array.layout.dim) == [] and array.layout.data_offset == 0


@settings(max_examples=40, deadline=None)
@given(stamps, st.integers(0, 10**12), texts, texts, st.lists(floats, min_size=19, max_size=19))
def test_multi_dof_point_writer_reads_back_in_rclpy(ns: int, elapsed: int, frame: str, joint: str,
                                                    v: list[float]) -> None:
    msg = deserialize_message(cdr.multi_dof_point(ns, frame, joint, v[:7], v[7:13], v[13:], elapsed),
                              MultiDOFJointTrajectory)
    assert (ns_of(msg.header.stamp), msg.header.frame_id, list(msg.joint_names)) == (ns, frame, [joint])
    (point,) = msg.points
    (t,), (tw,), (acc,) = point.transforms, point.velocities, point.accelerations
    assert [t.translation.x, t.translation.y, t.translation.z, t.rotation.x, t.rotation.y, t.rotation.z,
            t.rotation.w] == v[:7]
    assert [tw.linear.x, tw.linear.y, tw.linear.z, tw.angular.x, tw.angular.y, tw.angular.z] == v[7:13]
    assert [acc.linear.x, acc.linear.y, acc.linear.z, acc.angular.x, acc.angular.y, acc.angular.z] == v[13:]
    assert ns_of(point.time_from_start) == elapsed


# ---- rclpy -> readers -----------------------------------------------------------------------------


def rclpy_joint_state(ns: int, frame: str, names: list[str], p: list[float], v: list[float],
                      e: list[float]) -> bytes:
    msg = JointState(name=names, position=p, velocity=v, effort=e)
    msg.header.stamp.sec, msg.header.stamp.nanosec, msg.header.frame_id = ns // NS, ns % NS, frame
    return bytes(serialize_message(msg))


@settings(max_examples=80, deadline=None)
@given(stamps, texts, st.lists(texts, max_size=16), st.lists(floats, max_size=16), st.lists(floats, max_size=16),
       st.lists(floats, max_size=4), texts)
def test_joint_state_reader_equals_rclpy(ns: int, frame: str, names: list[str], p: list[float], v: list[float],
                                         e: list[float], other_frame: str) -> None:
    """Any names, counts and frame_id (so any alignment); the second message, same names after
    another frame_id, comes from the names cache and must read the same."""
    read = cdr.JointStateReader()
    for f in (frame, other_frame):
        stamp, got_names, position, velocity = read(rclpy_joint_state(ns, f, names, p, v, e))
        assert (stamp, got_names) == (ns, tuple(names))
        assert position.tolist() == p and velocity.tolist() == v


@settings(max_examples=60, deadline=None)
@given(stamps, st.lists(texts, max_size=3), st.integers(0, 3), st.integers(0, 2), st.integers(0, 2),
       st.lists(floats, min_size=13, max_size=13))
def test_relative_target_reader_equals_rclpy(ns: int, joints: list[str], points: int, transforms: int,
                                             velocities: int, v: list[float]) -> None:
    def point() -> MultiDOFJointTrajectoryPoint:
        t = Transform()
        t.translation.x, t.translation.y, t.translation.z = v[:3]
        t.rotation.x, t.rotation.y, t.rotation.z, t.rotation.w = v[3:7]
        tw = Twist()
        tw.linear.x, tw.linear.y, tw.linear.z, tw.angular.x, tw.angular.y, tw.angular.z = v[7:]
        return MultiDOFJointTrajectoryPoint(transforms=[t] * transforms, velocities=[tw] * velocities,
                                            accelerations=[tw])

    msg = MultiDOFJointTrajectory(joint_names=joints, points=[point() for _ in range(points)])
    msg.header.stamp.sec, msg.header.stamp.nanosec = ns // NS, ns % NS
    stamp, n, t, tw = cdr.relative_target(bytes(serialize_message(msg)))
    assert (stamp, n, t.shape, tw.shape) == (ns, points, (transforms if points else 0, 7),
                                             (velocities if points else 0, 6))
    assert all(row.tolist() == v[:7] for row in t) and all(row.tolist() == v[7:] for row in tw)


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(texts, st.integers(0, 2**32 - 1), st.integers(0, 2**32 - 1)), max_size=3),
       st.lists(floats, max_size=20))
def test_float64_multi_array_reader_equals_rclpy(dims: list[tuple[str, int, int]], values: list[float]) -> None:
    msg = Float64MultiArray(data=values)
    msg.layout.dim = [MultiArrayDimension(label=label, size=size, stride=stride) for label, size, stride in dims]
    assert cdr.float64_multi_array_data(bytes(serialize_message(msg))).tolist() == values


def test_truncated_or_foreign_payloads_raise_cdr_error() -> None:
    """Every prefix shorter than a payload's content, a big-endian header and garbage raise
    CdrError, never a wrong value or another exception (rclpy pads its payloads to 8 bytes:
    a prefix that only lacks that padding reads)."""
    names = [f"joint_{i}" for i in range(14)]
    payloads = {
        "joint_state": (rclpy_joint_state(5, "base", names, [0.1] * 14, [0.2] * 14, []), cdr.JointStateReader(),
                        [5, names, [0.1] * 14, [0.2] * 14]),
        "target": (convert.target_message(5, 0, _sample()), cdr.relative_target,
                   [5, 1, [[0.1, 0.2, 0.3, 0.0, 0.0, 0.0, 1.0]], [[0.0] * 6]]),
        "command": (bytes(serialize_message(Float64MultiArray(data=[0.5] * 14))), cdr.float64_multi_array_data,
                    [0.5] * 14),
    }
    for what, (payload, read, expected) in payloads.items():
        assert _content(read(payload)) == expected, what  # the whole payload reads its content
        reads = []
        for cut in range(len(payload)):
            try:
                value = read(payload[:cut])
            except cdr.CdrError:
                continue
            assert _content(value) == expected, (what, cut)  # a prefix lacking only padding reads the same
            reads.append(cut)
        assert reads == list(range(len(payload) - len(reads), len(payload))) and len(reads) < 8, (what, reads)
        with pytest.raises(cdr.CdrError, match="encapsulation"):
            read(b"\x00\x00\x00\x00" + payload[4:])  # CDR_BE: left to rclpy
        with pytest.raises(cdr.CdrError):
            read(payload[:4] + b"\xff" * (len(payload) - 4))


def _content(value: object) -> object:
    """A reader's result as plain lists (arrays, tuples) to compare with the values serialized."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, tuple):
        return [_content(v) for v in value]
    return value


def _sample() -> object:
    from types import SimpleNamespace
    zero = np.zeros(3)
    return SimpleNamespace(position=np.array([0.1, 0.2, 0.3]), rotation=np.eye(3), linear_velocity=zero,
                           angular_velocity=zero, linear_acceleration=zero, angular_acceleration=zero)


# ---- the node inputs: fast path == message path ---------------------------------------------------


def _decoded(decode: Any, data: Any) -> Any:
    """``decode(data)``, or the rejection's (reason, stamp) (:class:`InputRejected`)."""
    try:
        return decode(data)
    except InputRejected as exc:
        return exc.reason, exc.stamp


def test_inputs_read_the_same_from_bytes_and_from_the_message() -> None:
    """JointStateInput, TargetInput and CommandInput give the same value (or reject it with the same
    reason at the same stamp) from the CDR bytes as from the rclpy message, for good and bad samples."""
    order = {f"j{i}": i for i in range(3)}
    joint_input = convert.JointStateInput(order)
    for names, p, v in ([["j2", "j0", "x", "j1"], [2.0, 0.0, 9.0, 1.0], [0.2, 0.0, 0.0, 0.1]],
                        [["j0", "j1", "j2"], [0.0, 1.0, 2.0], []],
                        [["j0", "j1"], [0.0, 1.0], []],
                        [["j0", "j1", "j2"], [0.0, float("nan"), 2.0], []],
                        [["j0", "j0", "j2"], [0.0, 1.0, 2.0], []]):
        raw = rclpy_joint_state(7, "", names, p, v, [])
        fast = _decoded(joint_input.from_bytes, raw)
        slow = _decoded(joint_input.from_message, deserialize_message(raw, JointState))
        if isinstance(slow[0], str):
            assert fast == slow and slow[1] == 7
        else:
            assert fast[0] == slow[0] == 7
            for a, b in zip(fast[1], slow[1], strict=True):
                np.testing.assert_array_equal(a, b)
    target_input = convert.TargetInput(2.87)
    for position, quat in (([0.1, 0.2, 0.3], (0.0, 0.0, 0.0, 1.0)), ([3.0, 0.0, 0.0], (0.0, 0.0, 0.0, 1.0)),
                           ([0.0, 0.0, 0.0], (0.0, 0.0, 0.0, 0.0)), ([float("nan"), 0.0, 0.0], (0.0, 0.0, 0.0, 1.0))):
        sample = _sample()
        sample.position = np.array(position)  # type: ignore[attr-defined]
        raw = convert.target_message(9, 0, sample)
        if quat[3] == 0.0:  # a zero quaternion cannot come from a rotation matrix: write it directly
            raw = cdr.multi_dof_point(9, "left_tool", "right_tool", [*position, *quat], [0.0] * 6, [0.0] * 6, 0)
        fast_t = _decoded(target_input.from_bytes, raw)
        slow_t = _decoded(target_input.from_message, deserialize_message(raw, MultiDOFJointTrajectory))
        assert type(fast_t[0]) is type(slow_t[0])
        if isinstance(slow_t[0], str):
            assert fast_t == slow_t and slow_t[1] == 9
        else:
            assert fast_t[0] == slow_t[0] == 9
            np.testing.assert_allclose(fast_t[1].position, slow_t[1].position)
            np.testing.assert_allclose(fast_t[1].rotation, slow_t[1].rotation)
    command_input = convert.CommandInput(3)
    for values in ([0.1, 0.2, 0.3], [0.1, 0.2], [0.0, float("inf"), 0.0]):
        raw = cdr.float64_multi_array(values)
        fast_c = _decoded(command_input.from_bytes, raw)
        slow_c = _decoded(command_input.from_message, deserialize_message(raw, Float64MultiArray))
        assert (fast_c == slow_c) if isinstance(slow_c, tuple) else np.array_equal(fast_c, slow_c)


def _random_rotations(n: int, seed: int = 3) -> list[np.ndarray]:
    """Random rotations, and ones near 180 degrees about each axis (every branch of Shepperd's method)."""
    import pinocchio as pin

    rng = np.random.default_rng(seed)
    out = [pin.exp3(rng.normal(size=3) * rng.uniform(0.0, np.pi)) for _ in range(n)]
    for axis in np.eye(3):
        out += [pin.exp3(axis * (np.pi - 1e-9)), pin.exp3((axis + 1e-3 * rng.normal(size=3)) * (np.pi - 1e-3))]
    return out + [np.eye(3)]


def test_quaternion_of_a_rotation_equals_pinocchios_up_to_sign() -> None:
    import pinocchio as pin

    from dualarm_control.ros.convert import quaternion_xyzw, rotation_xyzw

    for rot in _random_rotations(500):
        ours = np.array(quaternion_xyzw(rot))
        theirs = pin.SE3ToXYZQUAT(pin.SE3(rot, np.zeros(3)))[3:]
        theirs = theirs / np.linalg.norm(theirs)
        assert min(np.abs(ours - theirs).max(), np.abs(ours + theirs).max()) < 1e-12
        np.testing.assert_allclose(rotation_xyzw(ours), rot, atol=1e-12)
        np.testing.assert_allclose(rotation_xyzw(ours), pin.Quaternion(ours[3], *ours[:3]).toRotationMatrix(),
                                   atol=1e-14)
    assert np.isnan(quaternion_xyzw(np.full((3, 3), np.nan))).all()
    assert np.isnan(rotation_xyzw(np.zeros(4))).all() and np.isnan(rotation_xyzw(np.array([0, 0, np.inf, 1]))).all()
    np.testing.assert_allclose(rotation_xyzw(np.array([0.0, 0.0, 2.0, 0.0])), np.diag([-1.0, -1.0, 1.0]), atol=1e-15)


def test_one_string_field_equals_a_sequence_of_one_without_its_count() -> None:
    from dualarm_control.ros.cdr import Writer

    for text in ("", "a", "ab", "abc", "abcd", "left_tool", "ü"):
        one, seq = Writer(), Writer()
        one.u32(7)
        seq.u32(7)
        one.string(text)
        seq.strings([text], count=False)
        assert one.bytes() == seq.bytes()


@pytest.mark.parametrize("values", [{}, {"a": 1}, {"solver": "sparse_qp", "cycles": 12, "x": 1.5e-3, "": ""},
                                    {f"key_{i}": "v" * i for i in range(9)},
                                    # values that compare equal but print differently, kept or not (_padded_value)
                                    {"i": 1, "s": "1", "b": True, "f": 1.0, "z": 0.0, "nz": -0.0, "st": Status.SOLVED,
                                     "big": 2**70, "u": "ü", "last": 0}])
def test_diagnostics_writer_reads_back_in_rclpy_for_any_values(values: dict) -> None:
    from rclpy.serialization import deserialize_message

    from dualarm_control.ros.cdr import diagnostic_array

    for _ in range(2):  # the second time from the cached keys
        msg = deserialize_message(diagnostic_array(5, 1, "n", "m", "h", values), DiagnosticArray)
        assert [(kv.key, kv.value) for kv in msg.status[0].values] == [(k, str(v)) for k, v in values.items()]
        assert (msg.status[0].name, msg.status[0].message, msg.status[0].hardware_id) == ("n", "m", "h")
