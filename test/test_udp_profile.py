"""The package's processes send their user data over UDP, never through Fast DDS shared memory.

Why (config/fastdds_discovery.xml, docs/safety.md "A peer killed mid-message"): a process killed while its
shared-memory listener held its port's interprocess mutex leaves it locked, and the next peer that writes to
that port waits up to boost's 10 s lock timeout while holding its writer's send mutex; the simulator stopped
stepping after a SIGKILLed controller. The package's profile gives every participant a UDPv4 default unicast
locator, so none announces a shared-memory one. ``FASTDDS_BUILTIN_TRANSPORTS=UDPv4`` does not do it: under
``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` rmw_fastrtps installs its own shared-memory transport.

Two processes exchange messages: under the package's default environment and under ``dualarm faults``'
loopback-netem one (``ros.env.udp_only_env``: netem on lo acts only on what goes through lo) they hear each
other and neither maps a shared-memory port (``/dev/shm/fastrtps_port*``); under the same discovery settings
with a profile that lacks the locator and ``FASTDDS_BUILTIN_TRANSPORTS=UDPv4`` (what the netem row set
before) both map one (the check can fail).
"""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Mapping
from pathlib import Path

import pytest
from waiting import node_env

from dualarm_control.ros.env import (
    FASTDDS_USER_PROFILES,
    apply_discovery_profile,
    localhost_environment,
    udp_only_env,
)

PEER = r"""
import os, time
import rclpy
from std_msgs.msg import String

rclpy.init()
node = rclpy.create_node(f"udp_check_{os.getpid()}")
pub = node.create_publisher(String, "/udp_profile_check", 10)
heard, acked = set(), set()  # peers heard; peers that said they heard someone (a handshake: neither leaves early)


def on_message(m):
    pid, peer_heard = m.data.split()
    if pid != str(os.getpid()):
        heard.add(pid)
        if peer_heard == "1":
            acked.add(pid)


node.create_subscription(String, "/udp_profile_check", on_message, 10)
msg = String()
deadline = time.monotonic() + 60.0  # hang guard: discovery on a loaded machine
sent_after = 0
while time.monotonic() < deadline and sent_after < 20:  # go on publishing a while after the handshake
    msg.data = f"{os.getpid()} {int(bool(heard))}"
    pub.publish(msg)
    rclpy.spin_once(node, timeout_sec=0.02)
    sent_after += bool(acked)
ports = sorted({line.split()[-1] for line in open("/proc/self/maps") if "/dev/shm/fastrtps_port" in line})
print("heard", len(heard), "ports", " ".join(ports) or "-", flush=True)
# the check is done: leave without the interpreter's finalization, whose rclpy and Fast DDS teardown can hang (a peer
# that had printed its line was still there 120 s later in a loaded fresh clone's run; the exit is not under test)
os._exit(0)
"""

NO_LOCATOR = """<?xml version="1.0" encoding="UTF-8" ?>
<dds><profiles xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles">
  <participant profile_name="no_locator" is_default_profile="true"><rtps><builtin><discovery_config>
    <leaseAnnouncement><sec>0</sec><nanosec>100000000</nanosec></leaseAnnouncement>
  </discovery_config></builtin></rtps></participant>
</profiles></dds>
"""


def _pair(env: Mapping[str, str]) -> list[str]:
    """Run two peers side by side under ``env``; their last lines ("heard N ports ...")."""
    procs = [subprocess.Popen([sys.executable, "-c", PEER], env=dict(env), stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True) for _ in range(2)]
    outs = [p.communicate(timeout=120) for p in procs]
    for p, (_, err) in zip(procs, outs):
        assert p.returncode == 0, err[-2000:]
    return [out.strip().splitlines()[-1] for out, _ in outs]


def _base_env() -> dict[str, str]:
    """This test process's environment without any discovery or Fast DDS setting (the session's ROS domain kept)."""
    env = {k: v for k, v in node_env().items()
           if k not in ("ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_STATIC_PEERS", "FASTDDS_BUILTIN_TRANSPORTS",
                        *FASTDDS_USER_PROFILES)}
    assert env.get("ROS_DOMAIN_ID"), "the session's leased domain (conftest)"
    return env


def _package_default() -> dict[str, str]:
    """What every node and tool of the package runs with when the user set nothing (ros/env.py)."""
    env = localhost_environment(_base_env())
    assert apply_discovery_profile(env)
    return env


@pytest.mark.parametrize("environment", [_package_default, lambda: {**_base_env(), **udp_only_env()}],
                         ids=["package default", "faults loopback netem"])
def test_user_data_never_goes_through_shared_memory(environment) -> None:  # type: ignore[no-untyped-def]
    lines = _pair(environment())
    assert all(line.startswith("heard 1 ports -") for line in lines), lines


def test_without_the_locator_shared_memory_is_used(tmp_path: Path) -> None:
    """The control: LOCALHOST, the package's discovery timing without the locator, and FASTDDS_BUILTIN_TRANSPORTS=UDPv4."""
    profile = tmp_path / "no_locator.xml"
    profile.write_text(NO_LOCATOR)
    lines = _pair({**_base_env(), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
                   "FASTRTPS_DEFAULT_PROFILES_FILE": str(profile), "FASTDDS_BUILTIN_TRANSPORTS": "UDPv4"})
    assert all(line.startswith("heard 1 ports /dev/shm/fastrtps_port") for line in lines), lines
