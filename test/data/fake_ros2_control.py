"""A plain rclpy script (imports nothing from dualarm_control) posing as a ros2_control cell: two
velocity_controllers/JointGroupVelocityController (``left_velocity_controller`` and
``right_velocity_controller``, each with its own ``joints`` order, not the description's) and a
joint_state_broadcaster on /joint_states (the hardware's order: scrambled, two gripper joints extra).

As the real controllers: a command of the wrong length is dropped silently, there is no command
timeout. The "hardware" integrates the commanded velocities at 200 Hz (wall clock). It exits once
the trajectory node reports "complete" on /diagnostics (or after HANG_GUARD_S) and prints JSON: the
controller's last position_error_m and the commands each controller received.

Usage: python fake_ros2_control.py INITIAL_POSITIONS_JSON [RENAME_JSON]
(joint name -> rad; RENAME_JSON: joint name -> the name the broadcaster gives it, a mismatched description)
"""

import json
import sys
import time

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

PERIOD = 0.005
HANG_GUARD_S = 120.0  # a hang guard, not a timing claim
LEFT = [f"left_joint_{i}" for i in (7, 6, 5, 4, 3, 2, 1)]
RIGHT = [f"right_joint_{i}" for i in (2, 1, 4, 3, 6, 5, 7)]
GRIPPERS = ["left_gripper_finger_joint", "right_gripper_finger_joint"]
BROADCAST = ["right_gripper_finger_joint", "right_joint_5", "left_joint_3", "right_joint_1", "left_joint_7",
             "right_joint_7", "left_joint_1", "right_joint_3", "left_joint_5", "left_gripper_finger_joint",
             "right_joint_2", "left_joint_2", "right_joint_6", "left_joint_4", "right_joint_4", "left_joint_6"]


class Cell:
    def __init__(self, initial, rename):
        rclpy.init()
        self.node = Node("controller_manager")
        self.rename = rename
        self.q = {n: float(initial.get(n, 0.0)) for n in BROADCAST}
        self.qd = dict.fromkeys(BROADCAST, 0.0)
        self.received = {"left_velocity_controller": 0, "right_velocity_controller": 0}
        self.error = None
        self.complete_at = None
        self.pub = self.node.create_publisher(JointState, "/joint_states", 10)
        for name, joints in (("left_velocity_controller", LEFT), ("right_velocity_controller", RIGHT)):
            self.node.create_subscription(Float64MultiArray, f"/{name}/commands",
                                          lambda m, name=name, joints=joints: self.on_command(name, joints, m), 10)
        self.node.create_subscription(DiagnosticArray, "/diagnostics", self.on_diag, 100)
        self.node.create_timer(PERIOD, self.update)

    def on_command(self, name, joints, msg):
        if len(msg.data) != len(joints):
            return  # as forward_command_controller: dropped silently
        self.received[name] += 1
        self.qd.update(zip(joints, msg.data))

    def on_diag(self, msg):
        for s in msg.status:
            values = {kv.key: kv.value for kv in s.values}
            if s.name == "controller_node" and "position_error_m" in values:
                self.error = float(values["position_error_m"])
            if s.name == "trajectory_node" and s.message == "complete" and self.complete_at is None:
                self.complete_at = time.monotonic()

    def update(self):
        for n in BROADCAST:
            self.q[n] += self.qd[n] * PERIOD
        now = self.node.get_clock().now().to_msg()
        msg = JointState(name=[self.rename.get(n, n) for n in BROADCAST], position=[self.q[n] for n in BROADCAST],
                         velocity=[self.qd[n] for n in BROADCAST])
        msg.header.stamp = now
        self.pub.publish(msg)


def main():
    cell = Cell(json.loads(sys.argv[1]), json.loads(sys.argv[2]) if len(sys.argv) > 2 else {})
    end = time.monotonic() + HANG_GUARD_S
    try:
        while time.monotonic() < end and (cell.complete_at is None or time.monotonic() - cell.complete_at < 0.5):
            rclpy.spin_once(cell.node, timeout_sec=0.01)
    finally:
        print(json.dumps({"complete": cell.complete_at is not None, "position_error_m": cell.error,
                          "received": cell.received}), flush=True)
        cell.node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
