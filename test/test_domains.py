"""Test processes never share a ROS domain (test/domains.py, issue 38): a domain another process holds is
never drawn, a fixed one that is held is refused naming the holder, and a holder's death frees its domains.

Before the leases each pytest process drew its domain at random from 1..101 and each launch drew from
what was left of the session's, uncoordinated: with all domains but one held elsewhere, such a draw
lands on a held one 4 times in 5 here. The pools below are private (their own lock directory), so
that the tests' other processes keep drawing from the machine's pool meanwhile.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from domains import DomainPool

HOLDER = """
import sys
from pathlib import Path
sys.path.insert(0, {test_dir!r})
from domains import DomainPool
pool = DomainPool(Path({lock_dir!r}), range(1, 6))
held = [pool.try_lease(d) for d in pool.ids if d not in {keep}]
print(sum(lease is not None for lease in held), flush=True)
sys.stdin.read()  # hold until the test closes stdin (or kills this process)
"""


def holder(pool: DomainPool, keep: set[int]) -> subprocess.Popen[str]:
    """A process holding every domain of ``pool`` but ``keep`` (started once it holds them)."""
    proc = subprocess.Popen([sys.executable, "-c", HOLDER.format(test_dir=str(Path(__file__).parent),
                                                                 lock_dir=str(pool.lock_dir), keep=keep)],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    assert proc.stdout is not None
    assert int(proc.stdout.readline()) == len(pool.ids) - len(keep)
    return proc


def test_a_domain_held_by_another_process_is_never_drawn(tmp_path: Path) -> None:
    pool = DomainPool(tmp_path, range(1, 6))
    proc = holder(pool, {4})
    try:
        for _ in range(20):  # a random draw: the held ones, every time, left alone
            with pool.leased(1) as envs:
                assert envs == [{"ROS_DOMAIN_ID": "4"}]
                with pytest.raises(RuntimeError, match="every ROS domain 1..5 is held by a test process"):
                    pool.lease_any()
        assert pool.holder(2) == str(proc.pid)
    finally:
        proc.kill()
        proc.wait()
    with pool.leased(5) as envs:  # the holder's death dropped its locks
        assert sorted(int(e["ROS_DOMAIN_ID"]) for e in envs) == [1, 2, 3, 4, 5]


def test_a_fixed_domain_held_elsewhere_is_refused_naming_the_holder(tmp_path: Path) -> None:
    pool = DomainPool(tmp_path, range(1, 6))
    proc = holder(pool, set())
    try:
        with pytest.raises(RuntimeError, match=rf"DUALARM_TEST_DOMAIN_ID=3: that ROS domain is held by another "
                           rf"test process \(pid {proc.pid}\)"):
            pool.lease_session("3")
    finally:
        proc.kill()
        proc.wait()
    lease = pool.lease_session("3")
    assert lease.env == {"ROS_DOMAIN_ID": "3"} and pool.holder(3) == str(os.getpid())
    lease.release()
