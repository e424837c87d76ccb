"""The joint-name map between a robot description and its hardware (issue 40 item 5, docs/hardware.md).

A hardware profile's ``hardware.joint_map`` lists ``"description_name hardware_name"`` strings: the
description's joint ``description_name`` is called ``hardware_name`` on the wire (franka_ros2 names a
Panda's joints ``<arm_id>_joint1``; a dual-arm description prefixes them ``left_``/``right_``). A joint
the map does not name keeps its description name. :class:`JointMap` is applied in one place,
:meth:`~dualarm_control.hardware.HardwareProfile.hardware_names`, which every reader of joint states and
every writer of commands goes through (both directions: states are matched by hardware name into the
description's order, commands are named and ordered by hardware name). ROS-free.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from dualarm_control.errors import ParameterError

KEY = "hardware.joint_map"


def joint_map_entries(value: Any) -> str:
    """'description_name hardware_name' strings (two names each)"""
    if any(len(str(v).split()) != 2 for v in value if v):
        return "'description_name hardware_name' strings (two names each)"
    return ""


@dataclass(frozen=True)
class JointMap:
    """Description joint name -> hardware joint name (only the renamed joints)."""

    to_hardware: Mapping[str, str]

    def hardware(self, names: Sequence[str]) -> tuple[str, ...]:
        """``names`` (description) as the hardware calls them, in the same order."""
        return tuple(self.to_hardware.get(n, n) for n in names)

    def description(self, names: Sequence[str]) -> tuple[str, ...]:
        """Hardware ``names`` as the description calls them (names the map does not rename kept)."""
        back = {h: d for d, h in self.to_hardware.items()}
        return tuple(back.get(n, n) for n in names)

    def label(self, name: str) -> str:
        """A description joint's name for messages: ``left_joint_1 (hardware: panda_left_joint1)``."""
        hw = self.to_hardware.get(name)
        return f"{name} (hardware: {hw})" if hw else name


IDENTITY = JointMap({})
"""No joint renamed (a profile without ``hardware.joint_map``)."""


def parse_joint_map(entries: Sequence[str], joint_names: Sequence[str], key: str = KEY) -> JointMap:
    """The map of ``entries`` ('description_name hardware_name') on a description with ``joint_names``.

    Raises ParameterError naming ``key`` and the bad entry: a description name that is not a joint of
    the description, a joint mapped twice, two joints mapped to one hardware name, or a hardware name
    that is another (unmapped) joint's description name."""
    known = set(joint_names)
    out: dict[str, str] = {}
    for entry in (e for e in entries if e):
        parts = str(entry).split()
        if len(parts) != 2:
            raise ParameterError(key, entry, "'description_name hardware_name' (two names)")
        desc, hw = parts
        if desc not in known:
            raise ParameterError(key, entry, f"a joint of the robot description first ({', '.join(joint_names)})")
        if desc in out:
            raise ParameterError(key, entry, f"each joint mapped once ({desc} is already '{desc} {out[desc]}')")
        clash = [d for d, h in out.items() if h == hw]
        if clash:
            raise ParameterError(key, entry, f"a hardware name no other joint has ({hw} is already {clash[0]}'s)")
        out[desc] = hw
    taken = {n for n in joint_names if n not in out}
    for desc, hw in out.items():
        if hw in taken:
            raise ParameterError(key, f"{desc} {hw}", f"a hardware name that is not another joint's name ({hw} "
                                 "is a joint of the description that the map does not rename)")
    return JointMap(out)
