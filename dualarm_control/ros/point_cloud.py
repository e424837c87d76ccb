"""A sensor_msgs/PointCloud2's points straight from its CDR bytes (issue 42: a 100k-point cloud taken in
within one control period; docs/obstacles.md).

rclpy's ``deserialize_message`` copies the cloud's data into a Python ``array`` and every field into
message objects (0.6 ms for 100,000 points, more under load); :func:`read_point_cloud` reads the few
fields before the data with :class:`~dualarm_control.ros.cdr.Reader` and leaves the data where it is
(a memoryview of the payload), and :func:`cloud_points` views the x, y, z columns in it without a copy
when they are consecutive little-endian FLOAT32 fields (the usual layout). Payloads this reader does not
read exactly raise :class:`~dualarm_control.ros.cdr.CdrError`: the caller then deserializes with rclpy,
which stays the judge of what is malformed.

PointCloud2 in CDR (XCDR1, every primitive aligned to its size from the byte after the 4-byte header):
header (stamp: int32 sec, uint32 nanosec; string frame_id), uint32 height, uint32 width, a sequence of
PointField (string name, uint32 offset, uint8 datatype, uint32 count), bool is_bigendian, uint32
point_step, uint32 row_step, a sequence of uint8 data, bool is_dense.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from dualarm_control.arrays import FloatArray
from dualarm_control.errors import InputRejected
from dualarm_control.ros.cdr import CdrError, Reader

FLOAT32 = 7
"""sensor_msgs/PointField FLOAT32."""
_F32 = np.dtype("<f4")


@dataclass(frozen=True, slots=True)
class Field:
    """A sensor_msgs/PointField: ``name``, byte ``offset`` in a point, ``datatype`` (7: FLOAT32), ``count``."""

    name: str
    offset: int
    datatype: int
    count: int


@dataclass(frozen=True, slots=True)
class Header:
    """What is read of a std_msgs/Header: the frame."""

    frame_id: str


@dataclass(frozen=True, slots=True)
class CloudMessage:
    """The fields of a PointCloud2 that :func:`cloud_points` reads, named as the rclpy message's (so that
    either goes in); ``data`` a read-only view of the payload."""

    header: Header
    height: int
    width: int
    fields: tuple[Field, ...]
    is_bigendian: bool
    point_step: int
    data: memoryview


def read_point_cloud(payload: bytes) -> CloudMessage:
    """A PointCloud2's CDR bytes (module docstring) read without copying its data; CdrError when this
    reader cannot read them (another encoding, truncated, counts beyond the payload)."""
    reader = Reader(payload)
    reader.time()
    frame_id = reader.string()
    height, width = reader.u32(), reader.u32()
    fields = []
    for _ in range(reader.count(13)):  # a name of at least 1 byte with its length, offset, datatype, count
        name, offset = reader.string(), reader.u32()
        datatype = payload[reader._need(1)]
        fields.append(Field(name, offset, datatype, reader.u32()))
    is_bigendian = payload[reader._need(1)] != 0
    point_step = reader.u32()
    reader.u32()  # row_step
    size = reader.count(1)
    start = reader._need(size)
    return CloudMessage(Header(frame_id), height, width, tuple(fields), is_bigendian, point_step,
                        memoryview(payload)[start:start + size])


def cloud_points(msg: Any) -> FloatArray:
    """The (k, 3) x, y, z [m] of a PointCloud2 (FLOAT32 fields x, y, z, little endian; ``msg`` rclpy's or a
    :class:`CloudMessage`): a view of its data when x, y, z are consecutive 4-byte aligned fields, else a
    copy; InputRejected for a cloud this cannot read."""
    fields = {f.name: f for f in msg.fields}
    missing = [c for c in "xyz" if c not in fields or fields[c].datatype != FLOAT32]
    if missing or msg.is_bigendian:
        raise InputRejected(f"point cloud: needs little-endian FLOAT32 fields x, y, z (got "
                            f"{[(f.name, f.datatype) for f in msg.fields]}, big endian {msg.is_bigendian})", "fields")
    count = int(msg.width) * int(msg.height)
    step = int(msg.point_step)
    data = msg.data
    buffer = data if isinstance(data, bytes | bytearray | memoryview) else memoryview(data).cast("B")
    if step < 12 or len(buffer) < count * step:
        raise InputRejected(f"point cloud: {count} points of {step} bytes need {count * step} bytes, got {len(buffer)}",
                            "data", len(buffer))
    x, y, z = (int(fields[c].offset) for c in "xyz")
    if step % 4 == 0 and x % 4 == 0 and y == x + 4 and z == x + 8:  # the usual layout: a strided view
        words = np.frombuffer(buffer, _F32, count * step // 4).reshape(count, step // 4)
        view: FloatArray = words[:, x // 4:x // 4 + 3]  # type: ignore[assignment]
        return view
    dtype = np.dtype({"names": ["x", "y", "z"], "formats": [_F32] * 3, "offsets": [x, y, z], "itemsize": step})
    records = np.frombuffer(buffer, dtype=dtype, count=count)
    points: FloatArray = np.empty((count, 3), dtype=np.float32)  # type: ignore[assignment]
    points[:, 0], points[:, 1], points[:, 2] = records["x"], records["y"], records["z"]
    return points


def cloud_message(payload: bytes, deserialize: Any) -> Any:
    """:func:`read_point_cloud`, or ``deserialize(payload)`` (rclpy's message) when it cannot read them."""
    try:
        return read_point_cloud(payload)
    except CdrError:
        return deserialize(payload)

