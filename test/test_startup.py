"""A dependable start (issue 20, point 6): a node that joins a running cell gets its topics.

Fast DDS 2.14 sends a new participant's first announcement before it listens
(``RTPSParticipantImpl::enable``): a peer that answers at once is not heard, and does not
answer the newcomer's later announcements, so the two matched only at the peer's next
periodic announcement, every 3 s by default. The nodes announce every 0.1 s
(config/fastdds_discovery.xml, applied by dualarm_control/ros/env.py). The worst case is a
node joining a cell that is already running (no later newcomer makes the peer announce
itself again): here the trajectory node starts several times against one running sim_node, in
real time. The default test asserts what does not depend on the machine's load, on 3 starts: every
start receives its first /joint_states (waited for with a deadline), and prints how long each
took; a join slower than 1.5 s (below the stall) fails it. How long is a wall-clock figure: the bound (1 s, 6x the normal 80 ms and far below the
2.6-3.3 s stall it catches; before the profile, 21 of 30 such starts took over 0.5 s, up to
3.3 s: docs/bench.md, "Start-up") is asserted by the ``slow`` test, on 10 starts.
"""

from __future__ import annotations

import re
from pathlib import Path
from xml.etree import ElementTree

import pytest
from waiting import wait_for_line

from dualarm_control.app.run.launcher import Launch, Process, node_command
from dualarm_control.paths import config_path
from dualarm_control.ros.env import (
    FASTDDS_PROFILE_VARIABLE,
    apply_discovery_profile,
    apply_localhost_default,
    discovery_profile,
    localhost_environment,
)

STARTS = 10
"""Joins of the ``slow`` test (the wall-clock bound)."""
FEW_STARTS = 3
"""Joins of the default test (each gets its first joint state; about 1.5 s a join)."""
FIRST_STATE_WITHIN_S = 1.0
"""The slow test's bound. The stall it catches (a lost discovery reply) lasts until the next periodic
announcement: 2.6-3.3 s with Fast DDS's default 3 s. Measured with the package's profile: at most
0.41 s in 78 full launches and 60 joins on a loaded machine, but one of 10 joins took 0.515 s in a
fresh clone under ``stress-ng --cpu 1`` (the node itself starved of CPU), so the bound is 1 s, not the
0.5 s target that docs/bench.md reports against."""
STALL_GUARD_S = 1.5
"""The default test's bound: below the stall it exists for (a lost discovery reply, matched only at the peer's next
periodic announcement: 2.6-3.3 s in docs/bench.md; without the package's profile here 1.78-2.73 s in 6 joins,
2026-12), far above the normal join (80 ms quiet; 0.12-0.33 s on this shared machine; at most 0.41 s in 60 joins
on a loaded machine, 0.515 s once with the node starved under ``stress-ng --cpu 1``): a guard that a busy machine
does not trip (3 x the starved join), not a speed target (the slow test's 1 s)."""
REAL_TIME = ["-p", "lockstep:=false", "-p", "scenario:=assembly"]
LOG_FORMAT = {"RCUTILS_CONSOLE_OUTPUT_FORMAT": "[{severity}] [{time}] [{name}]: {message}"}
LOG_LINE = re.compile(r"\[INFO\] \[(\d+\.\d+)\] \[trajectory_node\]: (.*)")


def log_time(lines: list[str], prefix: str) -> float:
    """Time stamp [s] of the trajectory node's first log line starting with ``prefix``."""
    for line in lines:
        match = LOG_LINE.search(line)
        if match and match.group(2).startswith(prefix):
            return float(match.group(1))
    raise AssertionError(f"no '{prefix}' line in:\n" + "\n".join(lines[-20:]))


def wait_for(process: Process, text: str) -> None:
    wait_for_line(process.lines, text, process.popen, timeout=120.0, name=process.name)


def first_state_delay() -> float:
    """Start the trajectory node, stop it at its first joint state; seconds from up to that state."""
    run = Launch(echo=False)
    node = run.start("trajectory_node", node_command("trajectory_node", REAL_TIME), LOG_FORMAT)
    try:
        wait_for(node, "targets:")
    finally:
        run.stop()
    # "scenario 'assembly': ... waiting for /joint_states" ends __init__; "targets: ..." is the first state
    return log_time(node.lines, "targets:") - log_time(node.lines, "scenario '")


def join_delays(starts: int) -> list[float]:
    """``starts`` joins of the trajectory node to one running sim_node: seconds from each node
    being up to its first joint state."""
    cell = Launch(echo=False)
    try:
        sim = cell.start("sim_node", node_command("sim_node", REAL_TIME), LOG_FORMAT)
        wait_for(sim, "real-time at")  # the end of its __init__: publishing from the next period on
        delays = [first_state_delay() for _ in range(starts)]
        assert sim.popen.poll() is None, "\n".join(sim.lines[-20:])
    finally:
        cell.stop()
    print("first joint state after [s]:", [round(d, 3) for d in delays])
    return delays


@pytest.fixture(scope="module")
def few_joins() -> list[float]:
    """:data:`FEW_STARTS` joins (the default test's)."""
    return join_delays(FEW_STARTS)


@pytest.fixture(scope="module")
def joins() -> list[float]:
    """:data:`STARTS` joins (the ``slow`` test's)."""
    return join_delays(STARTS)


@pytest.mark.realtime
def test_a_node_joining_a_running_cell_gets_its_first_joint_state(few_joins: list[float]) -> None:
    """Each of 3 joins got its first joint state after it was up, none after a discovery stall (the node's
    own log stamps, from up to first state, under STALL_GUARD_S = 1.5 s: below the 1.8-3.3 s stall, 3 x the
    slowest join seen on a starved machine); how soon (1 s) is the slow test's, on 10 joins."""
    assert len(few_joins) == FEW_STARTS and all(0.0 <= delay < STALL_GUARD_S for delay in few_joins), \
        [round(d, 3) for d in few_joins]


@pytest.mark.slow
def test_a_node_joining_a_running_cell_gets_its_first_joint_state_within_one_second(joins: list[float]) -> None:
    """Each join's first joint state within 1 s of the node being up: a wall-clock bound (a starved
    node misses it on a busy machine), hence ``slow``."""
    assert max(joins) < FIRST_STATE_WITHIN_S, [round(d, 3) for d in joins]


def announcement_period(profile: Path) -> float:
    """The participant profile's periodic announcement [s] (Fast DDS XML leaseAnnouncement)."""
    ns = {"f": "http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles"}
    node = ElementTree.parse(profile).find(".//f:participant/f:rtps/f:builtin/f:discovery_config/f:leaseAnnouncement",
                                           ns)
    assert node is not None, profile
    return float(node.findtext("f:sec", "0", ns)) + 1e-9 * float(node.findtext("f:nanosec", "0", ns))


def test_the_discovery_profile_applies_unless_the_user_chose_a_fast_dds_profile(tmp_path: Path) -> None:
    ours = str(discovery_profile())
    assert announcement_period(discovery_profile()) == announcement_period(config_path("fastdds_link.xml")) == 0.1
    env: dict[str, str] = {}
    apply_localhost_default(env)
    assert apply_discovery_profile(env, cwd=tmp_path) and env[FASTDDS_PROFILE_VARIABLE] == ours
    assert localhost_environment({FASTDDS_PROFILE_VARIABLE: ours})["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
    for key in ("FASTRTPS_DEFAULT_PROFILES_FILE", "FASTDDS_DEFAULT_PROFILES_FILE"):  # the user's file wins
        user = {key: "/home/me/my_profile.xml"}
        assert not apply_discovery_profile(user, cwd=tmp_path) and user == {key: "/home/me/my_profile.xml"}
        assert "ROS_AUTOMATIC_DISCOVERY_RANGE" not in localhost_environment(user)
    (tmp_path / "DEFAULT_FASTRTPS_PROFILES.xml").write_text("<dds/>")  # Fast DDS loads it from the cwd
    cwd_user: dict[str, str] = {}
    assert not apply_discovery_profile(cwd_user, cwd=tmp_path) and cwd_user == {}
