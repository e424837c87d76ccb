"""``dualarm view`` on the running cell: subscribe, buffer, log to Rerun in batches.

Runs in its own process (never in a control node). Subscriptions are best effort (they match
reliable and best-effort publishers; a viewer may drop a sample rather than slow anyone
down) and read the CDR bytes with the nodes' own readers (:mod:`dualarm_control.ros.convert`);
``/diagnostics`` and the obstacles' MarkerArrays (the latched scene ``/dualarm/obstacles``, the moving
ones on ``/collision_objects``: :mod:`.obstacles_view`) are deserialized by rclpy (all through
:mod:`dualarm_control.ros.listen`). Every
``FLUSH_PERIOD_S`` the buffered samples go to Rerun through the parts of
:func:`.rerun_view.log_run` (one ``send_columns`` per joint and series: at 200 Hz one ``rr.log``
per joint and sample would not keep up). Time is the
joint-state stamp [s] since the first one seen; a command takes the stamp of the last joint
state (the one it answers), a controller status its ``stamp_ns``.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from dualarm_control.app.record.bag import CONTROLLER_STATUS, parse_float
from dualarm_control.app.view import rerun_view as rv
from dualarm_control.app.view.obstacles_view import (
    LIVE_TOPIC,
    SCENE_TOPIC,
    ObstacleTrack,
    add_markers,
    log_obstacles,
)
from dualarm_control.collision import CollisionModel
from dualarm_control.kinematics import DualArmModel
from dualarm_control.ros import convert
from dualarm_control.ros.listen import Topic, listen
from dualarm_control.ros.qos import latched_qos, stream_qos

FLUSH_PERIOD_S = 0.1
QUEUE_DEPTH = 1000
"""Samples kept per subscription while the view is busy logging (5 s of one topic at 200 Hz)."""
TOPICS = ("/joint_states", "/velocity_controller/commands", "/relative_target", "/diagnostics", SCENE_TOPIC, LIVE_TOPIC)


class LiveLog:
    """Buffers decoded samples of the cell's topics and logs them in batches to a recording."""

    def __init__(self, model: DualArmModel, recording: Any = None) -> None:
        self.model = model
        self.recording = recording
        self.collision = CollisionModel(model, allowed=model.description.collision_allowed)  # the closest pair
        self.t0: int | None = None
        self.last_state_ns: int | None = None
        self.states: list[tuple[float, np.ndarray]] = []
        self.commands: list[tuple[float, np.ndarray]] = []
        self.targets: list[tuple[float, np.ndarray]] = []
        self.cycles: list[tuple[float, dict[str, str]]] = []
        self.obstacles: dict[str, ObstacleTrack] = {}  # the obstacles' poses since the last flush, live ones' spans
        self.status: str | None = None
        self.counts = dict.fromkeys(TOPICS, 0)
        self.rejected = 0

    def seconds(self, ns: int) -> float:
        if self.t0 is None:
            self.t0 = ns
        return (ns - self.t0) * 1e-9

    def joint_state(self, value: tuple[int, tuple[np.ndarray, np.ndarray]]) -> None:
        stamp, vectors = value
        self.counts["/joint_states"] += 1
        self.last_state_ns = stamp
        self.states.append((self.seconds(stamp), vectors[0]))

    def malformed(self, text: str) -> None:
        """A sample that does not deserialize or that its decoder rejects (``text``: why): counted as rejected."""
        self.rejected += 1

    def command(self, value: np.ndarray) -> None:
        if self.last_state_ns is None:
            return
        self.counts["/velocity_controller/commands"] += 1
        self.commands.append((self.seconds(self.last_state_ns), value))

    def target(self, value: tuple[int, Any]) -> None:
        stamp, target = value
        self.counts["/relative_target"] += 1
        self.targets.append((self.seconds(stamp), np.array([*target.position, *convert.quaternion_xyzw(target.rotation)])))

    def diagnostics(self, msg: Any) -> None:
        for status in msg.status:
            if status.name != CONTROLLER_STATUS:
                continue
            values = {kv.key: kv.value for kv in status.values}
            if "stamp_ns" not in values or "status" not in values:
                continue  # the final "complete" status has no cycle
            self.counts["/diagnostics"] += 1
            self.cycles.append((self.seconds(int(values["stamp_ns"])), values))

    def scene(self, msg: Any) -> None:
        """The latched scene (still obstacles: one pose each)."""
        self.counts[SCENE_TOPIC] += 1
        add_markers(self.obstacles, msg, live=False)

    def markers(self, msg: Any) -> None:
        """Obstacles on the live topic (moving ones: a pose per message, on the joint states' clock)."""
        self.counts[LIVE_TOPIC] += 1
        add_markers(self.obstacles, msg, live=True, latest_ns=self.last_state_ns or 0)

    def flush(self, final: bool = False) -> None:
        """Log what arrived since the last flush (``final``: the last one, every obstacle's span ends too)."""
        rec = self.recording
        if self.obstacles:
            moving = [s for track in self.obstacles.values() for s in track.stamps if s >= 0]
            if moving and self.t0 is None:
                self.seconds(min(moving))
            seen = max([*moving, self.last_state_ns or 0])
            log_obstacles(self.obstacles, self.t0 or 0, rec, until_ns=None if final else seen)
            # a live obstacle's last span stays: a DELETE or its lifetime's end may come in a later batch
            self.obstacles = {name: track.trimmed() for name, track in self.obstacles.items()
                              if track.live and track.shown(seen)}
        if self.states:
            t, q = zip(*self.states, strict=True)
            rv.log_joints(self.model.urdf, np.array(t), np.array(q), self.model.joint_names, rec)
            rv.log_closest_pairs(np.array(t), rv.closest_pairs(self.model, np.array(q), self.collision), recording=rec)
        if self.commands:
            t, qd = zip(*self.commands, strict=True)
            rv.log_series(np.array(t), rv.velocity_norm_series(np.array(qd)), rec)
        if self.targets:
            t, poses = zip(*self.targets, strict=True)
            rv.log_frames(np.array(t), {"relative_target": np.array(poses)}, recording=rec)
        if self.cycles:
            t, values = zip(*self.cycles, strict=True)
            stamps = np.array(t)
            rv.log_series(stamps, {
                rv.TRACKING_POSITION: np.array([parse_float(v.get("position_error_m")) for v in values]),
                rv.TRACKING_ORIENTATION: np.array([parse_float(v.get("orientation_error_rad")) for v in values]),
                rv.SOLVE_TIME: np.array([parse_float(v.get("solve_time_s")) for v in values]),
                rv.CYCLE_TIME: np.array([parse_float(v.get("cycle_time_s")) for v in values]),
            }, rec)
            self.status = rv.log_statuses(stamps, [v["status"] for v in values], self.status, rec)
        self.states, self.commands, self.targets, self.cycles = [], [], [], []


def live_groups() -> list[str]:
    """The plot groups of the live view."""
    return rv.series_groups([rv.VELOCITY_L0, rv.TRACKING_POSITION, rv.SOLVE_TIME])


def run_live(model: DualArmModel, recording: Any, duration: float | None = None,
             report: Callable[[str], None] = print) -> int:
    """Subscribe to the cell and log until Ctrl-C/SIGTERM (or ``duration`` [s]); returns 0."""
    log = LiveLog(model, recording)
    rv.log_model(Path(model.urdf), recording)
    order = {name: i for i, name in enumerate(model.joint_names)}
    qos = stream_qos("best_effort", QUEUE_DEPTH)
    topics = {
        "/joint_states": Topic("sensor_msgs/msg/JointState", log.joint_state, qos,
                               decoder=convert.JointStateInput(order)),
        "/velocity_controller/commands": Topic("std_msgs/msg/Float64MultiArray", log.command, qos,
                                               decoder=convert.CommandInput(model.nq)),
        "/relative_target": Topic("trajectory_msgs/msg/MultiDOFJointTrajectory", log.target, qos,
                                  decoder=convert.TargetInput()),
        "/diagnostics": Topic("diagnostic_msgs/msg/DiagnosticArray", log.diagnostics, qos),
        SCENE_TOPIC: Topic("visualization_msgs/msg/MarkerArray", log.scene, latched_qos()),
        LIVE_TOPIC: Topic("visualization_msgs/msg/MarkerArray", log.markers, qos),
    }
    with listen("dualarm_view", topics, on_malformed=log.malformed) as listener:
        report(f"dualarm view: logging {', '.join(TOPICS)} (Ctrl-C to stop)")
        start = last = time.monotonic()
        while not listener.signalled and (duration is None or time.monotonic() - start < duration):
            listener.spin_once(FLUSH_PERIOD_S / 2)
            if time.monotonic() - last >= FLUSH_PERIOD_S:
                log.flush()
                last = time.monotonic()
        log.flush(final=True)
    counts = ", ".join(f"{topic} {n}" for topic, n in log.counts.items())
    report(f"dualarm view: logged {counts}; {log.rejected} samples rejected")
    return 0
