"""What every node shares: parameter declaration with validation, and the run/exit protocol.

Exit codes: 0 normal end (or Ctrl-C / SIGTERM), 2 bad parameters (message names the key,
the value and the valid choices), 1 an unexpected error.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterable, Sequence
from typing import Any

from dualarm_control import ros
from dualarm_control.errors import DualArmError
from dualarm_control.params import ParamSpec

EXIT_PARAMS = 2


class NodeFinished(Exception):
    """Raised by a node's callback to end spinning normally (e.g. scenario complete)."""


def declare(node: Any, specs: Iterable[ParamSpec]) -> dict[str, Any]:
    """Declare ``specs`` on ``node`` and return their validated values (ParameterError if bad)."""
    values: dict[str, Any] = {}
    name = node.get_name()
    for spec in specs:
        try:
            value = node.declare_parameter(spec.name, spec.default, description=spec.description).value
        except ros.InvalidParameterTypeException as exc:
            raise DualArmError(str(exc)) from None  # names the parameter, value and expected type
        values[spec.name] = spec.validate(value, name)
    for key in node.undeclared_overrides():
        node.get_logger().warning(f"ignoring unknown parameter '{key}' (not declared by {name})")
    return values


def request_realtime_priority(priority: int) -> str:
    """Put this process (and threads it creates later) under SCHED_FIFO ``priority`` (1-99), like
    ros2_control's ``thread_priority``. Returns '' on success, else why not (callers warn and go on)."""
    import os

    if priority <= 0:
        return "disabled"
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(min(priority, 99)))
    except (AttributeError, PermissionError, OSError) as exc:
        return f"SCHED_FIFO {priority} not permitted ({exc}); running with normal priority"
    return ""


def run_node(make: Callable[[], Any], args: Sequence[str] | None = None) -> int:
    """Init the middleware, build the node shell with ``make()``, spin until done; return the exit code.

    ``make()`` returns a ros Node, or a shell object with a ``node`` attribute and an optional
    ``close()`` called once on the way out (Ctrl-C, SIGTERM, NodeFinished or error).
    """
    argv = list(sys.argv if args is None else args)
    shell = None
    try:
        ros.init(args=argv)
        shell = make()
        ros.spin(getattr(shell, "node", shell))
    except NodeFinished:
        return 0
    except DualArmError as exc:
        print(f"error: {exc}", file=sys.stderr, flush=True)
        return EXIT_PARAMS
    except (KeyboardInterrupt, ros.ExternalShutdownException):
        return 0
    finally:
        if shell is not None:
            close = getattr(shell, "close", None)
            if close is not None:
                close()
            getattr(shell, "node", shell).destroy_node()
        ros.try_shutdown()
    return 0
