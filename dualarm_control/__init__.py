"""dualarm_control: sparse and hierarchical QP kinematic control of a dual-arm relative pose.

The package root is ROS-free: kinematics, limits, solvers, trajectory, metrics and
parameters import with numpy + pinocchio only. Middleware lives in ``dualarm_control.ros``.
"""

__version__ = "0.1.0"
