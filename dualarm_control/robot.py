"""Robot descriptions and their resolved URDF: which URDF, which joints make the two arms, which
frames are the tools.

The robot is data (DESIGN.md): one ROS-style parameter file per robot
(``config/robots/<name>.yaml``, keys under ``robot.``) is the only place a robot is named. The
core builds its model from it (:class:`~dualarm_control.kinematics.DualArmModel`), the simulator
loads the same resolved URDF, and ``/robot_description`` carries it.

A description is read from its parameter file by :mod:`dualarm_control.robot_params` (its keys
there); its files are found by :mod:`dualarm_control.robot_files`.

The resolved URDF always has the two tool frames as links named ``left_tool`` (F1) and
``right_tool`` (F2), fixed to the description's tool links by ``left_tool_joint`` /
``right_tool_joint`` (the F/T sensor's joint): every process, topic and frame_id names F1 and F2
so, whatever the robot. Mesh file names are made absolute (``package://`` resolved), so that
pybullet and any viewer read the file wherever it is written.

Joint order everywhere (commands, states in the model, ready positions): the left joints then the
right joints, as listed. Only revolute and prismatic arm joints are supported: a continuous joint
(nq = 2 in pinocchio) is refused, naming it.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np

from dualarm_control.arrays import FloatArray
from dualarm_control.paths import config_path
from dualarm_control.robot_files import (
    PREFIX,
    RobotError,
    _cached_file,
    _key,
    mesh_path,
)
from dualarm_control.tool_bodies import ToolSet, body_elements

LEFT_TOOL = "left_tool"
"""The link of F1 in every resolved URDF (and the frame_id of relative poses and goals)."""
RIGHT_TOOL = "right_tool"
"""The link of F2 in every resolved URDF."""
TOOL_JOINTS = {LEFT_TOOL: "left_tool_joint", RIGHT_TOOL: "right_tool_joint"}
SIDES = ("left", "right")
MOVABLE = ("revolute", "prismatic", "continuous")
TOOL_MASS = 1e-3  # kg: the generated tool links (a massless link gets pybullet's default 1 kg)


Pose6 = tuple[float, float, float, float, float, float]
IDENTITY: Pose6 = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


@dataclass(frozen=True)
class RobotDescription:
    """A validated robot description (module docstring).

    Attributes:
        name: the robot's name. description: one line about it.
        urdf: the source URDF (the single arm's for a pair).
        left_joints, right_joints: each arm's joints as the URDF names them, base to tip.
        left_tool, right_tool: the tool links as the URDF names them.
        left_tool_offset, right_tool_offset: fixed offsets of F1, F2 from those links (x y z [m],
            roll pitch yaw [deg]).
        pair: two copies of ``urdf`` (names prefixed ``left_`` / ``right_``), placed at
            ``left_base``, ``right_base`` (x y z [m], roll pitch yaw [deg]).
        locked: value [rad or m] of each movable joint that is not an arm's (URDF names).
        ready_positions: the arms' start configuration [rad or m], (n,), left then right.
        acceleration_limit: the robot's default joint acceleration bound [rad/s^2] (empty: none).
        collision_allowed: link pairs (resolved URDF names) the collision limit never checks.
        tools: the tool set whose bodies become links fixed to the tool frames (None: none;
            :mod:`dualarm_control.tool_bodies`).
        source: the file the description came from (None: built in code).
    """

    name: str
    urdf: Path
    left_joints: tuple[str, ...]
    right_joints: tuple[str, ...]
    left_tool: str
    right_tool: str
    ready_positions: tuple[float, ...]
    left_tool_offset: Pose6 = IDENTITY
    right_tool_offset: Pose6 = IDENTITY
    pair: bool = False
    left_base: Pose6 = IDENTITY
    right_base: Pose6 = IDENTITY
    locked: tuple[tuple[str, float], ...] = ()
    acceleration_limit: tuple[float, ...] = ()
    collision_allowed: tuple[tuple[str, str], ...] = ()
    tools: ToolSet | None = None
    description: str = ""
    source: Path | None = field(default=None, compare=False)

    @property
    def joint_names(self) -> list[str]:
        """The arms' joints as the resolved URDF (and /joint_states) names them, left then right."""
        return [self.model_name("left", j) for j in self.left_joints] + \
            [self.model_name("right", j) for j in self.right_joints]

    @property
    def n_left(self) -> int:
        return len(self.left_joints)

    @property
    def nq(self) -> int:
        return len(self.left_joints) + len(self.right_joints)

    @property
    def ready(self) -> FloatArray:
        """``ready_positions`` as an array [rad], (n,)."""
        return np.array(self.ready_positions, dtype=float)

    def model_name(self, side: str, name: str) -> str:
        """A joint or link of one arm as the resolved URDF names it (``left_`` prefix for a pair)."""
        return f"{side}_{name}" if self.pair else name

    @cached_property
    def reference(self) -> str:
        """How another process names this robot: its registry name when it is a shipped one, else
        the absolute path of its YAML (what ``--robot`` and the nodes' ``robot`` parameter take). Found
        once (the controller's /diagnostics name it every cycle: the file system's answer cost 8 % of a
        1 kHz cell's CPU)."""
        if self.source is None:
            return self.name
        shipped = config_path("robots", f"{self.name}.yaml")
        return self.name if shipped.is_file() and shipped.resolve() == self.source.resolve() else str(self.source)

    def locked_positions(self) -> dict[str, float]:
        """Every locked joint's value, by its name in the resolved URDF."""
        return dict(self.resolved.locked)

    @cached_property
    def resolved(self) -> ResolvedURDF:
        """The resolved URDF (built once per description; validated)."""
        return resolve(self)

    @property
    def resolved_limits(self) -> tuple[FloatArray, FloatArray]:
        """The arms' joint position limits from the URDF [rad or m], (n,) each, in joint order."""
        by_name = {m[0]: m for m in self.resolved.movable}
        rows = [by_name[n] for n in self.joint_names]
        return np.array([r[2] for r in rows]), np.array([r[3] for r in rows])

    @property
    def urdf_path(self) -> Path:
        """The resolved URDF file, loaded by pinocchio and pybullet alike."""
        return self.resolved.path

    @property
    def urdf_xml(self) -> str:
        """The resolved URDF text (what /robot_description carries)."""
        return self.resolved.xml


@dataclass(frozen=True)
class ResolvedURDF:
    """The URDF every process loads (module docstring).

    Attributes:
        xml: its text. path: a file holding exactly that text (the source file itself when it
            needed no change, else a content-addressed file in the cache directory).
        locked: (joint, value) of every movable joint that is not an arm's (resolved names).
        movable: every movable joint's (name, type, lower, upper) in the resolved URDF.
    """

    xml: str
    path: Path
    locked: tuple[tuple[str, float], ...]
    movable: tuple[tuple[str, str, float, float], ...]


def _origin(pose: Pose6, degrees: bool = True) -> ET.Element:
    rpy = [math.radians(v) for v in pose[3:]] if degrees else list(pose[3:])
    return ET.Element("origin", xyz=" ".join(repr(float(v)) for v in pose[:3]),
                      rpy=" ".join(repr(float(v)) for v in rpy))


def _fixed(name: str, parent: str, child: str, pose: Pose6) -> ET.Element:
    joint = ET.Element("joint", name=name, type="fixed")
    joint.append(ET.Element("parent", link=parent))
    joint.append(ET.Element("child", link=child))
    joint.append(_origin(pose))
    return joint


def _tool_link(name: str) -> ET.Element:
    link = ET.Element("link", name=name)
    inertial = ET.SubElement(link, "inertial")
    ET.SubElement(inertial, "mass", value=repr(TOOL_MASS))
    ET.SubElement(inertial, "inertia", ixx="1e-9", ixy="0", ixz="0", iyy="1e-9", iyz="0", izz="1e-9")
    return link


def _prefixed(robot: ET.Element, prefix: str) -> list[ET.Element]:
    """The links and joints of a single-arm URDF with every link and joint name prefixed."""
    out = []
    for el in robot:
        if el.tag not in ("link", "joint"):
            continue
        el = _copy(el)
        el.set("name", prefix + el.get("name", ""))
        if el.tag == "joint":
            for tag in ("parent", "child"):
                ref = el.find(tag)
                if ref is not None:
                    ref.set("link", prefix + ref.get("link", ""))
            mimic = el.find("mimic")
            if mimic is not None:
                mimic.set("joint", prefix + mimic.get("joint", ""))
        out.append(el)
    return out


def _copy(el: ET.Element) -> ET.Element:
    return ET.fromstring(ET.tostring(el))


def _parse(urdf: Path) -> ET.Element:
    try:
        return ET.parse(urdf).getroot()
    except ET.ParseError as exc:
        raise RobotError(f"robot parameter {_key('urdf')}: {urdf}: not a valid URDF ({exc})") from None


def resolve(robot: RobotDescription) -> ResolvedURDF:
    """The resolved URDF of ``robot`` (module docstring), validated against the description."""
    source = _parse(robot.urdf)
    changed = robot.pair
    if robot.pair:
        root = ET.Element("robot", name=robot.name)
        for el in source:
            if el.tag == "material":
                root.append(_copy(el))
        root.append(ET.Element("link", name="world"))
        single_root = _root_link(source, robot.urdf)
        for side, base in (("left", robot.left_base), ("right", robot.right_base)):
            root.append(_fixed(f"{side}_base_joint", "world", f"{side}_{single_root}", base))
            root.extend(_prefixed(source, f"{side}_"))
    else:
        root = source
    for mesh in root.iter("mesh"):
        name = mesh.get("filename", "")
        absolute = str(mesh_path(name, robot.urdf))
        if absolute != name:
            mesh.set("filename", absolute)
            changed = True
    links = {el.get("name") for el in root.findall("link")}
    joints = {el.get("name"): el for el in root.findall("joint")}
    for side, tool, offset, frame in (("left", robot.left_tool, robot.left_tool_offset, LEFT_TOOL),
                                      ("right", robot.right_tool, robot.right_tool_offset, RIGHT_TOOL)):
        link = robot.model_name(side, tool)
        if link not in links:
            raise RobotError(f"robot parameter {_key(side + '_tool')}: got {tool!r}, expected a link of "
                             f"{robot.urdf.name} (links: {', '.join(sorted(str(n) for n in links)[:40])})")
        if link == frame and offset == IDENTITY:
            continue
        if frame in links or TOOL_JOINTS[frame] in joints:
            raise RobotError(f"robot parameter {_key(side + '_tool')}: {robot.urdf.name} has a link {frame!r} or "
                             f"joint {TOOL_JOINTS[frame]!r} that is not the tool: rename it")
        root.append(_tool_link(frame))
        root.append(_fixed(TOOL_JOINTS[frame], link, frame, offset))
        links.add(frame)
        changed = True
    if robot.tools is not None:
        _add_tool_bodies(robot.tools, root, links)
        changed = True
    movable, locked = _check_joints(robot, root)
    xml = ET.tostring(root, encoding="unicode")
    path = robot.urdf if not changed else _cached_file(robot.name, xml)
    if not changed:
        xml = robot.urdf.read_text()
    _check_tools(robot, {_link_of(el, "child"): el for el in root.findall("joint")})
    return ResolvedURDF(xml=xml, path=path, locked=tuple(locked), movable=tuple(movable))


def _add_tool_bodies(tools: ToolSet, root: ET.Element, links: set[str | None]) -> None:
    """The tool set's bodies as links fixed to the tool frames (RobotError for a name the URDF has)."""
    for body in tools.bodies:
        if body.link in links:
            raise RobotError(f"robot parameter {_key('tools')}: tool set {tools.name!r}: body {body.name!r} would be "
                             f"link {body.link!r}, which the URDF already has: rename the body")
        root.extend(body_elements(body, LEFT_TOOL if body.side == "left" else RIGHT_TOOL))
        links.add(body.link)


def _link_of(joint: ET.Element, tag: str) -> str:
    """The link a joint's ``<parent>`` or ``<child>`` names ('' without one)."""
    ref = joint.find(tag)
    return "" if ref is None else str(ref.get("link", ""))


def _root_link(robot: ET.Element, urdf: Path) -> str:
    children = {_link_of(j, "child") for j in robot.findall("joint")}
    roots = [el.get("name") for el in robot if el.tag == "link" and el.get("name") not in children]
    if len(roots) != 1:
        raise RobotError(f"robot parameter {_key('urdf')}: {urdf.name} has {len(roots)} root links, expected one")
    return str(roots[0])


def _limits(joint: ET.Element) -> tuple[float, float]:
    limit = joint.find("limit")
    if limit is None or joint.get("type") == "continuous":
        return -math.inf, math.inf
    return float(limit.get("lower", "0")), float(limit.get("upper", "0"))


def _check_joints(robot: RobotDescription, root: ET.Element
                  ) -> tuple[list[tuple[str, str, float, float]], list[tuple[str, float]]]:
    """The movable joints, and the locked ones' values; RobotError for an unknown, fixed, continuous
    joint of an arm, an unknown locked joint, a locked value or ready position outside its range."""
    movable = [(str(j.get("name")), str(j.get("type")), *_limits(j)) for j in root.findall("joint")
               if j.get("type") in MOVABLE]
    by_name = {m[0]: m for m in movable}
    all_joints = {j.get("name"): j.get("type") for j in root.findall("joint")}
    arm = robot.joint_names
    for side, names in (("left", robot.left_joints), ("right", robot.right_joints)):
        for name in names:
            resolved_name = robot.model_name(side, name)
            kind = all_joints.get(resolved_name)
            if kind is None:
                raise RobotError(f"robot parameter {_key(side + '_joints')}: {name!r} is not a joint of "
                                 f"{robot.urdf.name} (movable joints: {', '.join(m[0] for m in movable)})")
            if kind == "continuous":
                raise RobotError(f"robot parameter {_key(side + '_joints')}: {name!r} is a continuous joint "
                                 "(no position limits, nq = 2 in pinocchio): not supported; give it a revolute "
                                 "type with limits in your URDF")
            if kind not in MOVABLE:
                raise RobotError(f"robot parameter {_key(side + '_joints')}: {name!r} is a {kind} joint, "
                                 "expected a revolute or prismatic one")
    for (name, _, lo, hi), q in zip((by_name[n] for n in arm), robot.ready_positions, strict=True):
        if not lo - 1e-9 <= q <= hi + 1e-9:
            raise RobotError(f"robot parameter {_key('ready_positions_deg')}: {name} = {math.degrees(q):.4g} deg is "
                             f"outside its range [{math.degrees(lo):.4g}, {math.degrees(hi):.4g}] deg")
    given = dict(robot.locked)
    locked: list[tuple[str, float]] = []
    for name, kind, lo, hi in movable:
        if name in arm:
            if name in given:
                raise RobotError(f"robot parameter '{PREFIX}locked.{name}': {name} is an arm joint, not a locked one")
            continue
        if name not in given and kind == "continuous":
            value = 0.0
        else:
            value = given.pop(name, 0.0 if lo <= 0.0 <= hi else 0.5 * (lo + hi))
        if not lo - 1e-9 <= value <= hi + 1e-9:
            raise RobotError(f"robot parameter '{PREFIX}locked.{name}': got {value}, outside [{lo}, {hi}]")
        locked.append((name, value))
    for name in given:
        raise RobotError(f"robot parameter '{PREFIX}locked.{name}': {name!r} is not a movable joint of "
                         f"{robot.urdf.name} outside the arms")
    return movable, locked


def _check_tools(robot: RobotDescription, parent_of: Mapping[str, ET.Element]) -> None:
    """Each tool is moved by every joint of its own arm and by none of the other's."""
    arms = {"left": set(robot.joint_names[:robot.n_left]), "right": set(robot.joint_names[robot.n_left:])}
    for side, other, frame in (("left", "right", LEFT_TOOL), ("right", "left", RIGHT_TOOL)):
        chain: set[str] = set()
        link, seen = frame, 0
        while link in parent_of and seen < 10000:
            joint = parent_of[link]
            chain.add(str(joint.get("name")))
            link = _link_of(joint, "parent")
            seen += 1
        tool = getattr(robot, f"{side}_tool")
        if not arms[side] <= chain:
            missing = sorted(arms[side] - chain)
            raise RobotError(f"robot parameter {_key(side + '_tool')}: {tool!r} is not moved by its arm's "
                             f"joints {', '.join(missing)} (it is not beyond them in the URDF's tree)")
        if arms[other] & chain:
            raise RobotError(f"robot parameter {_key(side + '_tool')}: {tool!r} is moved by the {other} arm's "
                             f"joints {', '.join(sorted(arms[other] & chain))}")
