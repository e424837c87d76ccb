"""Node plumbing shared by the three nodes and the tool verbs, on plain rclpy.

* :func:`declare` declares the core's :class:`~dualarm_control.params.ParamSpec` list on an
  rclpy node with descriptors (description, constraints, read-only) and validates the
  values with the core's rules, so a bad value from a file, ``-p`` or a live ``param set``
  is refused with the same message.
* :func:`run` is a node's ``main``: it checks ``--params-file`` files, initialises rclpy with
  localhost discovery and fast Fast DDS announcements by default (ros/env.py), spins until the node finishes, Ctrl-C or SIGTERM, then
  closes the shell, destroys the node and shuts rclpy down in that order (so no "publisher's
  context is invalid"). Exit codes: 0 normal end or signal, 2 bad parameters, 1 other errors.
* :func:`tool_node` gives the tool verbs a short-lived node and executor.
* :class:`LiveParameters`: live changes validated at once, applied at the next cycle boundary.
* :func:`clock_ns`: a clock's time in integer nanoseconds, without a ``Time`` object.
"""

from __future__ import annotations

import array
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from contextlib import contextmanager, nullcontext
from types import FrameType
from typing import Any, Generic, Self, TypeVar

from dualarm_control.errors import DualArmError, ParameterError
from dualarm_control.params import ParamSpec, params_files, read_params_files
from dualarm_control.ros.env import (
    apply_discovery_profile,
    apply_localhost_default,
    stop_with_launcher,
)
from dualarm_control.ros.node_exit import (
    ACK_TIMEOUT_S,
    EXIT_OK,
    EXIT_PARAMS,
    EXIT_STUCK_S,
    FINISHED_ACK_TIMEOUT_S,
    ExitWatchdog,
    flush_publishers,
)
from dualarm_control.ros.priority import apply_priority

SPIN_TIMEOUT_S = 0.1
T = TypeVar("T")


def descriptor(spec: ParamSpec) -> Any:
    """rcl_interfaces/ParameterDescriptor of ``spec``: description, constraints, read-only, range."""
    from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor

    d = ParameterDescriptor(description=spec.description, additional_constraints=spec.constraints,
                            read_only=spec.read_only)
    if spec.bounds is not None and spec.type_name == "double":
        d.floating_point_range = [FloatingPointRange(from_value=float(spec.bounds[0]), to_value=float(spec.bounds[1]),
                                                     step=0.0)]
    elif spec.bounds is not None and spec.type_name == "integer":
        d.integer_range = [IntegerRange(from_value=int(spec.bounds[0]), to_value=int(spec.bounds[1]), step=1)]
    return d


def declare(node: Any, specs: Iterable[ParamSpec]) -> dict[str, Any]:
    """Declare ``specs`` on ``node``; return their validated values (ParameterError if bad).

    A value of the wrong ROS type (``-p gain:=10`` for a double) is reported with the same
    message as the core's check; unknown overrides for this node are warned about.
    """
    from rclpy.exceptions import (
        InvalidParameterTypeException,
        InvalidParameterValueException,
    )

    values: dict[str, Any] = {}
    name = node.get_name()
    overrides: Mapping[str, Any] = getattr(node, "_parameter_overrides", {})
    specs = list(specs)
    for spec in specs:
        try:
            value = node.declare_parameter(spec.name, spec.default, descriptor(spec)).value
        except (InvalidParameterTypeException, InvalidParameterValueException) as exc:
            given = overrides[spec.name].value if spec.name in overrides else str(exc)
            spec.validate(given, name)  # raises ParameterError naming key, value and type
            raise DualArmError(str(exc)) from None
        values[spec.name] = spec.validate(value, name)
    declared = {s.name for s in specs} | {"use_sim_time", "start_type_description_service"}
    for key in overrides:
        if key not in declared and not node.has_parameter(key):
            node.get_logger().warning(f"ignoring unknown parameter '{key}' (not declared by {name})")
    return values


class LiveParameters(Generic[T]):
    """Live parameter changes of ``node``: each is validated with the core's rules (``specs``) and
    by ``build`` (which makes what the change needs, e.g. a new controller, and raises
    DualArmError or ValueError to refuse it) when it is set; :meth:`take` hands the accepted
    change over at the next cycle boundary. A refused change leaves the running values untouched."""

    def __init__(self, node: Any, specs: Mapping[str, ParamSpec], values: dict[str, Any],
                 build: Callable[[dict[str, Any]], T]) -> None:
        self.node, self.specs, self.values, self.build = node, specs, values, build
        self.pending: tuple[dict[str, Any], T] | None = None
        node.add_on_set_parameters_callback(self.on_set)

    def on_set(self, parameters: list[Any]) -> Any:
        from rcl_interfaces.msg import SetParametersResult

        # rclpy gives an array parameter as array.array ('d', 'q'): the specs' and the values' type is a list
        changes = {p.name: list(p.value) if isinstance(p.value, array.array) else p.value
                   for p in parameters if p.name in self.specs}
        if not changes:
            return SetParametersResult(successful=True)
        try:
            for key, value in changes.items():
                self.specs[key].validate(value, self.node.get_name())
            merged = {**(self.pending[0] if self.pending is not None else self.values), **changes}  # two sets before a cycle: both
            built = self.build(merged)
        except (DualArmError, ValueError) as exc:
            self.node.get_logger().warning(f"parameter change refused: {exc}")
            return SetParametersResult(successful=False, reason=str(exc))
        self.pending = (merged, built)
        return SetParametersResult(successful=True)

    def take(self, where: str = "") -> tuple[dict[str, Any], T] | None:
        """The accepted change not yet applied (its values and what ``build`` made), logged
        ("parameters changed<where>: ..."); or None."""
        if self.pending is None:
            return None
        (merged, built), self.pending = self.pending, None
        changed = {k: v for k, v in merged.items() if self.values.get(k) != v}
        self.values = merged
        self.node.get_logger().info(f"parameters changed{where}: "
                                    + ", ".join(f"{k}={v!r}" for k, v in changed.items()))
        return merged, built


class StopOnSignal:
    """SIGINT/SIGTERM set a flag that a loop checks instead of raising where they land (rclpy's own
    handlers are off, so the context stays valid until the node is destroyed; the launcher never has
    a KeyboardInterrupt inside a ``Popen.poll`` holding its lock). Outside the main thread, where
    Python takes no signal handler, it installs none and the flag stays unset."""

    def __init__(self) -> None:
        self.signal: int | None = None
        self._previous: dict[int, Any] = {}

    def _handle(self, signum: int, frame: FrameType | None) -> None:
        self.signal = signum

    def __enter__(self) -> Self:
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                self._previous[sig] = signal.signal(sig, self._handle)
        return self

    def __exit__(self, *exc: object) -> None:
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)


def init_rclpy(argv: Sequence[str]) -> Any:
    """``rclpy.init`` with localhost discovery and the package's Fast DDS discovery profile by default
    (ros/env.py), and no rclpy signal handlers; returns the context."""
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    apply_localhost_default()
    apply_discovery_profile()
    context = rclpy.Context()
    rclpy.init(args=list(argv), context=context, signal_handler_options=SignalHandlerOptions.NO)
    return context


EXECUTOR_VARIABLE = "DUALARM_EXECUTOR"


def make_executor(context: Any) -> Any:
    """The nodes' executor: rclpy's C++ EventsExecutor (``rclpy.experimental``, Jazzy) when present,
    else the SingleThreadedExecutor; ``DUALARM_EXECUTOR=single`` forces the latter. At 1 kHz the
    events executor cut the per-callback overhead of the Python wait-set loop (docs/bench.md)."""
    import os

    from rclpy.executors import SingleThreadedExecutor

    if os.environ.get(EXECUTOR_VARIABLE, "events") != "single":
        try:
            from rclpy.experimental.events_executor import EventsExecutor
        except ImportError:
            pass
        else:
            return EventsExecutor(context=context)
    return SingleThreadedExecutor(context=context)


Tick = tuple[float, Callable[[], None]]
"""A periodic callback of a node shell: (period [s], callback)."""


class Ticker:
    """The nodes' periodic callbacks, run by the spin loop itself between the executor's events.

    As ros2_control's controller manager runs its update loop: each tick is due at ``start + k
    period`` on the monotonic clock (drift-free) and runs in the order given, so ticks of equal
    periods in one process run back to back, in that order. A tick that fell more than a period
    behind skips to the next due time instead of running the missed ones in a burst. An rclpy
    timer costs two thread wake-ups per tick (the executor's timer thread, then its event queue):
    3 timers at 1 kHz ran 2483 callbacks/s at 0.156 core, this loop 3000/s at 0.061 (docs/bench.md).
    """

    def __init__(self, ticks: list[Tick], now: float | None = None) -> None:
        start = time.monotonic() if now is None else now
        self.ticks = ticks
        self.due = [start + period for period, _ in ticks]

    def timeout(self, now: float) -> float:
        """Seconds until the next tick is due (at most :data:`SPIN_TIMEOUT_S`, at least 0)."""
        return min([SPIN_TIMEOUT_S, *(due - now for due in self.due)]) if self.due else SPIN_TIMEOUT_S

    def run_due(self, now: float) -> None:
        """Run every tick due at ``now``, in order."""
        for i, (period, callback) in enumerate(self.ticks):
            if now >= self.due[i]:
                self.due[i] += period
                if now - self.due[i] > period:
                    self.due[i] = now + period
                callback()


def spin_until_stopped(executor: Any, stop: StopOnSignal, until: Callable[[], bool] = lambda: False,
                       ticks: list[Tick] | None = None) -> None:
    """Run callbacks and the periodic ``ticks`` until a signal or ``until()``."""
    ticker = Ticker(ticks or [])
    while stop.signal is None and not until():
        now = time.monotonic()
        ticker.run_due(now)
        timeout = ticker.timeout(time.monotonic())
        if timeout > 0.0:
            executor.spin_once(timeout_sec=timeout)


def clock_ns(clock: Any) -> int:
    """``clock.now().nanoseconds`` of an rclpy ``Clock`` without building the ``Time`` (4.2 against 1.1 us a
    call): the same reading of rcl's clock, /clock's time where it overrides ROS time (``use_sim_time``)."""
    handle = clock.handle
    with handle:
        return int(handle.get_now().nanoseconds)


def usage(name: str, doc: str, specs: Iterable[ParamSpec]) -> str:
    """``--help`` text of a node: its docstring and its parameters (type, default, rule)."""
    lines = [f"usage: {name} [--ros-args [-p NAME:=VALUE] [--params-file FILE] [-r FROM:=TO] ...]", "",
             doc.strip(), "", "parameters:"]
    for spec in specs:
        rule = f"; {spec.constraints}" if spec.constraints else ""
        ro = ", read-only" if spec.read_only else ""
        lines.append(f"  {spec.name} ({spec.type_name}, default {spec.default!r}{ro}): {spec.description}{rule}")
    lines.append("  use_sim_time (bool, default False): stamp with /clock (simulation time)")
    return "\n".join(lines)


ROS_VALUE_FLAGS = frozenset({"-p", "--param", "-r", "--remap", "--params-file", "--log-level", "--log-config-file",
                             "--log-file-name", "-e", "--enclave"})
"""rcl's ROS arguments that take the next argument as their value (a ``--help`` there is that value)."""


def wants_help(argv: Sequence[str]) -> bool:
    """``-h``/``--help`` anywhere in ``argv[1:]``: before ``--ros-args`` or among the ROS arguments, as
    ``ros2 run PKG NODE --ros-args --help`` (``dualarm run NODE --help`` passes ``--ros-args --help``);
    not the value of a ROS argument that takes one (``-p``, ``-r``, ``--params-file``, ...)."""
    args = list(argv[1:]) if argv else []
    return any(arg in ("-h", "--help") and (i == 0 or args[i - 1] not in ROS_VALUE_FLAGS)
               for i, arg in enumerate(args))


def run(make: Callable[[Any], Any], args: Sequence[str] | None = None, help_text: str = "",
        priority: int = 0) -> int:
    """A node's main: build the shell with ``make(context)``, spin it under SCHED_FIFO ``priority``
    (0: normal scheduling; :attr:`PriorityRequest.granted`), shut down cleanly.

    ``make`` returns a shell object with a ``node`` attribute (or ``nodes``, several nodes in
    one process on one executor: ``cell_container``), optional ``ticks`` (its periodic
    callbacks, run by :class:`Ticker`), an optional ``finished`` flag
    that ends spinning normally when a callback sets it (e.g. scenario complete), an
    optional ``close()`` (called once on the way out, while the node can still log), and an optional
    ``lockstep`` flag: a lockstep node waits on the way out until its readers acknowledged what it
    published (:func:`flush_publishers`), so that a lagging recorder gets the run's end.
    ``-h``/``--help`` prints ``help_text`` and exits 0.
    """
    argv = list(sys.argv if args is None else args)
    if wants_help(argv):
        print(help_text)
        return EXIT_OK
    shell = None
    context = None
    with StopOnSignal() as stop:
        stop_with_launcher()
        try:
            read_params_files(params_files(argv), "_check_")  # missing or malformed file: exit 2
            context = init_rclpy(argv)
            shell = make(context)
            executor = make_executor(context)
            for node in shell_nodes(shell):
                executor.add_node(node)
            apply_priority(priority)
            spin_until_stopped(executor, stop, lambda: bool(getattr(shell, "finished", False)),
                               list(getattr(shell, "ticks", ())))
        except ParameterError as exc:
            print(f"error: {exc}", file=sys.stderr, flush=True)
            return EXIT_PARAMS
        except DualArmError as exc:
            print(f"error: {exc}", file=sys.stderr, flush=True)
            return EXIT_PARAMS
        except KeyboardInterrupt:
            pass
        except Exception as exc:  # rcl's own argument errors (e.g. a malformed -p) are usage errors
            if type(exc).__name__ in ("RCLError", "InvalidROSArgsError", "RCLInvalidROSArgsError"):
                print(f"error: invalid ROS arguments: {exc}", file=sys.stderr, flush=True)
                return EXIT_PARAMS
            raise
        finally:
            watchdog = ExitWatchdog(EXIT_STUCK_S)
            if shell is not None:
                watchdog.stage = "close"
                close = getattr(shell, "close", None)
                if close is not None:
                    close()
                if getattr(shell, "lockstep", False):
                    watchdog.stage = "flush"
                    flush_publishers(shell_nodes(shell), ACK_TIMEOUT_S)
                elif getattr(shell, "finished", False):  # ended by itself (a trajectory node's "complete")
                    watchdog.stage = "flush"
                    flush_publishers(shell_nodes(shell), FINISHED_ACK_TIMEOUT_S)
                watchdog.stage = "teardown"
                for node in shell_nodes(shell):
                    node.destroy_node()
            watchdog.stage = "teardown"
            if context is not None:
                context.try_shutdown()
            watchdog.cancel()
    return EXIT_OK


def shell_nodes(shell: Any) -> list[Any]:
    """The rclpy nodes of a shell given to :func:`run`: its ``nodes``, else its ``node``."""
    return list(getattr(shell, "nodes", None) or [shell.node])


DISCOVERY_TIMEOUT_S = 20.0
"""How long a tool waits for the one node or topic it looks for (``dualarm param``, ``dualarm
topic echo|hz|info``); it answers as soon as it is found. Each tool is a new DDS participant:
Fast DDS discovered a running node's parameter services 0.15-4.1 s after such a start here
(40 starts on the loaded 2-core machine, 28 of them 2.2-4.1 s: a missed initial announcement
waits for the next one, 3 s later), so a 5 s wait answered "not found" for a node that was there."""


@contextmanager
def tool_node(name: str, signals: bool = True) -> Iterator[tuple[Any, Any, StopOnSignal]]:
    """A node, its executor and a stop flag for a tool verb; torn down in the right order.

    With ``signals`` (the default) Ctrl-C/SIGTERM set the flag (:class:`StopOnSignal`); without,
    no handler is installed (a server run in any thread; Ctrl-C raises KeyboardInterrupt as usual)
    and the flag stays unset."""
    from rclpy.node import Node

    context = init_rclpy([])
    node = None
    stop = StopOnSignal()
    try:
        with stop if signals else nullcontext(stop):
            node = Node(name, context=context, start_parameter_services=False)
            executor = make_executor(context)
            executor.add_node(node)
            yield node, executor, stop
    finally:
        if node is not None:
            node.destroy_node()
        context.try_shutdown()
