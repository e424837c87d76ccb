"""Test session set-up: DDS on loopback only, and a private DDS domain per test session."""

from __future__ import annotations

import os
import random

from dualarm_control.ros.dds_env import apply_loopback_default

apply_loopback_default(os.environ)  # before any DomainParticipant; inherited by subprocesses
os.environ.setdefault("ROS_DOMAIN_ID", str(random.SystemRandom().randint(1, 200)))
os.environ.setdefault("MPLBACKEND", "Agg")
