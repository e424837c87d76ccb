"""A PointCloud2 read straight from its CDR bytes (dualarm_control/ros/point_cloud.py; issue 42's cloud intake):
the same frame, fields and points as rclpy's deserialized message, the usual layouts as views of the payload,
others copied, payloads it cannot read left to rclpy."""

from __future__ import annotations

import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import PointCloud2, PointField

from dualarm_control.ros.cdr import CdrError
from dualarm_control.ros.point_cloud import (
    cloud_message,
    cloud_points,
    read_point_cloud,
)


def cloud(points: np.ndarray, layout: str = "xyz", step: int = 16, frame: str = "camera_depth_optical_frame",
          height: int = 1) -> bytes:
    """``points`` (k, 3) in the fields of ``layout`` order (one 4-byte float each, an ``rgb`` word after them
    when ``step`` has room)."""
    msg = PointCloud2()
    msg.header.frame_id = frame
    msg.header.stamp.sec, msg.header.stamp.nanosec = 12, 345
    msg.height, msg.width = height, len(points) // height
    names = list(layout) + (["rgb"] if step >= 16 else [])
    msg.fields = [PointField(name=c, offset=4 * i, datatype=PointField.FLOAT32, count=1) for i, c in enumerate(names)]
    msg.point_step, msg.row_step, msg.is_dense = step, step * msg.width, True
    words = np.zeros((len(points), step // 4), dtype=np.float32)
    for i, c in enumerate(layout):
        words[:, i] = points[:, "xyz".index(c)]
    if step >= 16:
        words[:, len(layout)] = 7.0
    msg.data = words.tobytes()
    return bytes(serialize_message(msg))


@pytest.mark.parametrize(("layout", "step", "height"), [("xyz", 16, 1), ("xyz", 12, 1), ("xyz", 32, 4), ("zyx", 16, 1)])
def test_the_bytes_read_as_rclpy_reads_them(layout: str, step: int, height: int) -> None:
    points = np.random.default_rng(0).uniform(-2.0, 2.0, (1000, 3)).astype(np.float32)
    data = cloud(points, layout, step, height=height)
    ours, theirs = read_point_cloud(data), deserialize_message(data, PointCloud2)
    assert ours.header.frame_id == theirs.header.frame_id == "camera_depth_optical_frame"
    assert (ours.height, ours.width, ours.point_step) == (theirs.height, theirs.width, theirs.point_step)
    assert [(f.name, f.offset, f.datatype, f.count) for f in ours.fields] == \
        [(f.name, f.offset, f.datatype, f.count) for f in theirs.fields]
    assert bytes(ours.data) == bytes(theirs.data)
    mine = cloud_points(ours)
    assert np.array_equal(mine, cloud_points(theirs)) and np.array_equal(mine, points)
    assert np.shares_memory(mine, np.frombuffer(data, np.uint8)) == (layout == "xyz")  # the usual layout: a view


def test_payloads_it_cannot_read_go_to_rclpy() -> None:
    data = cloud(np.zeros((10, 3), dtype=np.float32))
    asked: list[bytes] = []
    for bad in (b"\x00\x00\x00\x00" + data[4:], data[:60], b"\x00\x01\x00\x00garbage"):  # big endian, short, junk
        with pytest.raises(CdrError):
            read_point_cloud(bad)
        assert cloud_message(bad, lambda payload: asked.append(payload) or "rclpy's") == "rclpy's"
        assert asked[-1] is bad
