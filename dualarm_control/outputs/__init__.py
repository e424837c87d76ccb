"""The controller's command output message types behind one registry (issue 39, docs/outputs.md):
``output_type("joint_trajectory").encode(spec, values, period)``.

Each type is a file of this package; its import below registers it (``@register``).
"""

from __future__ import annotations

from dualarm_control.outputs import float64_multi_array as _float64_multi_array  # noqa: F401 - registers
from dualarm_control.outputs import joint_trajectory as _joint_trajectory  # noqa: F401 - registers
from dualarm_control.outputs.base import (
    CommandDecoder,
    OutputSpec,
    OutputType,
    by_name,
    check_command,
    output_names,
    output_type,
    register,
    unregister,
)

__all__ = [
    "CommandDecoder",
    "OutputSpec",
    "OutputType",
    "by_name",
    "check_command",
    "output_names",
    "output_type",
    "register",
    "unregister",
]
