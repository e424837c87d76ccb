"""``/dualarm/cell``: each node of the cell says, latched, what it runs with (issue 40).

Every node of the package publishes on :data:`CELL_TOPIC` (std_msgs/String, keep-last 1, reliable,
transient local, as ``/robot_description``) one ROS 2 parameter file (YAML) giving the node its
parameters as they are: the robot, the hardware profile, the scenario, the solver and the limits.
It publishes again after every accepted live change. A recorder that joins late still gets it, and
``dualarm bag record`` keeps it whenever a node publishes it (as ``/robot_description``), so a bag
carries its cell: ``dualarm report``, ``view`` and ``faults`` read the run through the recorded
profile (:mod:`dualarm_control.app.record.cell`). The file can be given back to a node
(``--params-file``) to run the same cell again.
"""

from __future__ import annotations

import array
from typing import Any, Final

from dualarm_control.params import params_document
from dualarm_control.ros.qos import latched_qos

CELL_TOPIC: Final = "/dualarm/cell"
NOT_RECORDED: Final = ("start_type_description_service",)
"""rclpy's own parameters that say nothing about the cell."""


def node_parameters(node: Any) -> dict[str, Any]:
    """Every parameter of ``node`` but :data:`NOT_RECORDED`, by name, with its current value (an array set live,
    which rclpy keeps as array.array, as a list)."""
    return {name: list(param.value) if isinstance(param.value, array.array) else param.value
            for name, param in sorted(node.get_parameters_by_prefix("").items()) if name not in NOT_RECORDED}


class CellPublisher:
    """Publishes ``node``'s parameters on :data:`CELL_TOPIC` now and after every accepted change."""

    def __init__(self, node: Any) -> None:
        from std_msgs.msg import String

        self.node = node
        self.message = String
        self.pub = node.create_publisher(String, CELL_TOPIC, latched_qos())
        self.publish()
        node.add_post_set_parameters_callback(lambda _params: self.publish())

    def publish(self) -> None:
        self.pub.publish(self.message(data=params_document(self.node.get_name(), node_parameters(self.node))))
