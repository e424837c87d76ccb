"""What rclpy does not do for this package: message <-> core conversions, node plumbing
(validated parameter declaration, clean run/exit), input guards (malformed samples, stamps,
throttled logs: ``inputs``) and QoS choices. The tool verbs built on rclpy (topic, param,
bag record) are applications: ``dualarm_control.app.graph``, ``params_client``, ``recorder``.

Everything here is plain rclpy (from ROS 2 Jazzy, apt or the ``ros-jazzy-*`` wheels); the
core (kinematics, solvers, controller, ...) never imports this package.
"""
