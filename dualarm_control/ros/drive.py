"""``dualarm topic pub``, ``dualarm goal`` and ``dualarm jog``: drive the cell from the command line.

* ``topic pub TOPIC TYPE VALUES`` publishes any installed message type filled from YAML, as
  ``ros2 topic pub`` does (ros2cli's ``ros2topic/verb/pub.py``): ``VALUES`` is a YAML mapping
  of the message's fields (nested for nested messages, ``header: auto`` or ``stamp: now`` for
  the current time), default ``{}``; 1 Hz until Ctrl-C, or ``--once`` / ``-t N`` messages after
  waiting for one matching subscription (``-w``), then 0.1 s to let them reach the wire.
  ``rosidl_runtime_py`` (ros2cli's ``set_message_fields``) has no ros-jazzy wheel, so
  :func:`set_message_fields` is a small equivalent over ``get_fields_and_field_types()``.
* ``goal`` publishes one geometry_msgs/PoseStamped on ``/relative_goal`` (frame ``left_tool``)
  and with ``--wait`` follows the trajectory node's ``/diagnostics`` drive keys
  (:data:`dualarm_control.drive_status.STATUS_KEYS`) until the goal is reached (exit 0),
  or rejected, stalled or timed out (exit 1).
* ``jog`` streams geometry_msgs/TwistStamped on ``/relative_twist`` at ``--rate`` for
  ``--seconds``; the node brakes to rest ``jog_timeout`` after the last one.
* ``--absolute`` (issue 41): the same on ``/absolute_goal`` and ``/absolute_twist``, frame ``world``: the absolute
  frame's pose or twist (the scenario's ``absolute_frame``), tracked under the relative pose.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from typing import Any, TextIO

import yaml

from dualarm_control.drive_status import (
    ABSOLUTE_STATUS_NAME,
    REACHED,
    REJECTED,
    STALLED,
    STATUS_NAME,
    parse_status,
)
from dualarm_control.errors import DualArmError
from dualarm_control.robot import LEFT_TOOL
from dualarm_control.ros.convert import quaternion_xyzw
from dualarm_control.ros.graph import fq_topic, message_class
from dualarm_control.ros.node import tool_node

GOAL_TOPIC = "/relative_goal"
TWIST_TOPIC = "/relative_twist"
ABSOLUTE_GOAL_TOPIC = "/absolute_goal"
ABSOLUTE_TWIST_TOPIC = "/absolute_twist"
WORLD = "world"
KEEP_ALIVE_S = 0.1  # ros2 topic pub's default --keep-alive
EXIT_OK, EXIT_FAIL = 0, 1


class FieldError(DualArmError, ValueError):
    """A VALUES entry does not fit the message (unknown field, wrong type)."""


# ------------------------------------------------------------------------- YAML -> message


def _now_stamp(node: Any) -> Any:
    return node.get_clock().now().to_msg()


def set_message_fields(msg: Any, values: Mapping[str, Any], node: Any = None, path: str = "") -> None:
    """Fill ``msg`` from ``values`` (ros2cli's ``set_message_fields``, the part ``topic pub`` uses).

    Nested mappings fill nested messages; lists fill sequences and arrays (of messages too);
    ``header: auto`` sets ``stamp`` to now (``node``'s clock) and keeps the frame empty,
    ``stamp: now`` (a builtin_interfaces/Time field) sets now. Numbers are converted to the
    field's type (an int for a float field; a float for an int field only when integral).

    Raises:
        FieldError: an unknown field (naming the message's fields) or a value of the wrong type.
    """
    fields: dict[str, str] = msg.get_fields_and_field_types()
    for name, value in values.items():
        where = f"{path}{name}"
        if name not in fields:
            raise FieldError(f"'{where}' is not a field of {type(msg).__name__} (fields: {', '.join(fields)})")
        current = getattr(msg, name)
        if hasattr(current, "get_fields_and_field_types"):
            if value == "auto" and type(current).__name__ == "Header" and node is not None:
                current.stamp = _now_stamp(node)
            elif value == "now" and type(current).__name__ == "Time" and node is not None:
                setattr(msg, name, _now_stamp(node))
            elif isinstance(value, Mapping):
                set_message_fields(current, value, node, where + ".")
            else:
                raise FieldError(f"'{where}': expected a mapping of {type(current).__name__}'s fields, got {value!r}")
            continue
        setattr(msg, name, _converted(fields[name], current, value, where, node))


def _converted(type_name: str, current: Any, value: Any, where: str, node: Any) -> Any:
    """``value`` for a field of ROS type ``type_name`` (its current value ``current``)."""
    base = type_name.split("<")[1].rstrip(">") if type_name.startswith("sequence<") else type_name.split("[")[0]
    if isinstance(value, list):
        if "/" in base:  # sequence or array of messages
            element = type(current[0]) if len(current) else message_class(_msg_type(base))
            items = []
            for i, entry in enumerate(value):
                item = element()
                if not isinstance(entry, Mapping):
                    raise FieldError(f"'{where}[{i}]': expected a mapping of {element.__name__}'s fields")
                set_message_fields(item, entry, node, f"{where}[{i}].")
                items.append(item)
            return items
        return [_scalar(base, v, f"{where}[{i}]") for i, v in enumerate(value)]
    return _scalar(base, value, where)


def _msg_type(base: str) -> str:
    pkg, name = base.split("/")[0], base.split("/")[-1]
    return f"{pkg}/msg/{name}"


def _scalar(base: str, value: Any, where: str) -> Any:
    if base in ("float", "double"):
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise FieldError(f"'{where}': expected a number, got {value!r}")
        return float(value)
    if base == "boolean":
        if not isinstance(value, bool):
            raise FieldError(f"'{where}': expected true or false, got {value!r}")
        return value
    if base.startswith(("int", "uint")) or base in ("octet", "char"):
        if isinstance(value, float) and value.is_integer():
            value = int(value)
        if isinstance(value, bool) or not isinstance(value, int):
            raise FieldError(f"'{where}': expected an integer, got {value!r}")
        return value
    if base.startswith(("string", "wstring")):
        return str(value)
    raise FieldError(f"'{where}': cannot set a field of type {base} from {value!r}")


def parse_values(text: str) -> dict[str, Any]:
    """VALUES as a mapping (FieldError if the YAML is not one)."""
    try:
        data = yaml.safe_load(text) if text.strip() else {}
    except yaml.YAMLError as exc:
        raise FieldError(f"VALUES is not valid YAML: {' '.join(str(exc).split())}") from None
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise FieldError("the passed value needs to be a dictionary in YAML format")
    return data


# ------------------------------------------------------------------------- topic pub


def wait_for_subscriptions(pub: Any, executor: Any, stop: Any, count: int, max_wait: float | None,
                           out: TextIO) -> bool:
    """Wait until ``pub`` matches ``count`` subscriptions (False after ``max_wait`` s or a signal)."""
    start = time.monotonic()
    told = False
    while pub.get_subscription_count() < count:
        if not told:
            print(f"Waiting for at least {count} matching subscription(s)...", file=out)
            told = True
        if stop.signal is not None or (max_wait is not None and time.monotonic() - start >= max_wait):
            return False
        executor.spin_once(timeout_sec=0.1)
    return True


def topic_pub(topic: str, type_name: str, values: str = "{}", *, rate: float = 1.0, times: int = 0,
              wait_matching: int | None = None, max_wait: float | None = None,
              keep_alive: float = KEEP_ALIVE_S, out: TextIO = sys.stdout) -> int:
    """``ros2 topic pub``: publish ``type_name`` filled from YAML ``values`` on ``topic``.

    ``times`` 0: at ``rate`` Hz until Ctrl-C; otherwise that many messages. Waits for
    ``wait_matching`` subscriptions first (default 1 when ``times`` > 0, as ros2cli).
    Returns 0, or 1 when no subscription came within ``max_wait`` s.
    """
    cls = message_class(type_name)
    data = parse_values(values)
    wait = wait_matching if wait_matching is not None else int(times != 0)
    set_message_fields(cls(), data)  # a bad field fails before any waiting (ros2cli checks after)
    with tool_node("_dualarm_topic_pub") as (node, executor, stop):
        pub = node.create_publisher(cls, fq_topic(topic), 10)
        if not wait_for_subscriptions(pub, executor, stop, wait, max_wait, out):
            if stop.signal is None:
                print(f"Timed out waiting for subscribers: expected {wait}, got {pub.get_subscription_count()}",
                      file=sys.stderr)
                return EXIT_FAIL
            return EXIT_OK
        msg = cls()
        set_message_fields(msg, data, node)
        print("publisher: beginning loop", file=out)
        period, count, next_time = 1.0 / rate, 0, time.monotonic()
        while stop.signal is None and (times == 0 or count < times):
            set_message_fields(msg, data, node)  # refresh 'auto' / 'now' stamps
            pub.publish(msg)
            count += 1
            print(f"publishing #{count}: {msg!r}\n", file=out)
            out.flush()
            if times != 0 and count >= times:
                break
            next_time += period
            while stop.signal is None and time.monotonic() < next_time:
                executor.spin_once(timeout_sec=max(0.0, min(0.05, next_time - time.monotonic())))
        time.sleep(keep_alive)
    return EXIT_OK


# ------------------------------------------------------------------------- goal and jog


def goal_rotation(rpy: Sequence[float] | None, quat: Sequence[float] | None) -> Any:
    """The goal's rotation matrix from ``--rpy`` or ``--quat`` (identity if neither)."""
    import numpy as np

    from dualarm_control.drive_commands import (
        rotation_from_quaternion,
        rotation_from_rpy,
    )

    if quat is not None:
        return rotation_from_quaternion(quat)
    if rpy is not None:
        return rotation_from_rpy(rpy)
    return np.eye(3)


def pose_stamped(node: Any, xyz: Sequence[float], rotation: Any, frame: str = LEFT_TOOL) -> Any:
    """geometry_msgs/PoseStamped in ``frame`` (``left_tool``; ``world`` for an absolute goal) stamped now."""
    from geometry_msgs.msg import PoseStamped

    from dualarm_control.drive_commands import finite_vector

    msg = PoseStamped()
    msg.header.frame_id = frame
    msg.header.stamp = _now_stamp(node)
    p = finite_vector(xyz, 3, "--xyz")
    msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = (float(v) for v in p)
    x, y, z, w = quaternion_xyzw(rotation)
    msg.pose.orientation.x, msg.pose.orientation.y, msg.pose.orientation.z, msg.pose.orientation.w = x, y, z, w
    return msg


def _stamp_s(stamp: Any) -> float:
    return float(stamp.sec) + 1e-9 * float(stamp.nanosec)


def drive_status(msg: Any, name: str = STATUS_NAME) -> dict[str, str] | None:
    """The drive keys of the trajectory node's entry ``name`` in a DiagnosticArray (None if absent): the relative
    goals' (default), or the absolute frame's (:data:`~dualarm_control.drive_status.ABSOLUTE_STATUS_NAME`)."""
    for status in msg.status:
        if status.name == name:
            values = {kv.key: kv.value for kv in status.values}
            if parse_status(values) is not None:
                return values
    return None


def send_goal(xyz: Sequence[float], rpy: Sequence[float] | None = None, quat: Sequence[float] | None = None, *,
              wait: bool = False, timeout: float | None = None, subscriber_wait: float = 5.0,
              out: TextIO = sys.stdout, absolute: bool = False) -> int:
    """Publish one goal on ``/relative_goal`` (``absolute``: on ``/absolute_goal``, frame ``world``); with ``wait``,
    follow ``/diagnostics`` to the end (an absolute goal: the trajectory node's ``trajectory_node/absolute`` status).

    Exit codes: 0 published (without ``wait``) or reached; 1 no subscriber within
    ``subscriber_wait`` s, rejected, stalled, or ``timeout`` s passed.
    """
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import PoseStamped

    rotation = goal_rotation(rpy, quat)
    topic = ABSOLUTE_GOAL_TOPIC if absolute else GOAL_TOPIC
    name = ABSOLUTE_STATUS_NAME if absolute else STATUS_NAME
    updates: list[dict[str, str]] = []
    with tool_node("_dualarm_goal") as (node, executor, stop):
        pub = node.create_publisher(PoseStamped, topic, 10)
        if wait:
            node.create_subscription(DiagnosticArray, "/diagnostics",
                                     lambda m: updates.extend([v] if (v := drive_status(m, name)) else []), 10)
        if not wait_for_subscriptions(pub, executor, stop, 1, subscriber_wait, out):
            print(f"dualarm goal: nobody subscribes {topic} (start the cell with 'dualarm launch "
                  "interactive')", file=sys.stderr)
            return EXIT_FAIL
        msg = pose_stamped(node, xyz, rotation, WORLD if absolute else LEFT_TOOL)
        pub.publish(msg)
        stamp = _stamp_s(msg.header.stamp)
        print(f"{'absolute ' if absolute else ''}goal sent: xyz {list(xyz)} m, quat (x y z w) {[round(v, 6) for v in quaternion_xyzw(rotation)]}, "
              f"stamp {stamp:.9f}", file=out)
        if not wait:
            time.sleep(KEEP_ALIVE_S)
            return EXIT_OK
        return follow_goal(executor, stop, updates, stamp, timeout, out)


def follow_goal(executor: Any, stop: Any, updates: list[dict[str, str]], stamp: float, timeout: float | None,
                out: TextIO) -> int:
    """Print the goal's progress once a second (and each state change); the exit code."""
    start = time.monotonic()
    last_print, last_state = -math.inf, ""
    while stop.signal is None:
        executor.spin_once(timeout_sec=0.05)
        while updates:
            parsed = parse_status(updates.pop(0))
            assert parsed is not None
            progress, reason = parsed
            if progress.goal_stamp is None or abs(progress.goal_stamp - stamp) > 1e-6:
                continue  # another goal's status
            now = time.monotonic()
            if progress.state != last_state or now - last_print >= 1.0:
                print(f"{progress.state}: distance {progress.distance * 1000:.2f} mm, angle {progress.angle:.4f} rad, "
                      f"time to go {progress.time_to_go:.2f} s" + (f" ({reason})" if reason else ""), file=out)
                out.flush()
                last_print, last_state = now, progress.state
            if progress.state == REACHED:
                return EXIT_OK
            if progress.state in (REJECTED, STALLED):
                return EXIT_FAIL
        if timeout is not None and time.monotonic() - start > timeout:
            print(f"dualarm goal: not reached within {timeout:g} s", file=sys.stderr)
            return EXIT_FAIL
    return EXIT_FAIL


def jog(linear: Sequence[float], angular: Sequence[float], seconds: float, rate: float = 50.0, *,
        subscriber_wait: float = 5.0, out: TextIO = sys.stdout, absolute: bool = False) -> int:
    """Stream geometry_msgs/TwistStamped (``left_tool``) on ``/relative_twist`` for ``seconds`` at ``rate`` Hz
    (``absolute``: ``world`` on ``/absolute_twist``, the absolute frame's twist)."""
    from geometry_msgs.msg import TwistStamped

    from dualarm_control.drive_commands import finite_vector

    v = finite_vector(linear, 3, "--linear")
    w = finite_vector(angular, 3, "--angular")
    topic = ABSOLUTE_TWIST_TOPIC if absolute else TWIST_TOPIC
    with tool_node("_dualarm_jog") as (node, executor, stop):
        pub = node.create_publisher(TwistStamped, topic, 10)
        if not wait_for_subscriptions(pub, executor, stop, 1, subscriber_wait, out):
            print(f"dualarm jog: nobody subscribes {topic}", file=sys.stderr)
            return EXIT_FAIL
        msg = TwistStamped()
        msg.header.frame_id = WORLD if absolute else LEFT_TOOL
        msg.twist.linear.x, msg.twist.linear.y, msg.twist.linear.z = (float(x) for x in v)
        msg.twist.angular.x, msg.twist.angular.y, msg.twist.angular.z = (float(x) for x in w)
        start = time.monotonic()
        count = 0
        while stop.signal is None and time.monotonic() - start < seconds:
            msg.header.stamp = _now_stamp(node)
            pub.publish(msg)
            count += 1
            next_time = start + count / rate
            while stop.signal is None and time.monotonic() < next_time:
                executor.spin_once(timeout_sec=max(0.0, min(0.05, next_time - time.monotonic())))
        print(f"jog: {count} twists sent in {time.monotonic() - start:.2f} s", file=out)
        time.sleep(KEEP_ALIVE_S)
    return EXIT_OK


# ------------------------------------------------------------------------- argparse (one line each in cli.py)


def _positive(text: str) -> float:
    value = float(text)
    if not (math.isfinite(value) and value > 0.0):
        raise argparse.ArgumentTypeError(f"expected a number > 0, got {text}")
    return value


def _count(text: str) -> int:
    value = int(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected an integer >= 0, got {text}")
    return value


def _verb(run: Callable[[argparse.Namespace], int], interrupted: int = EXIT_OK) -> Callable[[argparse.Namespace], int]:
    """A verb's ``func``: ``run(args)``, or ``interrupted`` when Ctrl-C lands before the tool node's
    stop flag takes over (while rclpy starts). A refused command (CommandError) reaches ``dualarm``'s
    main: "dualarm VERB: error: ...", exit 2."""
    def func(args: argparse.Namespace) -> int:
        try:
            return run(args)
        except KeyboardInterrupt:
            return interrupted

    return func


def _topic_pub(args: argparse.Namespace) -> int:
    """``ros2 topic pub``."""
    return topic_pub(args.topic, args.message_type, args.values, rate=args.rate, times=1 if args.once else args.times,
                     wait_matching=args.wait_matching_subscriptions, max_wait=args.max_wait_time_secs,
                     keep_alive=args.keep_alive)


def add_topic_pub_parser(verbs: Any) -> None:
    """``dualarm topic pub`` under the ``topic`` verbs."""
    pub = verbs.add_parser("pub", help="publish a message from YAML (like ros2 topic pub)",
                           description="Publish TYPE on TOPIC filled from VALUES (YAML of the message's fields, "
                           "e.g. \"{header: {frame_id: left_tool}, pose: {position: {x: 0.1}}}\"; 'header: auto' "
                           "or 'stamp: now' stamp it now). At --rate Hz until Ctrl-C, or --once / -t N messages "
                           "after waiting for a matching subscription, as ros2 topic pub.")
    pub.add_argument("topic")
    pub.add_argument("message_type", metavar="TYPE", help="message type, e.g. geometry_msgs/msg/PoseStamped")
    pub.add_argument("values", nargs="?", default="{}", metavar="VALUES", help="YAML mapping (default: {})")
    pub.add_argument("-r", "--rate", type=_positive, default=1.0, metavar="HZ",
                     help="publishing rate (default: %(default)s Hz)")
    once = pub.add_mutually_exclusive_group()
    once.add_argument("-1", "--once", action="store_true", help="publish one message and exit")
    once.add_argument("-t", "--times", type=_count, default=0, metavar="N", help="publish N messages and exit")
    pub.add_argument("-w", "--wait-matching-subscriptions", type=_count, default=None, metavar="N",
                     help="wait for N matching subscriptions first (default: 1 with --once/--times, else 0)")
    pub.add_argument("--max-wait-time-secs", type=_positive, default=None, metavar="S",
                     help="give up waiting for subscriptions after S seconds (exit 1)")
    pub.add_argument("--keep-alive", type=float, default=KEEP_ALIVE_S, metavar="S",
                     help="stay alive S seconds after the last message (default: %(default)s)")
    pub.set_defaults(func=_verb(_topic_pub))


def add_drive_parsers(sub: Any) -> None:
    """``dualarm goal`` and ``dualarm jog``."""
    goal = sub.add_parser("goal", help="send a relative goal pose to the cell (/relative_goal)",
                          description="Publish geometry_msgs/PoseStamped (frame left_tool) on /relative_goal: the "
                          "right tool's pose in the left tool frame. With --wait, print the progress from "
                          "/diagnostics and exit 0 when reached, 1 when rejected, stalled or timed out.")
    goal.add_argument("--xyz", nargs=3, type=float, required=True, metavar=("X", "Y", "Z"), help="position [m]")
    rot = goal.add_mutually_exclusive_group()
    rot.add_argument("--rpy", nargs=3, type=float, metavar=("R", "P", "Y"), help="roll pitch yaw [rad] (default 0)")
    rot.add_argument("--quat", nargs=4, type=float, metavar=("X", "Y", "Z", "W"), help="quaternion")
    goal.add_argument("--wait", action="store_true", help="follow the goal until reached, rejected or stalled")
    goal.add_argument("--timeout", type=_positive, default=None, metavar="S", help="with --wait: give up after S s")
    goal.add_argument("--absolute", action="store_true", help="the absolute frame's pose in the world on "
                      "/absolute_goal (a scenario with absolute_frame: tracked under the relative pose)")
    goal.set_defaults(func=_verb(lambda a: send_goal(a.xyz, a.rpy, a.quat, wait=a.wait, timeout=a.timeout,
                                                     absolute=a.absolute), EXIT_FAIL))
    jg = sub.add_parser("jog", help="stream a relative twist to the cell (/relative_twist)",
                        description="Publish geometry_msgs/TwistStamped (frame left_tool) on /relative_twist at "
                        "--rate Hz for --seconds; the cell brakes to rest 0.1 s (jog_timeout) after the last one.")
    jg.add_argument("--linear", nargs=3, type=float, default=[0.0] * 3, metavar=("X", "Y", "Z"), help="m/s")
    jg.add_argument("--angular", nargs=3, type=float, default=[0.0] * 3, metavar=("X", "Y", "Z"), help="rad/s")
    jg.add_argument("--seconds", type=_positive, default=1.0, metavar="S", help="duration (default: %(default)s s)")
    jg.add_argument("--rate", type=_positive, default=50.0, metavar="HZ", help="twists per second (default: %(default)s)")
    jg.add_argument("--absolute", action="store_true", help="the absolute frame's twist (world axes) on "
                    "/absolute_twist")
    jg.set_defaults(func=_verb(lambda a: jog(a.linear, a.angular, a.seconds, a.rate, absolute=a.absolute)))
