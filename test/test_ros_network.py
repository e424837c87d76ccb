"""ROS traffic stays on this machine: a full launch sends zero packets on any interface but loopback.

The launch runs inside a network namespace that this test makes (``ip netns``), whose only
non-loopback interface is one end of a veth pair leading to a second namespace of the
test's own, with a default route through it: a process there that used multicast or any
non-loopback address would send packets on the veth end. The interface counters
(``/proc/net/dev`` of the namespace) are compared before and after. A control run with
``ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET`` shows the same counters do move when discovery
is allowed off the host. Needs root and iproute2; skipped otherwise.
"""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from dualarm_control.app.faults.netns import (
    LINK_DEVICE,
    Link,
    exec_prefix,
    private_link,
    unavailable,
)

REPO = Path(__file__).resolve().parents[1]
SHORT = Path(__file__).parent / "data" / "short.yaml"

pytestmark = pytest.mark.skipif(bool(unavailable()), reason=unavailable() or "namespaces available")


@pytest.fixture
def link() -> Iterator[Link]:
    """Namespace ``a`` with lo and the veth end, default route through it to the peer namespace."""
    with private_link(subnet="192.0.2", default_route=True) as made:  # TEST-NET-1, only between the two
        yield made


def tx_packets(link: Link) -> dict[str, int]:
    """Transmitted packets per interface of namespace ``a`` but lo."""
    return {k: v for k, v in link.tx_packets(link.a).items() if k != "lo"}


def launch_in(ns: str, env: dict[str, str]) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*exec_prefix(ns), sys.executable, "-m", "dualarm_control.app.cli", "launch",
                           str(SHORT), "--lockstep", "--timeout", "120"], cwd=REPO, env=env, capture_output=True,
                          text=True, timeout=180, check=False)


def test_launch_sends_nothing_off_loopback(link: Link) -> None:
    env = {k: v for k, v in os.environ.items() if k != "ROS_AUTOMATIC_DISCOVERY_RANGE"}  # the package's default
    before = tx_packets(link)
    out = launch_in(link.a, env)
    after = tx_packets(link)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]
    assert "[launch] scenario complete" in out.stdout
    assert {k: after[k] - before[k] for k in after} == {LINK_DEVICE: 0}


def test_control_subnet_discovery_does_send(link: Link) -> None:
    """The counters are live: allowing subnet discovery sends packets on the link."""
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="SUBNET")
    before = tx_packets(link)
    out = launch_in(link.a, env)
    after = tx_packets(link)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]
    assert after[LINK_DEVICE] - before[LINK_DEVICE] > 0
