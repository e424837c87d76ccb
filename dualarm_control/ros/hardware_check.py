"""Does a hardware profile match the live graph? (issue 29: ``dualarm hardware check``, and the
controller's ``hardware.startup_check``.)

:func:`check_graph` lists the profile's joint-state and command topics with their publishers and
subscribers (node and type), the joint names matched or missing, and one line per problem, e.g.
"no subscriber on /left/forward_position_controller/commands". The profile can run when there is
no problem.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from dualarm_control.hardware import HardwareProfile

JOINT_STATE_TYPE = "sensor_msgs/msg/JointState"


@dataclass(frozen=True)
class GraphReport:
    """What :func:`check_graph` found: ``lines`` (the topics, endpoints and joints) and ``problems``."""

    lines: tuple[str, ...]
    problems: tuple[str, ...]
    named: bool = True
    """Every endpoint's node is known (discovery gives an endpoint before its node's name)."""

    @property
    def ok(self) -> bool:
        return not self.problems

    def text(self) -> str:
        verdict = ("the profile can run" if self.ok else
                   f"{len(self.problems)} problem(s): the profile cannot run")
        return "\n".join([*self.lines, *(f"problem: {p}" for p in self.problems), verdict])


UNKNOWN = "_NODE_NAME_UNKNOWN_"


def _node(info: Any) -> str:
    return "(a node not discovered yet)" if info.node_name == UNKNOWN else \
        f"{info.node_namespace.rstrip('/')}/{info.node_name}"


def _endpoints(infos: Sequence[Any]) -> str:
    return ", ".join(f"{_node(i)} [{i.topic_type}]" for i in infos) or "none"


def check_graph(node: Any, profile: HardwareProfile, joint_names: Sequence[str],
                seen: Mapping[str, Sequence[str]], ignore_node: str = "") -> GraphReport:
    """The profile against the graph ``node`` sees; ``seen``: the joint names of a message received on
    each joint-state topic; endpoints of the node named ``ignore_node`` are left out (the checking node)."""
    lines: list[str] = []
    problems: list[str] = []
    endpoints: list[Any] = []

    def others(infos: Sequence[Any]) -> list[Any]:
        return [i for i in infos if i.node_name != ignore_node]

    carried: dict[str, list[str]] = {}
    hardware = profile.hardware_names(joint_names)  # the joints as the hardware names them (hardware.joint_map)
    for topic in profile.joint_states:
        pubs = others(node.get_publishers_info_by_topic(topic))
        endpoints += pubs
        lines.append(f"joint states {topic}: publishers {_endpoints(pubs)}")
        if not pubs:
            problems.append(f"no publisher on {topic}")
        for wrong in {i.topic_type for i in pubs} - {JOINT_STATE_TYPE}:
            problems.append(f"{topic} is published as {wrong}, not {JOINT_STATE_TYPE}")
        if topic in seen:
            names = list(seen[topic])
            mine = [n for n in names if n in set(hardware)]
            extra = [n for n in names if n not in set(hardware)]
            lines.append(f"  {len(names)} joints, {len(mine)} of the robot's" +
                         (f", extra: {', '.join(extra)}" if extra else ""))
            for n in mine:
                carried.setdefault(n, []).append(topic)
        elif pubs:
            problems.append(f"no message on {topic}")
    if len(seen) == len(profile.joint_states):
        missing = [profile.joint_map.label(d) for d, h in zip(joint_names, hardware, strict=True) if h not in carried]
        twice = [f"{n} ({', '.join(t)})" for n, t in carried.items() if len(t) > 1]
        lines.append(f"joints matched: {len(joint_names) - len(missing)} of {len(joint_names)}")
        problems += [f"joint {n} is on no joint-state topic" for n in missing]
        problems += [f"joint {n} is on several joint-state topics" for n in twice]
    for out in profile.outputs:
        expected = out.kind.type_name
        subs = others(node.get_subscriptions_info_by_topic(out.topic))
        endpoints += subs
        pubs = others(node.get_publishers_info_by_topic(out.topic))
        lines.append(f"command {out.topic} ({out.interface}, {len(out.joints)} joints): subscribers "
                     f"{_endpoints(subs)}; publishers {_endpoints(pubs)}")
        if not subs:
            problems.append(f"no subscriber on {out.topic}")
        for wrong in {i.topic_type for i in subs} - {expected}:
            problems.append(f"{out.topic} is subscribed as {wrong}, the profile sends {expected}")
    return GraphReport(tuple(lines), tuple(problems), all(i.node_name != UNKNOWN for i in endpoints))


def wait_for_graph(node: Any, executor: Any, profile: HardwareProfile, joint_names: Sequence[str],
                   names_seen: Any, timeout_s: float, ignore_node: str = "") -> GraphReport:
    """Spin ``executor`` until the profile matches the graph or ``timeout_s`` passed; the last report.
    ``names_seen()`` gives the joint names received per joint-state topic (JointStates.names_seen)."""
    end = time.monotonic() + timeout_s
    while True:
        report = check_graph(node, profile, joint_names, names_seen(), ignore_node)
        if (report.ok and report.named) or time.monotonic() >= end:
            return report
        executor.spin_once(timeout_sec=0.1)
