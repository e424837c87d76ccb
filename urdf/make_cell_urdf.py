"""Generate ``dualarm_cell.urdf``: two KUKA LWR4 arms on a fixed torso (BAZAR-like).

Run ``python urdf/make_cell_urdf.py`` after editing; the generated URDFs are committed so
pinocchio and pybullet load the very same file. Two tool sets, same arms:

* ``dualarm_cell.urdf`` (tools ``assembly``, paper 000): flanges with mounting plates and the
  tool frames of the hole's entrance (left) and the peg's tip (right); the hole block and the peg
  are the tool set config/tools/peg_and_hole.yaml, added by the robot description.
* ``dualarm_cell_pan.urdf`` (tools ``pan_cleaning``, paper 001): a pan on the left flange,
  tool frame ``left_tool`` at the centre of its top surface with z the pan normal; a brush
  on the right flange, tool frame ``right_tool`` at the brush tip with z the brush axis
  (pointing out of the tip). The brush body is the ``right_tool`` link itself, child of the
  force/torque sensor joint ``right_tool_joint``, so contact forces on the brush pass
  through the sensor. The brush head is a sphere (robust sliding contact in pybullet) with
  a compliant contact (``BRUSH_CONTACT``: bristles, about 3 mm for 5 N).

Nominal LWR4 kinematics: shoulder 0.3105 m above the base, elbow +0.40 m, wrist +0.39 m,
flange +0.078 m past the wrist centre (A6 and A7 intersect). Axes z, y, z, y, z, y, z.
"""

from __future__ import annotations

import math
from pathlib import Path

POS_LIMITS_DEG = (170, 120, 170, 120, 170, 120, 170)
VEL_LIMITS_DEG = (110, 110, 128, 128, 204, 184, 184)
EFFORT = (176, 176, 100, 100, 100, 38, 38)
# (parent->joint offset along z [m], axis, link mass [kg], link length for inertia [m])
CHAIN = (
    (0.1575, "0 0 1", 2.7, 0.20),
    (0.1530, "0 1 0", 2.7, 0.20),
    (0.2000, "0 0 1", 2.7, 0.20),
    (0.2000, "0 1 0", 2.7, 0.20),
    (0.2000, "0 0 1", 1.7, 0.19),
    (0.1900, "0 1 0", 1.6, 0.08),
    (0.0000, "0 0 1", 0.3, 0.05),
)
FLANGE_OFFSET = 0.078
RADIUS = 0.06
# Arm mounts on the torso: (side, y offset [m], rpy of the arm base)
MOUNTS = (("left", 0.26, (0.0, math.pi / 2, math.radians(20))), ("right", -0.26, (0.0, math.pi / 2, -math.radians(20))))
TORSO_HEIGHT = 1.0


def _inertia(mass: float, length: float, radius: float = RADIUS) -> str:
    ixx = mass * (3 * radius**2 + length**2) / 12.0
    izz = mass * radius**2 / 2.0
    return f'<inertia ixx="{ixx:.6f}" ixy="0" ixz="0" iyy="{ixx:.6f}" iyz="0" izz="{izz:.6f}"/>'


def _cyl_link(name: str, mass: float, length: float, rgba: str) -> str:
    return f"""  <link name="{name}">
    <inertial><origin xyz="0 0 {length / 2:.4f}"/><mass value="{mass}"/>{_inertia(mass, length)}</inertial>
    <visual><origin xyz="0 0 {length / 2:.4f}"/><geometry><cylinder radius="{RADIUS}" length="{length}"/></geometry><material name="m_{name}"><color rgba="{rgba}"/></material></visual>
    <collision><origin xyz="0 0 {length / 2:.4f}"/><geometry><cylinder radius="{RADIUS * 0.9:.3f}" length="{length}"/></geometry></collision>
  </link>
"""


def _arm(side: str, y: float, rpy: tuple[float, float, float], tools: str) -> str:
    out = [
        (
            f'  <joint name="{side}_mount" type="fixed"><parent link="torso"/><child link="{side}_link_0"/>'
            f'<origin xyz="0 {y} {TORSO_HEIGHT}" rpy="{rpy[0]:.6f} {rpy[1]:.6f} {rpy[2]:.6f}"/></joint>\n'
        ),
        _cyl_link(f"{side}_link_0", 2.0, 0.1575, "0.9 0.5 0.1 1"),
    ]
    parent = f"{side}_link_0"
    for i, (dz, axis, mass, length) in enumerate(CHAIN, start=1):
        lim = math.radians(POS_LIMITS_DEG[i - 1])
        vel = math.radians(VEL_LIMITS_DEG[i - 1])
        child = f"{side}_link_{i}"
        out.append(
            f'  <joint name="{side}_joint_{i}" type="revolute"><parent link="{parent}"/><child link="{child}"/>'
            f'<origin xyz="0 0 {dz}"/><axis xyz="{axis}"/>'
            f'<limit lower="{-lim:.6f}" upper="{lim:.6f}" velocity="{vel:.6f}" effort="{EFFORT[i - 1]}"/>'
            f'<dynamics damping="0.5" friction="0.0"/></joint>\n'
        )
        out.append(_cyl_link(child, mass, length, "0.9 0.5 0.1 1" if i % 2 else "0.8 0.8 0.8 1"))
        parent = child
    out.append(
        f'  <joint name="{side}_flange_joint" type="fixed"><parent link="{parent}"/><child link="{side}_flange"/>'
        f'<origin xyz="0 0 {FLANGE_OFFSET}"/></joint>\n'
    )
    out.append(_tool(side, tools))
    return "".join(out)


PAN_RADIUS = 0.13
"""Pan radius [m] (visual cylinder; the collision shape is a 0.26 m square plate, 1 cm thick)."""
PAN_SURFACE = 0.07
"""Height [m] of the pan's top surface (frame ``left_tool``) above the left flange."""
BRUSH_LENGTH = 0.16
"""Flange-to-tip length [m] of the brush (frame ``right_tool`` at the tip)."""
BRUSH_HEAD_RADIUS = 0.015
"""Radius [m] of the brush head sphere; its lowest point is the tip."""
BRUSH_MASS = 0.1
"""Mass [kg] of the brush link (what the F/T sensor carries)."""
BRUSH_CONTACT = {"stiffness": 1500.0, "damping": 60.0, "lateral_friction": 0.2}
"""pybullet contact of the brush head: normal stiffness [N/m], damping [N s/m], friction [-]."""


def _pan_tool(side: str) -> str:
    """Left: a pan (stem + plate), frame at the centre of the top surface, z = pan normal.
    Right: a brush (handle + spherical head) in the ``right_tool`` link, frame at the tip."""
    if side == "left":
        half = PAN_SURFACE - 0.005
        return (
            '  <link name="left_flange"><inertial><origin xyz="0 0 0.04"/><mass value="0.8"/>'
            f'{_inertia(0.8, 0.08, 0.1)}</inertial>'
            f'<visual><origin xyz="0 0 {half / 2:.4f}"/><geometry><cylinder radius="0.02" length="{half:.4f}"/></geometry>'
            '<material name="pan_stem"><color rgba="0.3 0.3 0.3 1"/></material></visual>'
            f'<visual><origin xyz="0 0 {half:.4f}"/><geometry><cylinder radius="{PAN_RADIUS}" length="0.01"/></geometry>'
            '<material name="pan"><color rgba="0.15 0.15 0.15 1"/></material></visual>'
            f'<collision><origin xyz="0 0 {half:.4f}"/><geometry><box size="0.26 0.26 0.01"/></geometry></collision>'
            '</link>\n'
            f'  <joint name="left_tool_joint" type="fixed"><parent link="left_flange"/><child link="left_tool"/>'
            f'<origin xyz="0 0 {PAN_SURFACE}"/></joint>\n'
            '  <link name="left_tool"><inertial><mass value="0.001"/>'
            '<inertia ixx="1e-7" ixy="0" ixz="0" iyy="1e-7" iyz="0" izz="1e-7"/></inertial></link>\n'
        )
    head = BRUSH_HEAD_RADIUS
    handle = BRUSH_LENGTH - 2 * head
    contact = "".join(f'<{k} value="{v}"/>' for k, v in BRUSH_CONTACT.items())
    return (
        '  <link name="right_flange"><inertial><mass value="0.001"/>'
        '<inertia ixx="1e-7" ixy="0" ixz="0" iyy="1e-7" iyz="0" izz="1e-7"/></inertial></link>\n'
        f'  <joint name="right_tool_joint" type="fixed"><parent link="right_flange"/><child link="right_tool"/>'
        f'<origin xyz="0 0 {BRUSH_LENGTH}"/></joint>\n'
        f'  <link name="right_tool"><contact>{contact}</contact>'
        f'<inertial><origin xyz="0 0 {-BRUSH_LENGTH / 2:.4f}"/><mass value="{BRUSH_MASS}"/>'
        f'{_inertia(BRUSH_MASS, BRUSH_LENGTH, 0.015)}</inertial>'
        f'<visual><origin xyz="0 0 {-(2 * head + handle / 2):.4f}"/><geometry><cylinder radius="0.01" length="{handle:.4f}"/></geometry>'
        '<material name="brush_handle"><color rgba="0.6 0.4 0.2 1"/></material></visual>'
        f'<visual><origin xyz="0 0 {-head}"/><geometry><sphere radius="{head}"/></geometry>'
        '<material name="bristles"><color rgba="0.9 0.9 0.2 1"/></material></visual>'
        f'<collision><origin xyz="0 0 {-head}"/><geometry><sphere radius="{head}"/></geometry></collision>'
        '</link>\n'
    )


FLANGE_PLATE = (0.035, 0.01, 0.05)
"""The assembly cell's flanges: a mounting plate, radius [m], thickness [m], mass [kg]."""
TOOL_FRAME_OFFSET = {"left": 0.08, "right": 0.12}
"""Tool frame above the flange [m]: the hole's entrance (left), the peg's tip (right)."""


def _tool(side: str, tools: str = "assembly") -> str:
    """Left: tool frame at the hole entrance, z out of the hole. Right: tool frame at the peg tip,
    z along the peg pointing out of the tip. The hole block and the peg themselves are a tool set
    (config/tools/peg_and_hole.yaml, which config/robots/lwr4_cell.yaml names): the flanges carry
    only their mounting plates here. ``tools="pan_cleaning"``: the pan and the brush of
    :func:`_pan_tool` instead."""
    if tools == "pan_cleaning":
        return _pan_tool(side)
    radius, thick, mass = FLANGE_PLATE
    plate = f'<origin xyz="0 0 {thick / 2}"/><geometry><cylinder radius="{radius}" length="{thick}"/></geometry>'
    return (
        f'  <link name="{side}_flange"><inertial><origin xyz="0 0 {thick / 2}"/><mass value="{mass}"/>'
        f'{_inertia(mass, thick, radius)}</inertial>'
        f'<visual>{plate}<material name="flange"><color rgba="0.3 0.3 0.3 1"/></material></visual>'
        f'<collision>{plate}</collision></link>\n'
        f'  <joint name="{side}_tool_joint" type="fixed"><parent link="{side}_flange"/><child link="{side}_tool"/>'
        f'<origin xyz="0 0 {TOOL_FRAME_OFFSET[side]}"/></joint>\n'
        f'  <link name="{side}_tool"><inertial><mass value="0.001"/>'
        '<inertia ixx="1e-7" ixy="0" ixz="0" iyy="1e-7" iyz="0" izz="1e-7"/></inertial></link>\n'
    )


TOOL_SETS = {"assembly": "dualarm_cell.urdf", "pan_cleaning": "dualarm_cell_pan.urdf"}
"""Tool set -> generated file name."""


def make_urdf(tools: str = "assembly") -> str:
    torso = (
        '  <link name="world"/>\n'
        '  <joint name="torso_joint" type="fixed"><parent link="world"/><child link="torso"/></joint>\n'
        '  <link name="torso"><inertial><origin xyz="0 0 0.5"/><mass value="40"/>'
        '<inertia ixx="4" ixy="0" ixz="0" iyy="4" iyz="0" izz="1"/></inertial>'
        '<visual><origin xyz="-0.1 0 0.5"/><geometry><box size="0.2 0.4 1.0"/></geometry>'
        '<material name="torso"><color rgba="0.5 0.5 0.5 1"/></material></visual>'
        '<collision><origin xyz="-0.1 0 0.5"/><geometry><box size="0.2 0.4 1.0"/></geometry></collision></link>\n'
    )
    arms = "".join(_arm(side, y, rpy, tools) for side, y, rpy in MOUNTS)
    return f'<?xml version="1.0"?>\n<!-- generated by urdf/make_cell_urdf.py: do not edit by hand -->\n<robot name="dualarm_cell">\n{torso}{arms}</robot>\n'


if __name__ == "__main__":
    for tool_set, file_name in TOOL_SETS.items():
        out = Path(__file__).with_name(file_name)
        out.write_text(make_urdf(tool_set))
        print(f"wrote {out}")
