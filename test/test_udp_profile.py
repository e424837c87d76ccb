"""``dualarm faults``' loopback-netem environment sends user data over UDP, not shared memory.

netem on lo (the best_effort_loss row, where the kernel has netem) acts only on what goes through lo.
Under ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` rmw_fastrtps adds a shared-memory transport of its own,
so ``FASTDDS_BUILTIN_TRANSPORTS=UDPv4`` (what the row used before) left same-host traffic in shared memory.
Two processes exchange messages under the row's environment (``matrix.udp_only_env``): they hear each
other and neither maps a Fast DDS shared-memory port (``/dev/shm/fastrtps_port*``); under the package's
default environment the same two processes map one each (the check can fail).
"""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Mapping

from waiting import node_env

from dualarm_control.app.faults.matrix import udp_only_env
from dualarm_control.ros.env import apply_discovery_profile, localhost_environment

PEER = r"""
import os, sys, time
import rclpy
from std_msgs.msg import String

rclpy.init()
node = rclpy.create_node(f"udp_check_{os.getpid()}")
pub = node.create_publisher(String, "/udp_profile_check", 10)
heard = set()
node.create_subscription(String, "/udp_profile_check", lambda m: heard.add(m.data) if m.data != str(os.getpid()) else None, 10)
msg = String(data=str(os.getpid()))
deadline = time.monotonic() + 30.0  # hang guard: discovery on a loaded machine
sent_after = 0
while time.monotonic() < deadline and sent_after < 20:  # go on publishing a while after hearing the peer
    pub.publish(msg)
    rclpy.spin_once(node, timeout_sec=0.02)
    sent_after += bool(heard)
ports = sorted({line.split()[-1] for line in open("/proc/self/maps") if "/dev/shm/fastrtps_port" in line})
print("heard", len(heard), "ports", " ".join(ports) or "-", flush=True)
"""


def _pair(env: Mapping[str, str]) -> list[str]:
    """Run two peers side by side under ``env``; their last lines ("heard N ports ...")."""
    procs = [subprocess.Popen([sys.executable, "-c", PEER], env=dict(env), stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True) for _ in range(2)]
    outs = [p.communicate(timeout=60) for p in procs]
    for p, (_, err) in zip(procs, outs):
        assert p.returncode == 0, err[-2000:]
    return [out.strip().splitlines()[-1] for out, _ in outs]


def _base_env() -> dict[str, str]:
    env = {k: v for k, v in node_env().items()
           if k not in ("ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_STATIC_PEERS", "FASTRTPS_DEFAULT_PROFILES_FILE",
                        "FASTDDS_DEFAULT_PROFILES_FILE", "FASTDDS_BUILTIN_TRANSPORTS")}
    assert env.get("ROS_DOMAIN_ID"), "the session's leased domain (conftest)"
    return env


def test_the_loopback_netem_environment_sends_no_user_data_through_shared_memory() -> None:
    udp = _pair({**_base_env(), **udp_only_env()})
    assert all(line.startswith("heard 1 ports -") for line in udp), udp

    default = localhost_environment(_base_env())
    apply_discovery_profile(default)
    shm = _pair(default)
    assert all(line.startswith("heard 1 ports /dev/shm/fastrtps_port") for line in shm), shm
