"""A plain rclpy script (imports nothing from dualarm_control): drives a running
`dualarm launch interactive` with geometry_msgs/PoseStamped goals on /relative_goal, reads the
relative pose from /relative_pose and the trajectory node's /diagnostics, prints JSON results.

Usage: python plain_driver.py goals|bad
"""

import json
import math
import sys
import time

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped
from rclpy.node import Node

TOL_M, TOL_RAD = 1e-3, 1e-2
HANG_GUARD_S = 120.0  # a hang guard, not a timing claim


def qmul(a, b):
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz)


def about_z(angle):
    return (0.0, 0.0, math.sin(angle / 2), math.cos(angle / 2))


class Driver:
    def __init__(self):
        rclpy.init()
        self.node = Node("plain_driver")
        self.pose = None
        self.status = []
        self.node.create_subscription(PoseStamped, "/relative_pose", self.on_pose, 10)
        self.node.create_subscription(DiagnosticArray, "/diagnostics", self.on_diag, 100)
        self.pub = self.node.create_publisher(PoseStamped, "/relative_goal", 10)
        self.spin_until(lambda: self.pose is not None and self.pub.get_subscription_count() > 0)

    def on_pose(self, m):
        p, o = m.pose.position, m.pose.orientation
        self.pose = ((p.x, p.y, p.z), (o.x, o.y, o.z, o.w))

    def on_diag(self, m):
        for s in m.status:
            if s.name == "trajectory_node":
                self.status.append({kv.key: kv.value for kv in s.values})

    def spin_until(self, cond, limit=HANG_GUARD_S):
        end = time.monotonic() + limit
        while not cond():
            if time.monotonic() > end:
                raise SystemExit(f"hang guard: condition not met in {limit} s")
            rclpy.spin_once(self.node, timeout_sec=0.05)

    def send(self, xyz, quat, frame="left_tool", stamp=None):
        msg = PoseStamped()
        msg.header.frame_id = frame
        msg.header.stamp = stamp if stamp is not None else self.node.get_clock().now().to_msg()
        msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = xyz
        o = msg.pose.orientation
        o.x, o.y, o.z, o.w = quat
        self.pub.publish(msg)
        return msg.header.stamp

    def errors(self, xyz, quat):
        p, q = self.pose
        dist = math.dist(p, xyz)
        dot = min(abs(sum(a * b for a, b in zip(q, quat))), 1.0)
        return dist, 2 * math.acos(dot)

    def arrive(self, xyz, quat):
        """Spin until 20 consecutive poses are within the tolerance; their largest errors."""
        inside = []

        def check():
            d, a = self.errors(xyz, quat)
            inside[:] = [*inside, (d, a)] if d <= TOL_M and a <= TOL_RAD else []
            return len(inside) >= 20

        self.spin_until(check)
        return max(d for d, _ in inside), max(a for _, a in inside)

    def settled(self, xyz, quat, seconds=1.0):
        """The errors after ``seconds`` more (the arms converging on the goal)."""
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            rclpy.spin_once(self.node, timeout_sec=0.05)
        return self.errors(xyz, quat)


def stamp_s(stamp):
    return stamp.sec + 1e-9 * stamp.nanosec


def goals(d):
    p0, q0 = d.pose
    out = {"reached": [], "settled": []}
    plan = [((p0[0] + 0.03, p0[1], p0[2]), q0),
            ((p0[0] - 0.02, p0[1] + 0.03, p0[2] + 0.02), qmul(about_z(0.2), q0))]
    for xyz, quat in plan:
        d.send(xyz, quat)
        out["reached"].append(d.arrive(xyz, quat))
        out["settled"].append(d.settled(xyz, quat))
    start, _ = d.pose
    far = (start[0], start[1] - 0.10, start[2])
    d.send(far, q0)
    d.spin_until(lambda: math.dist(d.pose[0], start) > 0.015)  # moving toward the far goal
    nearest = [math.inf]
    final = (p0[0] + 0.02, p0[1], p0[2] + 0.03)
    d.send(final, q0)  # mid-motion: preempts

    def track():
        nearest[0] = min(nearest[0], math.dist(d.pose[0], far))
        return False

    d.node.create_timer(0.01, track)
    out["reached"].append(d.arrive(final, q0))
    out["settled"].append(d.settled(final, q0))
    out["preempted_at_m"] = math.dist(start, far) - nearest[0]
    out["nearest_to_far_m"] = nearest[0]
    return out


def bad(d):
    p0, q0 = d.pose
    cases = {
        "nan": {"xyz": (math.nan, 0.0, 0.1), "quat": q0},
        "inf": {"xyz": (0.0, math.inf, 0.1), "quat": q0},
        "quaternion": {"xyz": p0, "quat": (0.0, 0.0, 0.0, 1.5)},
        "frame": {"xyz": p0, "quat": q0, "frame": "world"},
        "reach": {"xyz": (3.0, 0.0, 0.0), "quat": q0},
        "older_stamp": {"xyz": p0, "quat": q0, "older": True},
    }
    out = {}
    for i, (name, case) in enumerate(cases.items()):
        goal = ((p0[0] + (0.02 if i % 2 == 0 else -0.02), p0[1], p0[2]), q0)
        good = d.send(*goal)
        good_s = stamp_s(good)
        d.spin_until(lambda good_s=good_s: any(s.get("drive_state") == "moving" and s.get("goal_stamp")
                                               and abs(float(s["goal_stamp"]) - good_s) < 1e-6 for s in d.status))
        moving_from = d.pose[0]
        stamp = None
        if case.get("older"):
            stamp = type(good)(sec=good.sec - 1, nanosec=good.nanosec)
        sent = d.send(case["xyz"], case["quat"], case.get("frame", "left_tool"), stamp)
        d.status.clear()
        d.spin_until(lambda: any(s.get("drive_state") == "rejected" for s in d.status))
        rejected = next(s for s in d.status if s.get("drive_state") == "rejected")
        errors = d.arrive(*goal)
        # a rejection stays the reported state for 1 s: wait for the state after it
        d.spin_until(lambda: any(s.get("drive_state") != "rejected" for s in d.status))
        after = [s for s in d.status if s.get("drive_state") != "rejected"]
        out[name] = {"reason": rejected["reason"], "rejected_stamp": float(rejected["goal_stamp"]),
                     "sent_stamp": stamp_s(sent), "arrived": errors,
                     "goal_stamp_after": float(after[-1]["goal_stamp"]), "good_stamp": stamp_s(good),
                     "moved_m": math.dist(moving_from, goal[0])}
    return out


if __name__ == "__main__":
    driver = Driver()
    result = {"goals": goals, "bad": bad}[sys.argv[1]](driver)
    print("RESULT " + json.dumps(result), flush=True)
    driver.node.destroy_node()
    rclpy.shutdown()
