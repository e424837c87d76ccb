"""Private network namespaces for tests and the fault matrix (``ip netns``, ``tc``; needs root).

A :class:`Link` is two namespaces of our own joined by a veth pair whose ends are both named
:data:`LINK_DEVICE`, with addresses that exist only inside them (``10.231.<n>.1/2``; or the
caller's). Nothing is routed to the host's interfaces: traffic stays on the pair. A single
namespace with only ``lo`` is a :class:`Link` with ``peer=False``. Everything is removed on
exit, also after an error.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import uuid
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass

LINK_DEVICE = "dualarm0"
"""Name of the veth end in each namespace (the Fast DDS profile config/fastdds_link.xml binds to it)."""


class NetnsError(RuntimeError):
    """An ``ip``/``tc`` command failed."""


def unavailable() -> str:
    """Why private namespaces cannot be made here ('' if they can)."""
    if os.geteuid() != 0:
        return "needs root for ip netns"
    if shutil.which("ip") is None:
        return "iproute2 'ip' not found"
    return ""


def tc_unavailable() -> str:
    """Why netem cannot be used here ('' if it can)."""
    return unavailable() or ("'tc' not found" if shutil.which("tc") is None else "")


def run(*cmd: str) -> str:
    out = subprocess.run(list(cmd), capture_output=True, text=True, check=False)
    if out.returncode != 0:
        raise NetnsError(f"{' '.join(cmd)}: {out.stderr.strip() or out.returncode}")
    return out.stdout


def exec_prefix(ns: str) -> list[str]:
    """Command prefix running a program inside namespace ``ns`` (the program keeps its pid)."""
    return ["ip", "netns", "exec", ns]


@dataclass(frozen=True)
class Link:
    """Namespaces ``a`` and ``b`` (``b`` empty without a peer) and their addresses on the link."""

    a: str
    b: str
    address_a: str
    address_b: str
    device: str = LINK_DEVICE

    def set_up(self, up: bool) -> None:
        """Bring the link up or down (on ``a``'s side: the carrier drops on both)."""
        run("ip", "-n", self.a, "link", "set", self.device, "up" if up else "down")

    def netem(self, ns: str, device: str, args: Sequence[str]) -> None:
        """``tc qdisc replace ... root netem ARGS`` on ``device`` in ``ns`` (e.g. ``loss 10%``)."""
        run("ip", "netns", "exec", ns, "tc", "qdisc", "replace", "dev", device, "root", "netem", *args)

    def tx_packets(self, ns: str) -> dict[str, int]:
        """Transmitted packets per interface of ``ns`` (``/proc/net/dev``), lo included."""
        text = run("ip", "netns", "exec", ns, "cat", "/proc/net/dev")
        out = {}
        for line in text.splitlines()[2:]:
            name, data = line.split(":", 1)
            out[name.strip()] = int(data.split()[9])
        return out


def _quiet(ns: str) -> None:
    """No IPv6 autoconfiguration chatter (router solicitations) on new links."""
    run("ip", "netns", "exec", ns, "sysctl", "-q", "-w", "net.ipv6.conf.all.disable_ipv6=1",
        "net.ipv6.conf.default.disable_ipv6=1")


@contextmanager
def private_link(peer: bool = True, subnet: str = "", tag: str = "", default_route: bool = False) -> Iterator[Link]:
    """Make namespace ``a`` (lo up) and, with ``peer``, namespace ``b`` joined to it by a veth pair
    named :data:`LINK_DEVICE` on both sides with ``<subnet>.1/24`` and ``<subnet>.2/24``
    (default ``10.231.<random>``); ``default_route`` routes everything of ``a`` through ``b``
    (so any non-loopback packet of ``a`` shows on the link). Deleted on exit."""
    tag = tag or uuid.uuid4().hex[:6]
    subnet = subnet or f"10.231.{int(tag[:2], 16)}"
    names = [f"dualarm_a_{tag}"] + ([f"dualarm_b_{tag}"] if peer else [])
    made: list[str] = []
    try:
        for ns in names:
            run("ip", "netns", "add", ns)
            made.append(ns)
            _quiet(ns)
            run("ip", "-n", ns, "link", "set", "lo", "up")
        if not peer:
            yield Link(names[0], "", "127.0.0.1", "")
            return
        a, b = names
        run("ip", "link", "add", f"va{tag}", "type", "veth", "peer", "name", f"vb{tag}")
        for ns, dev, addr in ((a, f"va{tag}", f"{subnet}.1"), (b, f"vb{tag}", f"{subnet}.2")):
            run("ip", "link", "set", dev, "netns", ns)
            run("ip", "-n", ns, "link", "set", dev, "name", LINK_DEVICE)
            run("ip", "-n", ns, "addr", "add", f"{addr}/24", "dev", LINK_DEVICE)
            run("ip", "-n", ns, "link", "set", LINK_DEVICE, "up")
        if default_route:
            run("ip", "-n", a, "route", "add", "default", "via", f"{subnet}.2")
        yield Link(a, b, f"{subnet}.1", f"{subnet}.2")
    finally:
        for ns in made:
            subprocess.run(["ip", "netns", "del", ns], check=False, capture_output=True)


def netem_unavailable() -> str:
    """Why ``tc ... netem`` cannot be used here ('' if it can): tried on lo of a throw-away namespace."""
    reason = tc_unavailable()
    if reason:
        return reason
    with private_link(peer=False) as link:
        try:
            link.netem(link.a, "lo", ["loss", "0%"])
        except NetnsError as exc:
            return f"netem not usable on this kernel ({exc})"
    return ""
