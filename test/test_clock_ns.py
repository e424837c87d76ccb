"""ros/node.py ``clock_ns``: an rclpy clock's reading in integer nanoseconds, as ``Clock.now()`` gives it."""

from __future__ import annotations

import rclpy
from rclpy.context import Context
from rclpy.time import Time

from dualarm_control.ros.node import clock_ns


def test_clock_ns_reads_the_clock_as_now_does_and_follows_a_ros_time_override() -> None:
    context = Context()
    rclpy.init(context=context)
    try:
        node = rclpy.create_node("_test_clock_ns", context=context)
        clock = node.get_clock()
        before = clock.now().nanoseconds
        reading = clock_ns(clock)
        after = clock.now().nanoseconds
        assert isinstance(reading, int)
        assert before <= reading <= after, (before, reading, after)
        clock._set_ros_time_is_active(True)  # what use_sim_time does on the first /clock message
        clock.set_ros_time_override(Time(nanoseconds=1_234_567_891, clock_type=clock.clock_type))
        assert clock_ns(clock) == clock.now().nanoseconds == 1_234_567_891
        node.destroy_node()
    finally:
        rclpy.shutdown(context=context)
