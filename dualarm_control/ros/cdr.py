"""CDR bytes of the messages the nodes exchange every control period, without rclpy message objects.

At 1 kHz the three nodes spend more time building, converting and parsing rclpy message
objects than computing (docs/bench.md, "1 kHz"): a DiagnosticArray of 26 values costs
about 56 us to build and publish, a MultiDOFJointTrajectory about 61 us to deserialize and
read. The functions here write and read the same bytes directly: the OMG CDR encoding
(XCDR1, little endian, encapsulation ``00 01 00 00``) that rmw_fastrtps_cpp uses for ROS 2
messages; ``Publisher.publish(bytes)`` sends them as a serialized message and any ROS tool
reads them as the standard type.

Layout rules (CDR 1): after the 4-byte encapsulation header, every primitive is aligned to
its size relative to the first byte after the header; a string is a uint32 length (NUL
included), the bytes and a NUL; a sequence is a uint32 count and its elements; nested
structures are their fields in order. Padding is written as zeros (rclpy leaves it
undefined, so tests compare decoded values, never raw bytes).

Readers raise :class:`CdrError` for anything they do not read exactly (another encoding,
a truncated payload, a count larger than the payload); the caller then falls back to
``rclpy.serialization.deserialize_message`` (:func:`dualarm_control.ros.inputs.subscribe_checked`),
so rclpy stays the judge of what is malformed. No rclpy import here.
"""

from __future__ import annotations

import functools
import struct
from collections.abc import Iterable, Mapping, Sequence

import numpy as np

from dualarm_control.errors import DualArmError

ENCAPSULATION_LE = b"\x00\x01\x00\x00"
"""CDR_LE (XCDR1 little endian), options 0: what rmw_fastrtps_cpp writes for ROS 2 types."""
NS = 1_000_000_000
_U32 = struct.Struct("<I")
_TIME = struct.Struct("<iI")
_ZEROS = bytes(8)
_NUL_PAD = (b"\x00", b"\x00\x00\x00\x00", b"\x00\x00\x00", b"\x00\x00")
"""The NUL ending a string of ``n`` bytes with its NUL, and the zeros up to the next 4-byte boundary, by n % 4."""
_F64 = np.dtype("<f8")


class CdrError(DualArmError, ValueError):
    """A payload this reader does not decode (other encoding, truncated, inconsistent counts)."""


class Writer:
    """Appends CDR fields to a buffer that starts with the encapsulation header."""

    __slots__ = ("buf",)

    def __init__(self) -> None:
        self.buf = bytearray(ENCAPSULATION_LE)

    def align(self, size: int) -> None:
        pad = -(len(self.buf) - 4) % size
        if pad:
            self.buf += _ZEROS[:pad]

    def u32(self, value: int) -> None:
        self.align(4)
        self.buf += _U32.pack(value)

    def time(self, ns: int) -> None:
        """builtin_interfaces/Time or Duration (int32 sec, uint32 nanosec) of integer nanoseconds."""
        self.align(4)
        self.buf += _TIME.pack(ns // NS, ns % NS)

    def string(self, text: str) -> None:
        """One string field (as :meth:`strings` of one string without its count, in one append)."""
        raw = text.encode()
        self.align(4)
        self.buf += _U32.pack(len(raw) + 1) + raw + b"\x00"

    def strings(self, texts: Sequence[str], count: bool = True) -> None:
        """sequence<string> (``count=False``: the strings alone, as consecutive string fields).

        One join: every string but the last is followed by its NUL and the zeros up to the
        next 4-byte boundary, which is where the next string's length goes.
        """
        if count:
            self.u32(len(texts))
        if not texts:
            return
        raws = [text.encode() for text in texts]
        self.align(4)
        self.buf += b"".join([_U32.pack(len(raw) + 1) + raw + _NUL_PAD[(len(raw) + 1) % 4] for raw in raws[:-1]])
        self.buf += _U32.pack(len(raws[-1]) + 1) + raws[-1] + b"\x00"

    def doubles(self, values: Iterable[float] | np.ndarray) -> None:
        """Consecutive float64 fields (a fixed-size group such as a Vector3, or a sequence's items)."""
        self.align(8)
        self.buf += np.asarray(values, dtype=_F64).tobytes()

    def double_seq(self, values: Sequence[float] | np.ndarray) -> None:
        """sequence<float64>."""
        self.u32(len(values))
        if len(values):
            self.doubles(values)

    def header(self, ns: int, frame_id: str) -> None:
        """std_msgs/Header."""
        self.time(ns)
        self.string(frame_id)

    def bytes(self) -> bytes:
        return bytes(self.buf)


class Reader:
    """Reads CDR fields from a payload; every read checks the payload's length first
    (:meth:`_need`), so a short payload raises :class:`CdrError`, never ``struct.error``."""

    __slots__ = ("data", "pos")

    def __init__(self, data: bytes) -> None:
        if data[:4] != ENCAPSULATION_LE:
            raise CdrError(f"encapsulation {data[:4].hex()} is not CDR_LE {ENCAPSULATION_LE.hex()}")
        self.data = data
        self.pos = 4

    def align(self, size: int) -> None:
        self.pos += -(self.pos - 4) % size

    def _need(self, size: int) -> int:
        start = self.pos
        if start + size > len(self.data):
            raise CdrError(f"payload of {len(self.data)} bytes ends before byte {start + size}")
        self.pos = start + size
        return start

    def u32(self) -> int:
        self.align(4)
        return int(_U32.unpack_from(self.data, self._need(4))[0])

    def time(self) -> int:
        """Integer nanoseconds of a builtin_interfaces/Time or Duration."""
        self.align(4)
        sec, nanosec = _TIME.unpack_from(self.data, self._need(8))
        return int(sec) * NS + int(nanosec)

    def string(self) -> str:
        size = self.u32()
        if size == 0:
            raise CdrError("string without its terminating NUL")
        start = self._need(size)
        if self.data[start + size - 1] != 0:
            raise CdrError("string not terminated by NUL")
        try:
            return self.data[start:start + size - 1].decode()
        except UnicodeDecodeError as exc:
            raise CdrError(f"string is not UTF-8: {exc}") from None

    def count(self, item_size: int) -> int:
        """A sequence's count, refused when its items cannot fit in the rest of the payload."""
        n = self.u32()
        if n * item_size > len(self.data) - self.pos:
            raise CdrError(f"sequence of {n} items does not fit in the {len(self.data) - self.pos} bytes left")
        return n

    def strings(self) -> tuple[str, ...]:
        return tuple(self.string() for _ in range(self.count(5)))

    def doubles(self, n: int) -> np.ndarray:
        """``n`` consecutive float64 fields, (n,), a read-only view of the payload."""
        if n == 0:
            return np.empty(0)
        self.align(8)
        return np.frombuffer(self.data, _F64, n, self._need(8 * n))

    def double_seq(self) -> np.ndarray:
        return self.doubles(self.count(8))


# --- writers -----------------------------------------------------------------------------
def float64_multi_array(values: Sequence[float] | np.ndarray) -> bytes:
    """std_msgs/Float64MultiArray with an empty layout (JointGroupVelocityController convention)."""
    w = Writer()
    w.u32(0)  # layout.dim: empty
    w.u32(0)  # layout.data_offset
    w.double_seq(values)
    return w.bytes()


def stamped_doubles(ns: int, frame_id: str, values: Sequence[float] | np.ndarray) -> bytes:
    """A std_msgs/Header followed by float64 fields: geometry_msgs/PoseStamped (x, y, z, qx, qy,
    qz, qw) (7,), WrenchStamped [fx, fy, fz, tx, ty, tz] (6,), Vector3Stamped (3,)."""
    w = Writer()
    w.header(ns, frame_id)
    w.doubles(values)
    return w.bytes()


def diagnostic_array(ns: int, level: int, name: str, message: str, hardware_id: str,
                     values: Mapping[str, object]) -> bytes:
    """diagnostic_msgs/DiagnosticArray with one DiagnosticStatus whose values are ``key: str(value)``."""
    w = Writer()
    w.header(ns, "")
    w.u32(1)
    w.buf += bytes([level])
    w.string(name)
    w.string(message)
    w.string(hardware_id)
    w.u32(len(values))
    if values:  # each key and value a string field; a key's bytes are made once (the keys repeat every cycle)
        *pairs, (key, value) = values.items()
        last = str(value).encode()
        w.buf += (b"".join([_padded_key(k) + (_padded_value(v) if type(v) in _KEPT_TYPES else _padded(str(v)))
                            for k, v in pairs]) + _padded_key(key)
                  + _U32.pack(len(last) + 1) + last + b"\x00")  # the last string is not padded
    return w.bytes()


def _padded(text: str) -> bytes:
    """A string field and the zeros up to the next 4-byte boundary (where the next field starts)."""
    raw = text.encode()
    return _U32.pack(len(raw) + 1) + raw + _NUL_PAD[(len(raw) + 1) % 4]


_padded_key = functools.lru_cache(maxsize=256)(_padded)
_KEPT_TYPES = (str, int)
"""The value types whose fields :func:`_padded_value` keeps (exactly these types: an int and its text are different
keys, a float is left out: 0.0 == -0.0 would share one)."""


@functools.lru_cache(maxsize=1024)
def _padded_value(value: str | int) -> bytes:
    """A value's field (:func:`_padded` of ``str(value)``), kept: most of a status's values repeat from one cycle to
    the next (the solver, the counters, the robot); one that changes every cycle is a miss, pushed out by later ones."""
    return _padded(str(value))


@functools.lru_cache(maxsize=8)
def _string_sequence(texts: tuple[str, ...]) -> bytes:
    """The CDR of ``sequence<string>`` written from a 4-byte aligned position (it is position-free there)."""
    w = Writer()
    w.strings(texts)
    return bytes(w.buf[len(ENCAPSULATION_LE):])


def joint_state(ns: int, names: Sequence[str], position: np.ndarray, velocity: np.ndarray) -> bytes:
    """sensor_msgs/JointState with positions [rad] and velocities [rad/s]; effort empty. The names'
    bytes are encoded once per list of names (a joint-state stream repeats them in every message)."""
    w = Writer()
    w.header(ns, "")
    w.align(4)
    w.buf += _string_sequence(tuple(names))
    w.double_seq(position)
    w.double_seq(velocity)
    w.u32(0)
    return w.bytes()


def joint_trajectory_point(names: Sequence[str], positions: Sequence[float] | np.ndarray,
                           velocities: Sequence[float] | np.ndarray, from_start_ns: int) -> bytes:
    """trajectory_msgs/JointTrajectory with a zero header stamp (start now) and one point: ``positions``,
    ``velocities`` (either may be empty), no accelerations or efforts, ``time_from_start``."""
    w = Writer()
    w.header(0, "")
    w.strings(names)
    w.u32(1)  # points
    w.double_seq(positions)
    w.double_seq(velocities)
    w.u32(0)  # accelerations
    w.u32(0)  # effort
    w.time(from_start_ns)
    return w.bytes()


def clock(ns: int) -> bytes:
    """rosgraph_msgs/Clock."""
    w = Writer()
    w.time(ns)
    return w.bytes()


def multi_dof_point(ns: int, frame_id: str, joint_name: str, transform: Sequence[float],
                    twist: Sequence[float], acceleration: Sequence[float], elapsed_ns: int) -> bytes:
    """trajectory_msgs/MultiDOFJointTrajectory with one joint and one point: transform
    (x, y, z, qx, qy, qz, qw) (7,), twist and acceleration (linear, angular) (6,) each, and
    time_from_start."""
    return multi_dof_joints(ns, frame_id, [joint_name], [transform], [twist], [acceleration], elapsed_ns)


def multi_dof_joints(ns: int, frame_id: str, joint_names: Sequence[str], transforms: Sequence[Sequence[float] | np.ndarray],
                     twists: Sequence[Sequence[float] | np.ndarray], accelerations: Sequence[Sequence[float] | np.ndarray],
                     elapsed_ns: int) -> bytes:
    """trajectory_msgs/MultiDOFJointTrajectory with one point of k joints: k transforms (7,), twists and
    accelerations (6,) each, in the order of ``joint_names``, and time_from_start."""
    w = Writer()
    w.header(ns, frame_id)
    w.strings(list(joint_names))
    w.u32(1)  # points
    for block in (transforms, twists, accelerations):
        w.u32(len(block))
        for values in block:
            w.doubles(values)
    w.time(elapsed_ns)
    return w.bytes()


# --- readers -----------------------------------------------------------------------------
class JointStateReader:
    """sensor_msgs/JointState -> (stamp ns, names, position, velocity).

    A joint-state stream repeats its names every message: the bytes of the last names
    sequence are kept, and a message carrying the same bytes reuses the decoded tuple (the
    same object, so a caller may cache what it derives from it by identity).
    """

    __slots__ = ("_names", "_raw")

    def __init__(self) -> None:
        self._raw = b""
        self._names: tuple[str, ...] = ()

    def __call__(self, data: bytes) -> tuple[int, tuple[str, ...], np.ndarray, np.ndarray]:
        r = Reader(data)
        stamp = r.time()
        r.string()  # frame_id
        r.align(4)
        start = r.pos
        if self._raw and data.startswith(self._raw, start):
            r.pos = start + len(self._raw)
            names = self._names
        else:
            names = r.strings()
            self._raw, self._names = data[start:r.pos], names
        position = r.double_seq()
        velocity = r.double_seq()
        r.double_seq()  # effort
        return stamp, names, position, velocity


def relative_target(data: bytes) -> tuple[int, int, np.ndarray, np.ndarray]:
    """trajectory_msgs/MultiDOFJointTrajectory -> (stamp ns, number of points, the first point's
    transforms (k, 7) [x y z qx qy qz qw], the first point's velocities (m, 6) [linear angular]).

    With no point the arrays are empty; with several, only the first is read.
    """
    r = Reader(data)
    stamp = r.time()
    r.string()  # frame_id
    r.strings()  # joint_names
    points = r.count(16)
    if points == 0:
        return stamp, 0, np.empty((0, 7)), np.empty((0, 6))
    transforms = r.doubles(7 * r.count(56)).reshape(-1, 7)
    velocities = r.doubles(6 * r.count(48)).reshape(-1, 6)
    r.doubles(6 * r.count(48))  # accelerations
    r.time()  # time_from_start
    return stamp, points, transforms, velocities


def float64_multi_array_data(data: bytes) -> np.ndarray:
    """std_msgs/Float64MultiArray -> its data (n,), a read-only view of the payload (the layout is read, not used)."""
    r = Reader(data)
    for _ in range(r.count(12)):  # layout.dim: label, size, stride
        r.string()
        r.u32()
        r.u32()
    r.u32()  # layout.data_offset
    return r.double_seq()
