"""Tool sets: the bodies a robot's tools are made of (a peg, a hole block with its hole, a gripper's
jaws), from config, as links of the resolved URDF.

Tools are geometry (DESIGN.md): a tool set's bodies become links of the URDF the package builds
(:mod:`dualarm_control.robot`), each fixed to its side's tool frame (``left_tool``, F1, or
``right_tool``, F2) at a pose, so the simulator, the viewers and the collision model see them like
the robot's own links. A robot description names its tool set (``robot.tools``: a name in
``config/tools/`` or a YAML path, relative to the description's folder).

A tool set's file (ROS-style, keys under ``tools.``)::

    tools:
      ros__parameters:
        tools:
          name: peg_and_hole
          left: [hole_floor, hole_wall_xp]     # bodies fixed to F1, base to tip
          right: [peg]                         # bodies fixed to F2
          peg:
            shape: cylinder                    # box | cylinder | sphere | mesh
            size: [0.015, 0.12]                # box: x y z; cylinder: radius length; sphere: radius [m];
                                               # mesh: scale x y z [-] (with file: the mesh's path)
            xyz: [0.0, 0.0, -0.06]             # the body's centre in the tool frame [m]
            rpy_deg: [0.0, 0.0, 0.0]           # its orientation in the tool frame [deg]
            mass: 0.3                          # [kg] (default 0.05)
            rgba: [0.3, 0.8, 0.3, 1.0]

A body ``B`` of side ``s`` is the link ``s_B`` (e.g. ``left_hole_wall_xp``, ``right_peg``), child of
the tool frame by the fixed joint ``s_B_joint``; its visual and collision shapes are the same
geometry at the same pose, its inertia that of a solid of uniform density (a mesh: a sphere of radius
0.05 m). A body beyond the tool frame is beyond the F/T sensor's joint (``left_tool_joint``,
``right_tool_joint``): its weight is measured, as a tool's is on a real wrist sensor.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from dualarm_control.params import ParameterError, read_params_file
from dualarm_control.paths import registry_file
from dualarm_control.robot_files import RobotError

TOOLS_PREFIX = "tools."
SHAPES = {"box": 3, "cylinder": 2, "sphere": 1, "mesh": 3}
"""Shape -> number of ``size`` values (box: x y z [m]; cylinder: radius length [m]; sphere: radius [m];
mesh: scale x y z [-])."""
BODY_KEYS = ("shape", "size", "file", "xyz", "rpy_deg", "mass", "rgba")
DEFAULT_MASS = 0.05
"""[kg] a body's mass when its file gives none."""
MESH_RADIUS = 0.05
"""[m] the radius of the sphere whose inertia a mesh body gets."""
DEFAULT_RGBA = (0.6, 0.6, 0.6, 1.0)


@dataclass(frozen=True)
class ToolBody:
    """One body of a tool set (module docstring): fixed to ``side``'s tool frame at ``xyz`` [m],
    ``rpy_deg`` [deg]; ``size`` as :data:`SHAPES` says; ``mass`` [kg]; ``file``: a mesh's path."""

    name: str
    side: str
    shape: str
    size: tuple[float, ...]
    xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rpy_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)
    mass: float = DEFAULT_MASS
    rgba: tuple[float, float, float, float] = DEFAULT_RGBA
    file: str = ""

    @property
    def link(self) -> str:
        """The body's link in the resolved URDF (``left_hole_wall_xp``)."""
        return f"{self.side}_{self.name}"


@dataclass(frozen=True)
class ToolSet:
    """A validated tool set: its name and bodies (left ones first), and the file it came from."""

    name: str
    bodies: tuple[ToolBody, ...]
    description: str = ""
    source: Path | None = None

    def links(self, side: str | None = None) -> list[str]:
        """The bodies' links (of one side, or all)."""
        return [b.link for b in self.bodies if side is None or b.side == side]


def tool_set_names() -> list[str]:
    """Names of the tool sets shipped in config/tools/."""
    from dualarm_control.paths import registry_names

    return registry_names("tools")


def load_tool_set(name_or_path: str, base: Path | None = None) -> ToolSet:
    """A tool set by registry name (``config/tools/<name>.yaml``) or YAML path (relative to ``base``,
    the robot description's folder); RobotError naming the bad key and value."""
    path = Path(name_or_path)
    if path.suffix in (".yaml", ".yml") and not path.is_absolute() and base is not None:
        path = base / path
    file = registry_file("tools", str(path) if path.suffix in (".yaml", ".yml") else name_or_path,
                         "tool set", RobotError, " (or a YAML file of your own, docs/robots.md)")
    try:
        flat = read_params_file(file, "tools")
    except ParameterError as exc:
        raise RobotError(str(exc)) from None
    return tool_set_from_parameters(flat, file)


def _key(key: str) -> str:
    return f"'{TOOLS_PREFIX}{key}'"


def _numbers(flat: Mapping[str, Any], key: str, size: int, default: tuple[float, ...] | None = None
             ) -> tuple[float, ...]:
    value = flat.get(TOOLS_PREFIX + key, default)
    ok = isinstance(value, list | tuple) and len(value) == size and all(
        isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) for v in value)
    if not ok:
        raise RobotError(f"tool set parameter {_key(key)}: got {value!r}, expected {size} finite numbers")
    return tuple(float(v) for v in value)


def _body(flat: Mapping[str, Any], name: str, side: str, base: Path) -> ToolBody:
    shape = flat.get(f"{TOOLS_PREFIX}{name}.shape")
    if shape not in SHAPES:
        raise RobotError(f"tool set parameter {_key(name + '.shape')}: got {shape!r}, expected one of "
                         f"{', '.join(SHAPES)}")
    size = _numbers(flat, f"{name}.size", SHAPES[shape], (1.0, 1.0, 1.0) if shape == "mesh" else None)
    if any(s <= 0 for s in size):
        raise RobotError(f"tool set parameter {_key(name + '.size')}: got {list(size)}, expected values > 0")
    mass = flat.get(f"{TOOLS_PREFIX}{name}.mass", DEFAULT_MASS)
    if isinstance(mass, bool) or not isinstance(mass, int | float) or not (math.isfinite(mass) and mass > 0):
        raise RobotError(f"tool set parameter {_key(name + '.mass')}: got {mass!r}, expected a mass > 0 [kg]")
    file = ""
    if shape == "mesh":
        given = flat.get(f"{TOOLS_PREFIX}{name}.file")
        if not isinstance(given, str) or not given:
            raise RobotError(f"tool set parameter {_key(name + '.file')}: got {given!r}, expected a mesh file")
        mesh = Path(given) if Path(given).is_absolute() else base / given
        if not mesh.is_file():
            raise RobotError(f"tool set parameter {_key(name + '.file')}: got {given!r}: no such file {mesh}")
        file = str(mesh.resolve())
    xyz = _numbers(flat, f"{name}.xyz", 3, (0.0, 0.0, 0.0))
    rpy = _numbers(flat, f"{name}.rpy_deg", 3, (0.0, 0.0, 0.0))
    rgba = _numbers(flat, f"{name}.rgba", 4, DEFAULT_RGBA)
    return ToolBody(name=name, side=side, shape=shape, size=size, xyz=(xyz[0], xyz[1], xyz[2]),
                    rpy_deg=(rpy[0], rpy[1], rpy[2]), mass=float(mass), rgba=(rgba[0], rgba[1], rgba[2], rgba[3]),
                    file=file)


def tool_set_from_parameters(flat: Mapping[str, Any], source: Path | None = None) -> ToolSet:
    """Build a ToolSet from flattened ``tools.*`` parameters; RobotError naming the bad key."""
    name = flat.get(TOOLS_PREFIX + "name")
    if not isinstance(name, str) or not name:
        raise RobotError(f"tool set parameter {_key('name')}: got {name!r}, expected a non-empty string "
                         f"({source or 'the tool set'})")
    bodies: list[ToolBody] = []
    listed: set[str] = set()
    for side in ("left", "right"):
        names = flat.get(TOOLS_PREFIX + side, [])
        if not isinstance(names, list) or not all(isinstance(n, str) and n.isidentifier() for n in names):
            raise RobotError(f"tool set parameter {_key(side)}: got {names!r}, expected a list of body names "
                             "(letters, digits, underscores)")
        for body in names:
            if body in listed:
                raise RobotError(f"tool set parameter {_key(side)}: body {body!r} listed twice")
            listed.add(body)
            bodies.append(_body(flat, body, side, source.parent if source is not None else Path.cwd()))
    known = {TOOLS_PREFIX + k for k in ("name", "description", "left", "right")} | {
        f"{TOOLS_PREFIX}{b}.{k}" for b in listed for k in BODY_KEYS}
    for key in flat:
        if key.startswith(TOOLS_PREFIX) and key not in known:
            raise RobotError(f"tool set parameter '{key}': unknown key (a body not listed in "
                             f"{_key('left')} or {_key('right')}, or a key not among {', '.join(BODY_KEYS)})")
    if not bodies:
        raise RobotError(f"tool set {name!r}: no bodies ({_key('left')} and {_key('right')} are empty)")
    return ToolSet(name=name, bodies=tuple(bodies), description=str(flat.get(TOOLS_PREFIX + "description", "")),
                   source=source)


# ---- as URDF ---------------------------------------------------------------------------------

def inertia(body: ToolBody) -> tuple[float, float, float]:
    """Principal moments (ixx, iyy, izz) [kg m^2] of a solid body of uniform density about its centre,
    in its own frame: box I_x = m (y^2 + z^2) / 12 (size x y z); cylinder (radius r, length l along z)
    I_x = I_y = m (3 r^2 + l^2) / 12, I_z = m r^2 / 2; sphere I = 2 m r^2 / 5 (a mesh: r = 0.05 m)."""
    m = body.mass
    if body.shape == "box":
        x, y, z = body.size
        return m * (y * y + z * z) / 12, m * (x * x + z * z) / 12, m * (x * x + y * y) / 12
    if body.shape == "cylinder":
        r, length = body.size
        side = m * (3 * r * r + length * length) / 12
        return side, side, m * r * r / 2
    r = body.size[0] if body.shape == "sphere" else MESH_RADIUS
    return (2 * m * r * r / 5,) * 3


def _geometry(body: ToolBody) -> ET.Element:
    geometry = ET.Element("geometry")
    if body.shape == "box":
        ET.SubElement(geometry, "box", size=" ".join(repr(v) for v in body.size))
    elif body.shape == "cylinder":
        ET.SubElement(geometry, "cylinder", radius=repr(body.size[0]), length=repr(body.size[1]))
    elif body.shape == "sphere":
        ET.SubElement(geometry, "sphere", radius=repr(body.size[0]))
    else:
        ET.SubElement(geometry, "mesh", filename=body.file, scale=" ".join(repr(v) for v in body.size))
    return geometry


def _origin(body: ToolBody) -> ET.Element:
    return ET.Element("origin", xyz=" ".join(repr(v) for v in body.xyz),
                      rpy=" ".join(repr(math.radians(v)) for v in body.rpy_deg))


def body_elements(body: ToolBody, tool_frame: str) -> list[ET.Element]:
    """The URDF ``<link>`` of ``body`` (visual, collision, inertial at its pose) and the fixed
    ``<joint>`` holding it to ``tool_frame`` (module docstring)."""
    link = ET.Element("link", name=body.link)
    inertial = ET.SubElement(link, "inertial")
    inertial.append(_origin(body))
    ET.SubElement(inertial, "mass", value=repr(body.mass))
    ixx, iyy, izz = inertia(body)
    ET.SubElement(inertial, "inertia", ixx=repr(ixx), ixy="0", ixz="0", iyy=repr(iyy), iyz="0", izz=repr(izz))
    visual = ET.SubElement(link, "visual")
    visual.append(_origin(body))
    visual.append(_geometry(body))
    material = ET.SubElement(visual, "material", name=f"tool_{body.link}")
    ET.SubElement(material, "color", rgba=" ".join(repr(v) for v in body.rgba))
    collision = ET.SubElement(link, "collision")
    collision.append(_origin(body))
    collision.append(_geometry(body))
    joint = ET.Element("joint", name=f"{body.link}_joint", type="fixed")
    ET.SubElement(joint, "parent", link=tool_frame)
    ET.SubElement(joint, "child", link=body.link)
    ET.SubElement(joint, "origin", xyz="0 0 0", rpy="0 0 0")
    return [link, joint]
