"""A depth camera's point cloud through controller_node over ROS (issue 42; docs/obstacles.md): ``dualarm launch
assembly --interactive --lockstep`` with the controller's cloud topic set, the arms holding their pose; a node of
this process publishes a PointCloud2 of a ball's surface within the safety distance of an arm link on that topic.
The controller takes it in (raw subscription, the intake's worker), reports the pair on /diagnostics and moves the
link out to the safety distance, and keeps it there; a live change of solver keeps the cloud (the new controller's
limit reads the intake's feed)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import coal
import numpy as np
from test_ros_live import Launch, tail
from waiting import wait_until

from dualarm_control.app.record.bag import CONTROLLER_STATUS
from dualarm_control.collision import CollisionParams
from dualarm_control.collision.live import LiveDistances, LiveObstacle
from dualarm_control.kinematics import DualArmModel
from dualarm_control.scenario import load_scenario

TOPIC = "/test_camera/points"
VOXEL = 0.01
"""m: the cloud's voxels (a cloud's distance is within the voxel's diagonal below the ball's: docs/obstacles.md)."""
BALL = 0.05
"""m: the ball's radius; its surface sampled every 3 mm."""
START_GAP = 0.02
"""m: the ball's distance to the closest arm link where it is put (the cloud's: 0.003-0.02 m), inside d_s."""
TOLERANCE = 1e-3
"""m: below the kept safety distance d_s' that the pair counts as out (inside d_s' the damper asks for
d_dot >= xi (d_s' - d) / (d_i' - d_s'): d comes up to d_s' exponentially, from below)."""


def ball_surface(centre: np.ndarray) -> np.ndarray:
    """Points on the ball's surface about 3 mm apart [m], (k, 3), float32."""
    rng = np.random.default_rng(0)
    count = int(4 * np.pi * BALL**2 / 0.003**2)
    directions = rng.standard_normal((count, 3))
    return (centre + BALL * directions / np.linalg.norm(directions, axis=1)[:, None]).astype(np.float32)


def ball_centre(q: np.ndarray) -> tuple[np.ndarray, str]:
    """Where the ball is START_GAP from the closest arm link at q, above the left tool (bisection along world z),
    and that link."""
    scenario = load_scenario("assembly")
    model = DualArmModel(scenario.robot)
    collision = scenario.collision_model(model)
    live = LiveDistances(collision.model, collision.geometry)
    tool = model.tool_poses(q)[0].translation
    up = np.array([0.0, 0.0, 1.0])

    def gap(height: float) -> tuple[float, str]:
        ball = LiveObstacle.make("ball", coal.Sphere(BALL), np.eye(3), tool + height * up)
        pairs = live.near(q, (ball,), 1.0)
        r = int(np.argmin(pairs.distance))
        return float(pairs.distance[r]), pairs.links[r][0]

    low, high = 0.0, 0.5
    for _ in range(40):
        middle = (low + high) / 2
        low, high = (middle, high) if gap(middle)[0] < START_GAP else (low, middle)
    return tool + high * up, gap(high)[1]


def cloud_message(points: np.ndarray) -> Any:
    from sensor_msgs.msg import PointCloud2, PointField

    msg = PointCloud2()
    msg.header.frame_id = "world"
    msg.height, msg.width = 1, len(points)
    msg.fields = [PointField(name=c, offset=4 * i, datatype=PointField.FLOAT32, count=1) for i, c in enumerate("xyz")]
    msg.point_step, msg.row_step, msg.is_dense = 12, 12 * len(points), True
    msg.data = points.tobytes()
    return msg


def switch_solver(node: Any, executor: Any, solver: str) -> bool:
    """``solver`` set on /controller_node through a parameter client of ``node``; whether it was accepted."""
    from rclpy.parameter import Parameter
    from rclpy.parameter_client import AsyncParameterClient

    client = AsyncParameterClient(node, "/controller_node")
    assert client.wait_for_services(timeout_sec=60.0), "no parameter services of /controller_node"
    future = client.set_parameters([Parameter("solver", value=solver)])
    executor.spin_until_future_complete(future, timeout_sec=60.0)
    assert future.done(), "no answer from /controller_node within 60 s"
    return all(r.successful for r in future.result().results)


def test_a_cloud_on_the_topic_makes_the_controller_keep_its_distance(tmp_path: Path) -> None:
    from diagnostic_msgs.msg import DiagnosticArray
    from sensor_msgs.msg import JointState, PointCloud2

    from dualarm_control.ros.node import tool_node

    params = tmp_path / "cloud.yaml"
    params.write_text("controller_node:\n  ros__parameters:\n    collision.live_obstacles: 2\n"
                      f"    obstacles.cloud_topic: {TOPIC}\n    obstacles.cloud_voxel: {VOXEL}\n"
                      "    obstacles.cloud_lifetime: 0.0\n")
    _, safety = CollisionParams().kept_distances
    names = DualArmModel(load_scenario("assembly").robot).joint_names
    states: list[np.ndarray] = []
    reports: list[dict[str, str]] = []

    def on_state(msg: JointState) -> None:
        where = dict(zip(msg.name, msg.position, strict=True))
        states.append(np.array([where[n] for n in names]))

    def on_diagnostics(msg: DiagnosticArray) -> None:
        for status in msg.status:
            values = {kv.key: kv.value for kv in status.values}
            if status.name == CONTROLLER_STATUS and "live_obstacle_pair" in values:
                reports.append(values)

    launch = Launch("assembly", "--interactive", "--lockstep", "--solver", "standard_qp", "--params", str(params))
    try:
        launch.wait_for("interactive: holding the measured relative pose", timeout=180)
        with tool_node("cloud_probe") as (node, executor, _):
            node.create_subscription(JointState, "/joint_states", on_state, 10)
            node.create_subscription(DiagnosticArray, "/diagnostics", on_diagnostics, 100)
            camera = node.create_publisher(PointCloud2, TOPIC, 1)

            def spin() -> None:
                executor.spin_once(timeout_sec=0.05)

            def gone() -> str | None:
                return None if launch.popen.poll() is None else "the launch exited:\n" + tail(launch.lines)

            wait_until(lambda: states, lambda: "no joint state", what="/joint_states", step=spin, gone=gone)
            centre, link = ball_centre(states[-1])
            cloud = cloud_message(ball_surface(centre))

            def seen() -> str:
                return f"{len(reports)} reports, the last: {reports[-1] if reports else None}"

            def yielded() -> bool:
                camera.publish(cloud)  # until the intake has it (a late subscription match loses the first)
                return any(r["live_obstacle_pair"].endswith("obstacle:cloud") for r in reports)

            wait_until(yielded, seen, what="the cloud's pair on /diagnostics", step=spin, gone=gone, timeout=120)
            first = next(k for k, r in enumerate(reports) if r["live_obstacle_pair"].endswith("obstacle:cloud"))
            held = wait_until(lambda: next((k for k in range(first, len(reports))
                                            if float(reports[k]["live_obstacle_distance_m"]) >= safety - TOLERANCE),
                                           None),
                              seen, what=f"the pair out to d_s' = {safety} m", step=spin, gone=gone, timeout=120)
            end = len(reports) + 200  # then 200 more cycles: the distance kept
            wait_until(lambda: len(reports) >= end, seen, what="200 more cycles", step=spin, gone=gone, timeout=120)
            switched = switch_solver(node, executor, "sparse_qp")  # a live change: the new controller reads the feed
            wait_until(lambda: sum(r.get("solver") == "sparse_qp" for r in reports) >= 100, seen,
                       what="100 cycles of sparse_qp after the live change", step=spin, gone=gone, timeout=120)
    finally:
        launch.kill()
    distances = np.array([float(r["live_obstacle_distance_m"]) for r in reports[first:]])
    active = [int(r["live_obstacle_active"]) for r in reports[first:held + 1]]
    after = distances[held - first:]
    print(f"ball above the left tool, closest link {link}: the cloud's pair at {distances[0] * 1e3:.1f} mm when first "
          f"seen, {held - first} cycles to within {TOLERANCE * 1e3:g} mm of d_s' = {safety * 1e3:.0f} mm (rows active "
          f"in {sum(a > 0 for a in active)}), then {after.min() * 1e3:.3f} to {after.max() * 1e3:.3f} mm over "
          f"{len(after)} cycles, the last 50 from {after[-50:].min() * 1e3:.4f} mm")
    assert switched, "the live change of solver was refused"
    changed = [r for r in reports if r.get("solver") == "sparse_qp"]
    assert all(r["live_obstacle_pair"].endswith("obstacle:cloud") and r["live_obstacles"] == "1" for r in changed), \
        changed[0]  # the cloud still there for the new controller (its limit took over the intake's feed)
    assert min(float(r["live_obstacle_distance_m"]) for r in changed) >= safety - TOLERANCE
    assert distances[0] < safety - 0.005  # it was put inside the safety distance
    assert any(active), "the rows held the command while the link moved out"
    assert after.min() >= safety - TOLERANCE  # once out, never back in
    assert after[-50:].min() >= safety - 1e-4  # the damper's approach to d_s' (from below: exponential)
