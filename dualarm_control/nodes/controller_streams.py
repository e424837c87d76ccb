"""controller_node's subscriptions to the reference source's streams (``/relative_target``,
``/joint_reference``, the F/T wrenches): each sample, or its rejection, goes to
:class:`~dualarm_control.nodes.controller_inputs.ControllerInputs`."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from geometry_msgs.msg import WrenchStamped
from trajectory_msgs.msg import JointTrajectory, MultiDOFJointTrajectory

from dualarm_control.kinematics import DualArmModel
from dualarm_control.nodes.controller_inputs import WRENCH_STREAMS, ControllerInputs
from dualarm_control.references.base import JOINT_REFERENCE, RELATIVE_TARGET
from dualarm_control.ros import convert, inputs
from dualarm_control.ros.local_bus import LocalBus


def subscribe_streams(node: Any, streams_in: ControllerInputs, model: DualArmModel, qos: Any,
                      bus: LocalBus | None, on_malformed: Callable[[str], None]) -> None:
    """Subscribe ``node`` to the streams ``streams_in`` consumes, with ``qos`` (wrenches: depth 10);
    a sample that fails to deserialize goes to ``on_malformed``, a refused one to
    :meth:`ControllerInputs.rejected`."""
    streams, order = streams_in.streams, {name: i for i, name in enumerate(model.joint_names)}

    def subscribe(msg_type: Any, topic: str, callback: Any, depth: Any, decoder: Any = None) -> None:
        inputs.subscribe_checked(node, msg_type, topic, callback, depth, on_malformed, decoder, bus,
                                 lambda exc: streams_in.rejected(topic, exc))

    if RELATIVE_TARGET in streams:
        subscribe(MultiDOFJointTrajectory, RELATIVE_TARGET, lambda s: streams_in.put(RELATIVE_TARGET, *s),
                  qos, convert.TargetInput(model.relative_reach()))
    if JOINT_REFERENCE in streams:
        subscribe(JointTrajectory, JOINT_REFERENCE,
                  streams_in.message_input(JOINT_REFERENCE, lambda msg: convert.joint_reference(msg, order)), qos)
    for wrench in WRENCH_STREAMS:
        if wrench in streams:
            subscribe(WrenchStamped, wrench, streams_in.message_input(wrench, convert.wrench_vector), 10)
