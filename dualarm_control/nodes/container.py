"""cell_container: sim_node, controller_node and trajectory_node in one process, on one executor.

As a ROS 2 component container with intra-process communication: the nodes are the same
nodes with the same names, parameters, topics and services, on one executor and one DDS
participant; the per-cycle samples between them (``/joint_states``, ``/wrench``,
``/velocity_controller/commands``, ``/relative_target``, ``/joint_reference``) go from node to
node in the process (:mod:`dualarm_control.ros.local_bus`) and are published on the wire as
well while a reader outside the process matches them, so every ROS 2 tool still reads every
topic. A sample published on those topics by another process is not heard by the container.
What it saves is measured in docs/bench.md ("One process").

Parameters per node: rcl's node-scoped form ``-p controller_node:solver:=daqp`` or a
``--params-file`` (keyed by node name, as for separate processes); an unscoped ``-p NAME:=VALUE``
reaches every node. One thread runs the three nodes, under the controller's ``thread_priority``.
Real time only: ``lockstep:=true`` is refused (the lockstep runs use separate processes). The
process ends when the scenario is complete (the trajectory node's end; the controller's in a task
scenario), on Ctrl-C or SIGTERM.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from typing import Any

from dualarm_control.errors import DualArmError
from dualarm_control.references.base import JOINT_REFERENCE, RELATIVE_TARGET, WRENCH
from dualarm_control.ros.local_bus import LocalBus
from dualarm_control.ros.node import run
from dualarm_control.ros.node_exit import exit_process
from dualarm_control.ros.priority import node_scheduling

NODE_TOPICS = {
    "sim_node": ("/joint_states", WRENCH),
    "controller_node": ("/velocity_controller/commands",),
    "trajectory_node": (RELATIVE_TARGET, JOINT_REFERENCE),
}
"""The topics each node publishes every cycle: local to the container when it runs the node."""
TICK_ORDER = ("trajectory_node", "sim_node", "controller_node")
USAGE = ("usage: cell_container [--nodes NAME,...] [--ros-args [-p [NODE:]NAME:=VALUE] [--params-file FILE] ...]\n"
         f"  --nodes: which of {', '.join(NODE_TOPICS)} run in the process (default: all three; a task "
         "scenario runs sim_node,controller_node)")


class Container:
    """The shells of ``names`` in one process, their local topics on one :class:`LocalBus`."""

    def __init__(self, context: Any, names: Sequence[str], priority_note: str = "disabled") -> None:
        from dualarm_control.nodes.controller_node import ControllerNode
        from dualarm_control.nodes.trajectory_node import TrajectoryNode
        from dualarm_sim.sim_node import SimNode

        makers = {"sim_node": SimNode, "controller_node": ControllerNode, "trajectory_node": TrajectoryNode}
        bus = LocalBus(topic for name in names for topic in NODE_TOPICS[name])
        self.shells: list[Any] = []
        for name in names:
            self.shells.append(makers[name](context, priority_note if name == "controller_node" else "disabled",
                                            bus=bus))
        if any(getattr(shell, "lockstep", False) for shell in self.shells):
            self.close()
            raise DualArmError("cell_container runs in real time: lockstep:=true needs the nodes in separate "
                                 "processes (dualarm launch --lockstep)")
        self.nodes = [shell.node for shell in self.shells]
        # One period: the target first, then the physics (its state delivers the controller's cycle at once,
        # with that target), then the controller's watchdog.
        order = [name for name in TICK_ORDER if name in names]
        self.ticks = [tick for name in order for tick in self.shells[list(names).index(name)].ticks]

    @property
    def finished(self) -> bool:
        return any(getattr(shell, "finished", False) for shell in self.shells)

    def close(self) -> None:
        for shell in self.shells:
            close = getattr(shell, "close", None)
            if close is not None:
                close()


def node_names(argv: Sequence[str]) -> list[str]:
    """The ``--nodes`` list before ``--ros-args`` (default: all three); ParameterError names a bad one."""
    head = list(argv[: argv.index("--ros-args")] if "--ros-args" in argv else argv)
    if "--nodes" not in head:
        return list(NODE_TOPICS)
    i = head.index("--nodes")
    names = [n for n in (head[i + 1] if i + 1 < len(head) else "").split(",") if n]
    bad = [n for n in names if n not in NODE_TOPICS] or ([] if names else ["(none)"])
    if bad:
        raise DualArmError(f"cell_container --nodes: unknown node {bad[0]!r}; valid: {', '.join(NODE_TOPICS)}")
    return names


def main(args: list[str] | None = None) -> int:
    argv = list(sys.argv if args is None else args)
    try:
        names = node_names(argv[1:])
    except DualArmError as exc:
        print(f"error: {exc}\n{USAGE}", file=sys.stderr)
        return 2
    from dualarm_control.nodes.controller_node import DEFAULT_PRIORITY

    request = node_scheduling(argv, DEFAULT_PRIORITY, "controller_node")
    help_text = (f"{USAGE}\n\n{(__doc__ or '').strip()}\n\nparameters: each node's own (sim_node --help, "
                 "controller_node --help, trajectory_node --help), given as -p NODE:NAME:=VALUE or in a params file")
    return run(lambda context: Container(context, names, request.note), argv, help_text, request.granted)


if __name__ == "__main__":
    exit_process(main())
