"""Test session set-up: ROS traffic on localhost only, and a private ROS domain per test session."""

from __future__ import annotations

import os
import random

from dualarm_control.ros.env import apply_localhost_default

apply_localhost_default()  # before rclpy.init; inherited by subprocesses
# Always a private domain (not the user's interactive one), unless DUALARM_TEST_DOMAIN_ID says which.
os.environ["ROS_DOMAIN_ID"] = os.environ.get("DUALARM_TEST_DOMAIN_ID") or str(random.SystemRandom().randint(1, 101))
os.environ.setdefault("MPLBACKEND", "Agg")
