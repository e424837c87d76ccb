"""``float64_multi_array``: std_msgs/Float64MultiArray, the values in the output's joint order, layout
empty: the convention of ros2_control's JointGroupVelocityController and
JointGroupPositionController (forward_command_controller)."""

from __future__ import annotations

from typing import Any

import numpy as np

from dualarm_control.outputs.base import FloatArray, OutputSpec, OutputType, register
from dualarm_control.ros import cdr


@register
class Float64MultiArrayOutput(OutputType):
    """Float64MultiArray ``data`` (len(joints),) [rad/s or rad], positional (no joint names)."""

    key = "float64_multi_array"
    type_name = "std_msgs/msg/Float64MultiArray"

    def encode(self, spec: OutputSpec, values: FloatArray, period: float) -> bytes:
        return cdr.float64_multi_array(values)

    def decode(self, spec: OutputSpec, msg: Any) -> FloatArray:
        return np.asarray(msg.data, dtype=float)

    def decode_bytes(self, spec: OutputSpec, data: bytes) -> FloatArray:
        return cdr.float64_multi_array_data(data)
