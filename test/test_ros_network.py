"""ROS traffic stays on this machine: a full launch sends zero packets on any interface but loopback.

The launch runs inside a network namespace that this test makes (``ip netns``), whose only
non-loopback interface is one end of a veth pair leading to a second namespace of the
test's own, with a default route through it: a process there that used multicast or any
non-loopback address would send packets on ``eth0``. The interface counters
(``/proc/net/dev`` of the namespace) are compared before and after. A control run with
``ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET`` shows the same counters do move when discovery
is allowed off the host. Needs root and iproute2; skipped otherwise.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import uuid
from collections.abc import Iterator
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHORT = Path(__file__).parent / "data" / "short.yaml"

pytestmark = pytest.mark.skipif(os.geteuid() != 0 or shutil.which("ip") is None,
                                reason="needs root and iproute2 for a private network namespace")


def ip(*args: str) -> None:
    subprocess.run(["ip", *args], check=True, capture_output=True, text=True)


@pytest.fixture
def namespace() -> Iterator[str]:
    """A namespace ``host`` with lo and eth0 (veth to a peer namespace), default route via eth0."""
    tag = uuid.uuid4().hex[:6]
    host, peer = f"dualarm_h_{tag}", f"dualarm_p_{tag}"
    ip("netns", "add", host)
    ip("netns", "add", peer)
    try:
        for ns in (host, peer):  # no IPv6 autoconfiguration chatter (router solicitations) on the new link
            subprocess.run(["ip", "netns", "exec", ns, "sysctl", "-q", "-w", "net.ipv6.conf.all.disable_ipv6=1",
                            "net.ipv6.conf.default.disable_ipv6=1"], check=True, capture_output=True)
        ip("link", "add", f"va{tag}", "type", "veth", "peer", "name", f"vb{tag}")
        ip("link", "set", f"va{tag}", "netns", host)
        ip("link", "set", f"vb{tag}", "netns", peer)
        ip("-n", host, "link", "set", f"va{tag}", "name", "eth0")
        ip("-n", host, "addr", "add", "192.0.2.1/24", "dev", "eth0")  # TEST-NET-1, only between the two
        ip("-n", peer, "addr", "add", "192.0.2.2/24", "dev", f"vb{tag}")
        for ns, dev in ((host, "eth0"), (host, "lo"), (peer, f"vb{tag}"), (peer, "lo")):
            ip("-n", ns, "link", "set", dev, "up")
        ip("-n", host, "route", "add", "default", "via", "192.0.2.2")
        yield host
    finally:
        subprocess.run(["ip", "netns", "del", host], check=False)
        subprocess.run(["ip", "netns", "del", peer], check=False)


def tx_packets(ns: str) -> dict[str, int]:
    """Transmitted packets per interface but lo, from the namespace's /proc/net/dev."""
    text = subprocess.run(["ip", "netns", "exec", ns, "cat", "/proc/net/dev"], check=True, capture_output=True,
                          text=True).stdout
    out = {}
    for line in text.splitlines()[2:]:
        name, data = line.split(":", 1)
        if name.strip() != "lo":
            out[name.strip()] = int(data.split()[9])
    return out


def launch_in(ns: str, env: dict[str, str]) -> subprocess.CompletedProcess[str]:
    return subprocess.run(["ip", "netns", "exec", ns, sys.executable, "-m", "dualarm_control.app.cli", "launch",
                           str(SHORT), "--lockstep", "--timeout", "120"], cwd=REPO, env=env, capture_output=True,
                          text=True, timeout=180, check=False)


def test_launch_sends_nothing_off_loopback(namespace: str) -> None:
    env = {k: v for k, v in os.environ.items() if k != "ROS_AUTOMATIC_DISCOVERY_RANGE"}  # the package's default
    before = tx_packets(namespace)
    out = launch_in(namespace, env)
    after = tx_packets(namespace)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]
    assert "[launch] scenario complete" in out.stdout
    assert {k: after[k] - before[k] for k in after} == {"eth0": 0}


def test_control_subnet_discovery_does_send(namespace: str) -> None:
    """The counters are live: allowing subnet discovery sends packets on eth0."""
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="SUBNET")
    before = tx_packets(namespace)
    out = launch_in(namespace, env)
    after = tx_packets(namespace)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]
    assert after["eth0"] - before["eth0"] > 0
