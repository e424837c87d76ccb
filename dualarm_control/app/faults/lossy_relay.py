"""A lossy relay: republish topics with best-effort QoS, dropping each message with a probability.

The fault matrix's stand-in for ``tc ... netem loss`` on kernels without netem: the nodes'
streams are remapped through this process (``FROM`` -> ``TO``, serialized bytes passed as
they are), which forwards a message with probability ``1 - loss`` (seeded, independent per
message). It runs until SIGINT/SIGTERM and prints, per topic, how many it forwarded and dropped.

    python -m dualarm_control.app.faults.lossy_relay --loss 0.1 FROM:TO:TYPE [FROM:TO:TYPE ...]
"""

from __future__ import annotations

import argparse
import random
import sys
from collections.abc import Callable, Sequence
from typing import Any

READY_LINE = "relay: ready"


def relay(routes: Sequence[tuple[str, str, str]], loss: float, seed: int) -> int:
    from dualarm_control.ros.graph import message_class
    from dualarm_control.ros.node import tool_node
    from dualarm_control.ros.qos import stream_qos

    rng = random.Random(seed)
    counts = {src: [0, 0] for src, _, _ in routes}  # forwarded, dropped
    qos = stream_qos("best_effort")
    with tool_node("_dualarm_lossy_relay") as (node, executor, stop):
        def forward(src: str, pub: Any) -> Callable[[bytes], None]:
            def on_message(data: bytes) -> None:
                if rng.random() < loss:
                    counts[src][1] += 1
                else:
                    counts[src][0] += 1
                    pub.publish(data)
            return on_message

        for src, dst, type_name in routes:
            cls = message_class(type_name)
            pub = node.create_publisher(cls, dst, qos)
            node.create_subscription(cls, src, forward(src, pub), qos, raw=True)
        print(READY_LINE, flush=True)
        while stop.signal is None:
            executor.spin_once(timeout_sec=0.1)
    for src, (sent, dropped) in counts.items():
        total = max(sent + dropped, 1)
        print(f"relay {src}: {sent} forwarded, {dropped} dropped ({dropped / total:.1%})", flush=True)
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="lossy_relay", description=__doc__.split("\n\n")[0] if __doc__ else "")
    parser.add_argument("--loss", type=float, required=True, help="drop probability per message, in [0, 1)")
    parser.add_argument("--seed", type=int, default=0, help="random seed (default: %(default)s)")
    parser.add_argument("routes", nargs="+", metavar="FROM:TO:TYPE", help="e.g. /raw/joint_states:/joint_states:"
                        "sensor_msgs/msg/JointState")
    args = parser.parse_args(argv)
    if not 0.0 <= args.loss < 1.0:
        parser.error(f"--loss {args.loss} must be in [0, 1)")
    routes = []
    for text in args.routes:
        parts = text.split(":")
        if len(parts) != 3:
            parser.error(f"route '{text}' is not FROM:TO:TYPE")
        routes.append((parts[0], parts[1], parts[2]))
    return relay(routes, args.loss, args.seed)


if __name__ == "__main__":
    sys.exit(main())
