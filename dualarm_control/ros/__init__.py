"""The one place that knows about ROS: rclpy when importable, else the Cyclone DDS runtime.

Nodes are written once against this API::

    from dualarm_control import ros

    ros.init(args)
    node = ros.Node("controller_node")
    rate = node.declare_parameter("rate_hz", 200.0, description="control rate").value
    pub = node.create_publisher(ros.msgs.Float64MultiArray, "/velocity_controller/commands", 10)
    node.create_subscription(ros.msgs.JointState, "/joint_states", on_joint_states, 10)
    node.create_timer(1.0 / rate, on_tick)
    try:
        ros.spin(node)
    except (KeyboardInterrupt, ros.ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        ros.try_shutdown()

``BACKEND`` is ``"rclpy"`` when ``import rclpy`` works and ``DUALARM_MIDDLEWARE`` is not
``cyclonedds``; then everything here is rclpy's own (messages are the real
``sensor_msgs.msg`` etc. classes). Otherwise it is ``"cyclonedds"``: the
:mod:`dualarm_control.ros.dds_runtime` node, byte-compatible with rmw_cyclonedds_cpp.

Importing this package applies the loopback Cyclone DDS config
(:func:`dualarm_control.ros.dds_env.apply_loopback_default`) unless the user set
``CYCLONEDDS_URI`` or ``ROS_AUTOMATIC_DISCOVERY_RANGE``: import it before any DDS
participant is created.
"""

from __future__ import annotations

import os

from dualarm_control.ros.dds_env import apply_loopback_default

apply_loopback_default()


def _rclpy_available() -> bool:
    if os.environ.get("DUALARM_MIDDLEWARE", "").strip().lower() == "cyclonedds":
        return False
    try:
        import rclpy  # noqa: F401
    except ImportError:
        return False
    return True


if _rclpy_available():
    try:  # keep the Cyclone message module importable without it replacing ``msgs`` below
        import dualarm_control.ros.msgs  # noqa: F401
    except ImportError:
        pass
    from dualarm_control.ros._rclpy_backend import (
        DurabilityPolicy,
        Duration,
        ExternalShutdownException,
        HistoryPolicy,
        InvalidParameterTypeException,
        Node,
        Parameter,
        ParameterNotDeclaredException,
        QoSProfile,
        ReliabilityPolicy,
        SingleThreadedExecutor,
        Time,
        get_logger,
        init,
        msgs,
        ok,
        qos_profile_sensor_data,
        remove_ros_args,
        shutdown,
        spin,
        spin_once,
        try_shutdown,
    )

    BACKEND = "rclpy"
else:
    from dualarm_control.ros import msgs
    from dualarm_control.ros.clock import Duration, Time
    from dualarm_control.ros.dds_runtime import (
        ExternalShutdownException,
        Node,
        SingleThreadedExecutor,
        init,
        ok,
        remove_ros_args,
        shutdown,
        spin,
        spin_once,
        try_shutdown,
    )
    from dualarm_control.ros.log import get_logger
    from dualarm_control.ros.parameters import (
        InvalidParameterTypeException,
        Parameter,
        ParameterNotDeclaredException,
    )
    from dualarm_control.ros.qos import (
        DurabilityPolicy,
        HistoryPolicy,
        QoSProfile,
        ReliabilityPolicy,
        qos_profile_sensor_data,
    )

    BACKEND = "cyclonedds"

__all__ = [
    "BACKEND",
    "DurabilityPolicy",
    "Duration",
    "ExternalShutdownException",
    "HistoryPolicy",
    "InvalidParameterTypeException",
    "Node",
    "Parameter",
    "ParameterNotDeclaredException",
    "QoSProfile",
    "ReliabilityPolicy",
    "SingleThreadedExecutor",
    "Time",
    "apply_loopback_default",
    "get_logger",
    "init",
    "msgs",
    "ok",
    "qos_profile_sensor_data",
    "remove_ros_args",
    "shutdown",
    "spin",
    "spin_once",
    "try_shutdown",
]
