"""Cost of the per-period messages: rclpy message objects against the CDR bytes of ros/cdr.py.

For each message a node sends or receives every control period, the time of the same work
done two ways in one process, one run: through rclpy's message objects (build the message and
publish it; deserialize it and read it) and through the CDR bytes the nodes use
(:mod:`dualarm_control.ros.cdr`, :mod:`dualarm_control.ros.convert`). Best of ``repeat``
batches of ``number`` calls (the machine is shared: the best batch is the least disturbed);
the ratio is the figure to compare. Publishers have one subscriber in the same process.
"""

from __future__ import annotations

import json
import timeit
from collections.abc import Callable, Sequence
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np

DIAGNOSTIC_VALUES = 26
"""As many values as the controller's per-cycle /diagnostics."""


def _best_us(call: Callable[[], object], number: int, repeat: int) -> float:
    call()
    return min(timeit.repeat(call, number=number, repeat=repeat)) / number * 1e6


def run_message_bench(number: int = 4000, repeat: int = 5) -> list[dict[str, Any]]:
    """Rows {message, rclpy_us, cdr_us, ratio}, measured in one process."""
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray
    from trajectory_msgs.msg import MultiDOFJointTrajectory

    from dualarm_control.kinematics import DualArmModel
    from dualarm_control.ros import convert
    from dualarm_control.ros.node import tool_node

    names = DualArmModel().joint_names
    order = {name: i for i, name in enumerate(names)}
    q = np.linspace(-1.0, 1.0, len(names))
    zero = np.zeros(3)
    sample = SimpleNamespace(position=np.array([0.1, 0.2, 0.3]), rotation=np.eye(3),
                             linear_velocity=np.array([0.1, 0.0, 0.0]), angular_velocity=zero,
                             linear_acceleration=zero, angular_acceleration=zero)
    values = {f"key_{i}": f"{i * 1.2345:.6e}" for i in range(DIAGNOSTIC_VALUES)}
    raw_state = convert.joint_state(names, 1, q, q)
    raw_target = convert.target_message(1, 0, sample)
    states, targets = convert.JointStateInput(order), convert.TargetInput(2.87)
    with tool_node("_dualarm_message_bench") as (node, _executor, _stop):
        kinds = {"diag": DiagnosticArray, "cmd": Float64MultiArray, "js": JointState}
        pubs = {k: node.create_publisher(t, f"/_dualarm_message_bench/{k}", 10) for k, t in kinds.items()}
        for k, t in kinds.items():
            node.create_subscription(t, f"/_dualarm_message_bench/{k}", lambda _m: None, 10, raw=True)

        def diagnostics_objects() -> None:
            status = DiagnosticStatus(level=b"\x00", name="controller_node", message="ok", hardware_id="dualarm_cell",
                                      values=[KeyValue(key=k, value=str(v)) for k, v in values.items()])
            pubs["diag"].publish(DiagnosticArray(header=convert.header(1), status=[status]))

        def joint_state_objects() -> None:
            pubs["js"].publish(JointState(header=convert.header(1), name=list(names), position=[float(v) for v in q],
                                          velocity=[float(v) for v in q], effort=[]))

        cases: list[tuple[str, Callable[[], object], Callable[[], object]]] = [
            ("/joint_states in (decode + checks)",
             lambda: states.from_message(deserialize_message(raw_state, JointState)),
             lambda: states.from_bytes(raw_state)),
            ("/relative_target in (decode + checks)",
             lambda: targets.from_message(deserialize_message(raw_target, MultiDOFJointTrajectory)),
             lambda: targets.from_bytes(raw_target)),
            (f"/diagnostics out, {DIAGNOSTIC_VALUES} values (build + publish)", diagnostics_objects,
             lambda: pubs["diag"].publish(convert.diagnostics(1, "controller_node", 0, "ok", values))),
            ("/velocity_controller/commands out",
             lambda: pubs["cmd"].publish(Float64MultiArray(data=[float(v) for v in q])),
             lambda: pubs["cmd"].publish(convert.float_array(q))),
            ("/joint_states out", joint_state_objects,
             lambda: pubs["js"].publish(convert.joint_state(names, 1, q, q))),
        ]
        rows = []
        for label, objects, cdr_bytes in cases:
            before, after = _best_us(objects, number, repeat), _best_us(cdr_bytes, number, repeat)
            rows.append({"message": label, "rclpy_us": before, "cdr_us": after, "ratio": after / before})
    return rows


def format_message_bench(rows: Sequence[dict[str, Any]]) -> str:
    lines = ["| message | rclpy objects [µs] | CDR bytes [µs] | ratio |", "|---|---|---|---|"]
    lines += [f"| {r['message']} | {r['rclpy_us']:.1f} | {r['cdr_us']:.1f} | {r['ratio']:.2f} |" for r in rows]
    return "\n".join(lines)


def write_message_bench(out: Path, rows: Sequence[dict[str, Any]]) -> None:
    out.mkdir(parents=True, exist_ok=True)
    (out / "messages.json").write_text(json.dumps(list(rows), indent=2) + "\n")
    (out / "messages.md").write_text(f"# Per-period message cost\n\n{format_message_bench(rows)}\n")
