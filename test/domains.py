"""ROS domains held by one test at a time, across every test process on this machine (issue 38).

A test that starts nodes runs them on a ROS domain that no other live test holds: this pytest
process's session domain, or one leased for a launch (:func:`leased`). A lease is an exclusive
``flock`` on ``<tmp>/dualarm-ros-domains/<id>.lock``; the kernel drops it when the holder closes it
or dies, so a killed run leaves no stale lease. pytest-xdist workers, a second ``make test`` and
a CI run beside a developer's session all draw from the same locks, so no two of them share a
domain (before, each process drew its domain at random from 1..101, uncoordinated, and one test's
nodes could answer another's). Domain ids 1..101 are safe on Linux (higher ones reach into the
ephemeral port range). ``DUALARM_TEST_DOMAIN_ID`` fixes the session's domain (a machine where only
that one is free); it is leased like any other and refused, naming the holder, if held.
"""

from __future__ import annotations

import fcntl
import os
import random
import tempfile
from collections.abc import Iterator
from contextlib import AbstractContextManager, ExitStack, contextmanager
from pathlib import Path

DOMAINS = range(1, 102)
LOCK_DIR = Path(tempfile.gettempdir()) / "dualarm-ros-domains"


class DomainLease:
    """One ROS domain id held by this process until :meth:`release` (or its exit)."""

    def __init__(self, domain: int, fd: int) -> None:
        self.domain, self._fd = domain, fd

    @property
    def env(self) -> dict[str, str]:
        """What a launch on this domain adds to its environment."""
        return {"ROS_DOMAIN_ID": str(self.domain)}

    def release(self) -> None:
        if self._fd >= 0:
            os.close(self._fd)  # drops the flock
            self._fd = -1


class DomainPool:
    """The ROS domains ``ids`` leased through lock files in ``lock_dir`` (one per domain)."""

    def __init__(self, lock_dir: Path = LOCK_DIR, ids: range = DOMAINS) -> None:
        self.lock_dir, self.ids = lock_dir, ids

    def try_lease(self, domain: int) -> DomainLease | None:
        """The lease of ``domain``, or None when another process (or this one) holds it."""
        self.lock_dir.mkdir(parents=True, exist_ok=True)
        fd = os.open(self.lock_dir / f"{domain}.lock", os.O_RDWR | os.O_CREAT, 0o666)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            return None
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode())
        return DomainLease(domain, fd)

    def holder(self, domain: int) -> str:
        """The pid written by the last holder of ``domain``'s lease ('' if none was written)."""
        try:
            return (self.lock_dir / f"{domain}.lock").read_text().strip()
        except OSError:
            return ""

    def lease_any(self) -> DomainLease:
        """A lease of a free domain, drawn at random; RuntimeError when all are held."""
        for domain in random.SystemRandom().sample(list(self.ids), len(self.ids)):
            lease = self.try_lease(domain)
            if lease is not None:
                return lease
        raise RuntimeError(f"every ROS domain {self.ids.start}..{self.ids.stop - 1} is held by a test process "
                           f"(locks in {self.lock_dir})")

    def lease_session(self, fixed: str | None) -> DomainLease:
        """A test process's own domain: ``fixed`` (``DUALARM_TEST_DOMAIN_ID``) if set, refused when held;
        else any free one."""
        if not fixed:
            return self.lease_any()
        lease = self.try_lease(int(fixed))
        if lease is None:
            raise RuntimeError(f"DUALARM_TEST_DOMAIN_ID={fixed}: that ROS domain is held by another test process "
                               f"(pid {self.holder(int(fixed)) or '?'}); unset it to draw a free one")
        return lease

    @contextmanager
    def leased(self, count: int) -> Iterator[list[dict[str, str]]]:
        """``count`` environments, each with a ROS domain of its own held for the context's life."""
        with ExitStack() as stack:
            envs = []
            for _ in range(count):
                lease = self.lease_any()
                stack.callback(lease.release)
                envs.append(lease.env)
            yield envs


MACHINE = DomainPool()
"""The machine's pool: every test process on this machine leases from it."""


def lease_session() -> DomainLease:
    """This test process's domain (:meth:`DomainPool.lease_session` with ``DUALARM_TEST_DOMAIN_ID``)."""
    return MACHINE.lease_session(os.environ.get("DUALARM_TEST_DOMAIN_ID"))


def leased(count: int) -> AbstractContextManager[list[dict[str, str]]]:
    """``count`` domains of the machine's pool for a context (:meth:`DomainPool.leased`)."""
    return MACHINE.leased(count)
