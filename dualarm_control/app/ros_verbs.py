"""The ros2-like verbs of the ``dualarm`` command on rclpy: ``bag`` (record, info, cell), ``topic``
(list, echo, hz, info, pub) and ``param`` (list, get, describe, set): their parsers and commands."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def cmd_bag_record(args: argparse.Namespace) -> int:
    """Record topics to a rosbag2 directory (MCAP, version 9) until Ctrl-C/SIGTERM or --duration."""
    from dualarm_control.ros.recorder import default_bag_path, record

    path = Path(args.output) if args.output else default_bag_path()
    return record(path, args.topics, record_all=args.all, duration=args.duration, use_sim_time=args.use_sim_time,
                  after_data=args.after_data, compute_tf=not args.no_tf, after_matched=args.after_matched)


def cmd_bag_info(args: argparse.Namespace) -> int:
    """Print a ``ros2 bag info``-style summary."""
    from dualarm_control.app.record.bag import bag_info, format_notes

    print(bag_info(Path(args.bag)))
    notes = format_notes(Path(args.bag))
    if notes:
        print(notes)
    return 0


def cmd_bag_cell(args: argparse.Namespace) -> int:
    """Print the bag's /dualarm/cell parameters as one parameter file."""
    from dualarm_control.app.record.bag import read_cell
    from dualarm_control.params import params_document

    cell = read_cell(Path(args.bag))
    unknown = [n for n in args.node if n not in cell]
    if unknown:
        print(f"error: no node {unknown[0]!r} on /dualarm/cell of {args.bag} (nodes: {', '.join(cell) or 'none'})",
              file=sys.stderr)
        return 2
    if not cell:
        print(f"{args.bag}: no /dualarm/cell message (recorded before issue 40, or without the topic)", file=sys.stderr)
        return 1
    print("".join(params_document(node, cell[node]) for node in (args.node or cell)), end="")
    return 0


def cmd_topic_list(args: argparse.Namespace) -> int:
    """``ros2 topic list``."""
    from dualarm_control.ros.graph import format_topic_list, list_topics

    text = format_topic_list(list_topics(args.spin_time), args.show_types)
    if text:
        print(text)
    return 0


def cmd_topic_echo(args: argparse.Namespace) -> int:
    """``ros2 topic echo``."""
    from dualarm_control.ros.graph import echo

    count = 1 if args.once else args.count
    try:
        return echo(args.topic, count=count, timeout=args.timeout, spin_time=args.spin_time)
    except KeyboardInterrupt:
        return 0


def cmd_topic_hz(args: argparse.Namespace) -> int:
    """``ros2 topic hz``."""
    from dualarm_control.ros.graph import hz

    try:
        return hz(args.topic, window=args.window, duration=args.duration, spin_time=args.spin_time)
    except KeyboardInterrupt:
        return 0


def cmd_topic_info(args: argparse.Namespace) -> int:
    """``ros2 topic info``."""
    from dualarm_control.ros.graph import format_topic_info, topic_info

    info = topic_info(args.topic, args.spin_time)
    if info.publishers == 0 and info.subscriptions == 0:
        print(f"Unknown topic '{info.name}'", file=sys.stderr)
        return 1
    print(format_topic_info(info))
    return 0


def add_bag_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    bag = sub.add_parser("bag", help="record and inspect rosbag2 bags (like ros2 bag)",
                         description="rosbag2 bags as ROS 2 Jazzy writes them (MCAP storage, metadata version 9).")
    verbs = bag.add_subparsers(dest="bag_verb", metavar="BAG_VERB")
    verbs.required = True
    rec = verbs.add_parser("record", help="record topics until Ctrl-C, SIGTERM or --duration",
                           description="Subscribe raw (serialized CDR, QoS adapted to the publishers, keep-last "
                           "1000) and write a rosbag2 directory as Jazzy does (DIR/DIR_0.mcap, metadata version 9 "
                           "with offered QoS and type hashes from the graph). Prints 'bag: ready' on stdout once the "
                           "named topics are subscribed; progress on stderr; the bag is closed cleanly on "
                           "Ctrl-C/SIGTERM with every message received.")
    rec.add_argument("-o", "--output", metavar="DIR", help="bag directory (default: rosbag2_YYYY_MM_DD-HH_MM_SS)")
    rec.add_argument("topics", nargs="*", default=[], metavar="TOPIC",
                     help="topics to record (subscribed once all have a publisher)")
    rec.add_argument("-a", "--all", action="store_true",
                     help="every topic discovery finds, as they appear (not /rosout, /parameter_events)")
    rec.add_argument("--use-sim-time", action="store_true",
                     help="stamp messages with /clock (simulation time), as rosbag2 does with use_sim_time")
    rec.add_argument("-d", "--duration", type=float, metavar="S", help="stop after S seconds")
    rec.add_argument("--after-data", action="append", default=[], metavar="TOPIC",
                     help="subscribe this named topic only once every other named topic has delivered a message "
                     "(repeatable): a node that waits for a reader on TOPIC then starts with the others recorded")
    rec.add_argument("--after-matched", action="append", default=[], metavar="TOPIC",
                     help="subscribe this named topic only once every other named topic's reader has matched all "
                     "of its publishers (repeatable): a lockstep simulator that waits for a reader on TOPIC then "
                     "starts with the others' readers matched (dualarm launch --lockstep gives /joint_states)")
    rec.add_argument("--no-tf", action="store_true",
                     help="do not write /tf and /tf_static computed from /joint_states (by default they are, "
                     "when no node publishes /tf: one transform per URDF joint, as robot_state_publisher)")
    rec.set_defaults(func=cmd_bag_record)
    info = verbs.add_parser("info", help="summary of a bag (like ros2 bag info)")
    info.add_argument("bag", help="rosbag2 directory")
    info.set_defaults(func=cmd_bag_info)
    cell = verbs.add_parser("cell", help="the parameters each node ran with (/dualarm/cell), as a parameter file",
                            description="Print what the bag's /dualarm/cell holds: each node's parameters at its "
                            "start (robot, hardware profile, scenario, solver, limits) as one ROS 2 parameter file "
                            "(YAML); give it back to the nodes with --params-file to run the same cell again. Exit 1 "
                            "when the bag holds none (recorded before issue 40, or without the topic).")
    cell.add_argument("bag", help="rosbag2 directory")
    cell.add_argument("--node", action="append", default=[], metavar="NAME",
                      help="only this node's section (repeatable; default: every node)")
    cell.set_defaults(func=cmd_bag_cell)


def add_topic_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    topic = sub.add_parser("topic", help="inspect topics (like ros2 topic)",
                           description="Graph tools on rclpy (any installed message type); localhost discovery "
                           "unless ROS_AUTOMATIC_DISCOVERY_RANGE / ROS_STATIC_PEERS / a DDS profile is set.")
    verbs = topic.add_subparsers(dest="topic_verb", metavar="TOPIC_VERB")
    verbs.required = True
    from dualarm_control.ros.graph import DEFAULT_SPIN_TIME
    from dualarm_control.ros.node import DISCOVERY_TIMEOUT_S

    def add_spin_time(verb: argparse.ArgumentParser) -> None:
        verb.add_argument("--spin-time", type=float, default=DISCOVERY_TIMEOUT_S, metavar="S",
                          help="wait up to S s for the topic's discovery; answers as soon as it is found "
                          "(default: %(default)s)")

    lst = verbs.add_parser("list", help="topics with publishers or subscriptions")
    lst.add_argument("-t", "--show-types", action="store_true", help="also print each topic's type")
    lst.add_argument("--spin-time", type=float, default=DEFAULT_SPIN_TIME, metavar="S",
                     help="collect what discovery finds for S s (default: %(default)s)")
    lst.set_defaults(func=cmd_topic_list)
    ech = verbs.add_parser("echo", help="print messages as YAML")
    ech.add_argument("topic")
    ech.add_argument("--once", action="store_true", help="print one message and exit")
    ech.add_argument("-n", "--count", type=int, metavar="N", help="print N messages and exit")
    ech.add_argument("--timeout", type=float, metavar="S", help="exit 1 if no message comes for S seconds")
    add_spin_time(ech)
    ech.set_defaults(func=cmd_topic_echo)
    hz_ = verbs.add_parser("hz", help="print the publishing rate")
    hz_.add_argument("topic")
    hz_.add_argument("-w", "--window", type=int, default=10_000, metavar="N",
                     help="messages in the rate window (default: %(default)s)")
    hz_.add_argument("--duration", type=float, metavar="S", help="stop after S seconds")
    add_spin_time(hz_)
    hz_.set_defaults(func=cmd_topic_hz)
    inf = verbs.add_parser("info", help="type and endpoint counts")
    inf.add_argument("topic")
    add_spin_time(inf)
    inf.set_defaults(func=cmd_topic_info)
    from dualarm_control.ros.drive import add_topic_pub_parser

    add_topic_pub_parser(verbs)


def cmd_param(args: argparse.Namespace) -> int:
    """``ros2 param list|get|set|describe`` on a running node."""
    from dualarm_control.ros import params_client as pc

    node = args.node if args.node.startswith("/") else "/" + args.node
    if args.param_verb == "list":
        print("\n".join(f"  {name}" for name in pc.list_parameters(node, args.timeout)))
    elif args.param_verb == "get":
        value = pc.get_parameter(node, args.name, args.timeout)
        kind = {bool: "Boolean", int: "Integer", float: "Double", str: "String"}.get(type(value), "Value")
        print(f"{kind} value is: {value}")
    elif args.param_verb == "describe":
        print(pc.describe_parameter(node, args.name, args.timeout))
    else:
        print(pc.set_parameter(node, args.name, pc.yaml_value(args.value), args.timeout))
    return 0


def add_param_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    par = sub.add_parser("param", help="parameters of a running node (like ros2 param)",
                         description="List, get, describe or set a running node's parameters through its "
                         "parameter services. A refused 'set' (e.g. solver:=nope) exits 2 with the node's reason; "
                         "the controller applies accepted changes at the next cycle boundary.")
    verbs = par.add_subparsers(dest="param_verb", metavar="PARAM_VERB")
    verbs.required = True
    from dualarm_control.ros.node import DISCOVERY_TIMEOUT_S

    for verb, helptext in (("list", "parameter names"), ("get", "a parameter's value"),
                           ("describe", "type, description, constraints"),
                           ("set", "set a parameter (value read as YAML: 10.0 double, 10 integer)")):
        v = verbs.add_parser(verb, help=helptext)
        v.add_argument("node", help="node name, e.g. /controller_node")
        for name in {"list": (), "set": ("name", "value")}.get(verb, ("name",)):
            v.add_argument(name)
        v.add_argument("--timeout", type=float, default=DISCOVERY_TIMEOUT_S, metavar="S",
                       help="wait up to S s for the node's parameter services, and as long for its answer "
                       "(default: %(default)s)")
    par.set_defaults(func=cmd_param)
