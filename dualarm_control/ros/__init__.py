"""What rclpy does not do for this package: message <-> core conversions, node plumbing
(validated parameter declaration, clean run/exit), input guards (malformed samples, stamps,
throttled logs: ``inputs``), QoS choices, and the tool verbs (topic: ``graph``, param:
``params_client``, bag record: ``recorder``), as DESIGN.md lays out.

Everything here is plain rclpy (from ROS 2 Jazzy, apt or the ``ros-jazzy-*`` wheels); the
core (kinematics, solvers, controller, ...) never imports this package.
"""
