"""``dualarm robot``: the robot descriptions (list, show), and ready positions (ready)."""

from __future__ import annotations

import math

import numpy as np

from dualarm_control.robot_params import load_robot, robot_names


def list_command() -> int:
    """One line per shipped robot: name, joints, description."""
    for name in robot_names():
        try:
            robot = load_robot(name)
        except Exception as exc:  # noqa: BLE001 - an uninstalled extra must not hide the others
            print(f"{name:<16} (unavailable: {exc})")
            continue
        print(f"{name:<16} {robot.n_left} + {robot.nq - robot.n_left} joints  {robot.description}")
    return 0


def show_command(name: str) -> int:
    """The resolved description: URDF, joints with limits, tools, locked joints, ready positions."""
    from dualarm_control.kinematics import DualArmModel

    robot = load_robot(name)
    model = DualArmModel(robot)
    print(f"robot {robot.name!r}: {robot.description}")
    print(f"  source: {robot.source}\n  urdf: {robot.urdf}\n  resolved urdf: {robot.urdf_path}")
    print(f"  tools: F1 = {robot.left_tool} (link left_tool), F2 = {robot.right_tool} (link right_tool)")
    if robot.tools is not None:
        for side in ("left", "right"):
            print(f"  tool set {robot.tools.name!r} on {side}_tool: {', '.join(robot.tools.links(side)) or 'nothing'}")
    allowed = ", ".join(f"{a} {b}" for a, b in robot.collision_allowed) or "none"
    print(f"  allowed pairs (robot-wide, overlapping by construction): {allowed}")
    print(f"  reach bound ||p_r|| <= {model.relative_reach():.3f} m")
    print("  joints (left then right): name, limits [deg], velocity limit [rad/s], ready [deg]")
    for i, joint in enumerate(model.joint_names):
        print(f"    {joint:<28} [{math.degrees(model.q_min[i]):8.2f}, {math.degrees(model.q_max[i]):8.2f}]"
              f"  {model.qd_max[i]:6.3f}  {math.degrees(robot.ready[i]):8.2f}")
    for joint, value in robot.locked_positions().items():
        print(f"  locked {joint} = {value:g}")
    p, r = model.relative_pose(robot.ready)
    print(f"  at ready: F2 in F1 p = {np.round(p, 4).tolist()} m, z axes angle "
          f"{math.degrees(math.acos(max(-1.0, min(1.0, float(r[2, 2]))))):.1f} deg")
    return 0


def ready_command(name: str, distance: float, center: list[float] | None, starts: int, seed: int) -> int:
    """Search ready positions (:func:`~dualarm_control.app.robot.ready.find_ready`); print the YAML line."""
    from dualarm_control.app.robot.ready import find_ready
    from dualarm_control.kinematics import DualArmModel

    model = DualArmModel(load_robot(name))
    found = find_ready(model, distance, None if center is None else np.array(center), starts, seed)
    print(f"# {model.description.name}: tools {distance} m apart, facing (F2 in F1: [0, 0, {distance}], rpy 180 0 0),"
          f" midpoint {np.round(found.center, 3).tolist()} m; pose error {found.pose_error:.1e}; smallest singular"
          f" value of J {found.sigma_min:.3f}; nearest limit at {100 * found.limit_margin:.1f} % of its range;"
          f" closest pair {found.clearance[1]} at {found.clearance[0]:.3f} m")
    print("ready_positions_deg: [" + ", ".join(f"{v:.2f}" for v in np.degrees(found.q)) + "]")
    return 0
