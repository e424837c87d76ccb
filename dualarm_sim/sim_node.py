"""sim_node: the pybullet cell as a velocity-controlled robot (FRI / ros2_control stand-in).

Publishes ``/joint_states`` every control period (and, with a scenario's held object, the wrist F/T sensors'
``/left/wrench`` and ``/right/wrench``, geometry_msgs/WrenchStamped in each tool frame, as an F/T driver does:
:mod:`dualarm_sim.held_object`), and ``/wrench`` and ``/clock`` (simulation
time, steps x period) every period while a subscription reads them (lazy, as image pipelines
publish); applies
``/velocity_controller/commands`` (Float64MultiArray, 14 values, controller joint order). Those are the
default hardware profile's topics: with ``hardware.*`` (docs/hardware.md) it takes the profile's command
outputs (topics, message types of the output registry (docs/outputs.md), velocity or position interfaces) and publishes its joint-state topics
as joint_state_broadcaster does (``state_order``, ``extra_joints``, a topic per namespace).
A command older than ``command_timeout`` (simulation time, counted in steps, as a robot's
own cycle counts it) brings the arms to rest, in both modes. A malformed command (bad CDR,
wrong length, NaN/inf) is rejected (throttled log, WARN on ``/diagnostics``, counted) and the
last valid one kept, so the timeout still applies. Once a second a ``sim_node`` status on
``/diagnostics`` counts the steps, the commands received and rejected, and the command
timeouts (WARN while the arms are held at rest by the timeout), and in a task scenario the
table contact points summed over the steps (``table_contacts``).

Contacts between the robot's links (issue 27; :mod:`dualarm_sim.contacts`): the cell collides the
link pairs of the controller's collision model (:meth:`~dualarm_sim.cell.CellConfig.for_robot`; a
task scenario's ``contact_links`` are allowed: they touch on purpose). After every step the pairs
in contact are counted, once per step each; a log line (WARN) names a pair and its penetration
depth when it comes into contact, another (INFO) when it separates; the status carries
``contacts`` (contact-steps summed over the pairs), ``contact_pairs`` (``link_a-link_b:steps``,
comma-separated), ``deepest_contact_m`` (the deepest penetration so far [m]) and ``in_contact``
(the pairs in contact at the last step; WARN, "links in contact: ...", while > 0).

A task scenario (pan_cleaning) loads its cell URDF (pan and brush) and its table; with
``force:=true`` its ``contact_links`` (pan and brush) make real contact, as in the in-process
runner (the pan's modelling error is the controller's, not the simulator's), and
``/contact_force`` (geometry_msgs/Vector3Stamped, ``vector.z`` = pybullet's normal contact
force brush-pan [N], stamped like the joint state after the step) gives the physics' ground
truth for the report's force metrics.

``/robot_description`` (std_msgs/String, keep-last 1, reliable, transient local, as
robot_state_publisher offers it) carries the text of the URDF the cell loaded, published once.

Real-time mode: a drift-free tick of the spin loop (``ros.node.Ticker``) steps the physics one
control period per tick, stamps are the wall clock. Lockstep mode (``lockstep:=true``): the state of step k (stamped with
sim time k*T) is published, and the physics advances only when the command for it arrives;
the first state is sent once ``lockstep_subscribers`` readers of /joint_states are matched.
"""

from __future__ import annotations

import functools
import sys
import time
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, Vector3Stamped, WrenchStamped
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from dualarm_control.cell_robot import node_scenario
from dualarm_control.errors import InputRejected
from dualarm_control.hardware import HARDWARE_PARAMETERS, profile_from_values
from dualarm_control.params import ParamSpec, non_negative, positive
from dualarm_control.references.base import HELD_OBJECT_POSE, LEFT_WRENCH, RIGHT_WRENCH
from dualarm_control.robot import LEFT_TOOL, RIGHT_TOOL
from dualarm_control.ros import convert
from dualarm_control.ros.cell_topic import CellPublisher
from dualarm_control.ros.hardware_io import declare_with_profile
from dualarm_control.ros.inputs import Throttle, subscribe_checked
from dualarm_control.ros.local_bus import (
    LocalBus,
    local_publisher,
    publish_if_subscribed,
)
from dualarm_control.ros.node import Tick, run, usage
from dualarm_control.ros.node_exit import exit_process
from dualarm_control.ros.obstacle_markers import ObstacleTopics
from dualarm_control.ros.priority import (
    log_priority,
    node_scheduling,
    thread_priority_spec,
)
from dualarm_control.ros.qos import (
    QOS_PARAMETER,
    latched_qos,
    publisher_depth,
    stream_qos,
)
from dualarm_control.scenario import ROBOT_PARAMETER, scenario_names
from dualarm_sim.cell import DualArmCell
from dualarm_sim.cell_config import CellConfig
from dualarm_sim.contacts import ContactCounter
from dualarm_sim.moving import MovingBodies
from dualarm_sim.ports import STATE_ORDERS, CommandMerger, state_layout
from dualarm_sim.samples import JointSample

PARAMETERS = (
    ParamSpec("scenario", "assembly", "scenario name or YAML path (initial configuration)", read_only=True),
    ROBOT_PARAMETER,
    ParamSpec("force", False, "task scenario: its contact_links touch (the force variant of pan_cleaning)",
              read_only=True),
    ParamSpec("control_period", 0.005, "control period [s]", check=positive, read_only=True),
    ParamSpec("physics_rate_hz", 1000.0, "physics rate [Hz] (>= 1000)", check=positive, read_only=True),
    ParamSpec("command_timeout", 0.05, "command age that brings the arms to rest [s]", check=positive),
    ParamSpec("lockstep", False, "advance one period per received command", read_only=True),
    ParamSpec("plan", "", "plan.json of `dualarm plan`: start at its first configuration", read_only=True),
    ParamSpec("collisions", True, "link contacts between the collision model's pairs (false: links pass through "
              "each other)", read_only=True),
    thread_priority_spec(50, "the physics loop"),
    ParamSpec("lockstep_subscribers", 2, "joint_states readers to wait for before the first lockstep state",
              check=non_negative),
    ParamSpec("lockstep_resend", 0.5, "re-publish the pending state after this long without a command [s] "
              "(before the first step: a discovery race; with best_effort streams: a lost sample)", check=positive),
    ParamSpec("lockstep_start_delay", 0.5, "wait after the joint_states readers matched, so that their other "
              "subscriptions (a recorder's /clock, /wrench) match too [s]", check=non_negative, read_only=True),
    QOS_PARAMETER,
    *HARDWARE_PARAMETERS,
    ParamSpec("state_order", STATE_ORDERS[0], "order of the joints on the joint-state topics (joint_state_broadcaster: "
              "the hardware's own)", choices=lambda: list(STATE_ORDERS), read_only=True),
    ParamSpec("extra_joints", [""], "joints the hardware has beyond the robot's (a gripper): on every joint-state "
              "topic, at 0", read_only=True),
)
STATUS_PERIOD_S = 1.0

DEFAULT_PRIORITY = 50


def plan_start(path: str, joint_names: list[str]) -> np.ndarray:
    """First planned configuration of a plan.json [rad], (n,)."""
    from dualarm_control.planning.plan_file import read_plan

    return read_plan(path, joint_names).configurations[0]


FIRST_COMMAND = "first command received"
"""Logged once, at the first command: after a restart, when the controller's commands reach this simulator again
(the fault matrix's kill_sim row waits for it)."""
UNHEARD = "no command received"
"""Logged (WARN, once a status period) while commands are published on a command topic and none has arrived:
after a restart, the controller's writer may be matched to this simulator's reader seconds later than the other
way round (DDS discovery), and its commands are lost meanwhile."""
UNHEARD_AFTER_S = 2.0
"""Seconds (wall clock) with a publisher on a command topic and no command, before :data:`UNHEARD`."""

class SimNode:
    """Node shell around :class:`DualArmCell`."""

    def __init__(self, context: Any, priority_note: str = "disabled", bus: LocalBus | None = None) -> None:
        self.node = Node("sim_node", context=context)
        p = declare_with_profile(self.node, PARAMETERS)
        scenario, robot_note = node_scenario(p, "sim_node")
        tasks = scenario.tasks  # a task scenario: its cell (pan and brush), table and contact pair
        held = tasks.held if tasks is not None else None  # or its held object and wrist sensors
        pan = tasks is not None and held is None  # a task scenario's contact links: those of pan cleaning
        robot = scenario.robot
        self.cell = DualArmCell(
            CellConfig.for_robot(robot, allowed=scenario.robot_pairs_allowed + ((tasks.contact_links,) if pan and tasks is not None else ()),
                                 collisions=p["collisions"],
                                 control_period=p["control_period"],
                                 physics_rate_hz=p["physics_rate_hz"], command_timeout=p["command_timeout"],
                                 table_height=tasks.cell_table if tasks is not None else None,
                                 obstacles=scenario.obstacles,
                                 contact_pairs=(tasks.contact_links,) if pan and tasks is not None and p["force"] else (),
                                 **(held.cell() if held is not None else {})),
            initial_positions=plan_start(p["plan"], robot.joint_names) if p["plan"] else scenario.initial_positions,
        )
        # a held object: the hands close grasp_time after the controller's first motion command (its task's start)
        self.cell.count_grasp_from_motion()
        # joint states as joint_state_broadcaster gives them: the arms' joints, the held (locked) ones, the extra ones
        profile = profile_from_values(p, robot.joint_names, "sim_node")
        self.extra = [j for j in p["extra_joints"] if j]
        self.layout = state_layout(profile, self.cell.joint_names, self.cell.held_names, self.extra, p["state_order"])
        self.merger = CommandMerger(profile, self.cell.joint_names, p["control_period"])
        self.holds = bool(self.merger.position_mask.any())
        self.table = tasks is not None
        self.contact = tasks.contact_links if pan and tasks is not None and p["force"] else None
        self.table_contacts = 0  # contact points with the table, summed over steps (as the in-process runner)
        self.contacts = ContactCounter()  # contact-steps per link pair of the robot (module docstring)
        self.period_ns = round(p["control_period"] * 1e9)
        self.lockstep = bool(p["lockstep"])
        self.wait_for = int(p["lockstep_subscribers"])
        self.resend_s = float(p["lockstep_resend"])
        self.best_effort = p["qos_reliability"] == "best_effort"
        self.start_delay = float(p["lockstep_start_delay"])
        self.readers_matched_at: float | None = None
        n = self.node
        qos = stream_qos(p["qos_reliability"])
        depth = publisher_depth(self.lockstep)
        self.pub_js = [local_publisher(bus, n.create_publisher(JointState, s.topic, stream_qos(
            p["qos_reliability"], depth)), s.topic) for s in self.layout]
        self.pub_wrench = local_publisher(bus, n.create_publisher(WrenchStamped, "/wrench", depth), "/wrench")
        self.pub_wrists = [local_publisher(bus, n.create_publisher(WrenchStamped, topic, depth), topic)
                           for topic in (LEFT_WRENCH, RIGHT_WRENCH)] if self.cell.held_object is not None else []
        self.wrists = self.cell.wrist_wrenches() if self.pub_wrists else None  # read once per step (noise)
        self.pub_object = local_publisher(bus, n.create_publisher(PoseStamped, HELD_OBJECT_POSE, depth),
                                          HELD_OBJECT_POSE) if self.cell.held_object is not None else None
        self.pub_clock = n.create_publisher(Clock, "/clock", depth)
        self.pub_diag = n.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.pub_description = n.create_publisher(String, "/robot_description", latched_qos())
        self.pub_description.publish(String(data=robot.urdf_xml))
        self.pub_contact = (n.create_publisher(Vector3Stamped, "/contact_force", depth) if self.contact is not None
                            else None)
        self.command_topics = [o.topic for o in profile.outputs]
        self.publishers_seen: float | None = None  # monotonic s since a command topic has had a publisher
        for o in profile.outputs:  # each output's registered message type (dualarm_control.outputs)
            decoder = self.merger.decoders[o.name]
            subscribe_checked(n, decoder.kind.message_class(), o.topic, functools.partial(self.on_command, o.name),
                              qos, self.reject, decoder, bus, self.on_rejected_command)
        self.log = n.get_logger()
        self.log.info(robot_note)
        self.throttle = Throttle(1.0)
        self.steps = 0
        self.stepped: JointSample | None = None  # the state the last step returned, until published
        self.started = False
        self.last_publish = 0.0
        self.rejected = self.received = self.timeouts = 0
        self.command_ns = 0  # the last accepted command's arrival, in the states' stamp clock [ns] (0: none yet)
        self.timed_out = False
        n.create_timer(STATUS_PERIOD_S, self.publish_status)
        self.ticks: list[Tick] = []  # real time: the physics tick (ros.node.Ticker, not an rclpy timer)
        if self.lockstep:
            n.create_timer(0.05, self.lockstep_watchdog)
        else:
            self.ticks.append((p["control_period"], self.on_tick))
        self.log.info(f"scenario '{scenario.name}' on robot '{robot.name}' ({robot.nq} joints), "
                      f"{'lockstep' if self.lockstep else 'real-time'} at "
                      f"{1.0 / p['control_period']:.0f} Hz, physics {p['physics_rate_hz']:.0f} Hz "
                      f"(known scenarios: {', '.join(scenario_names())})")
        log_priority(self.log, priority_note, p["thread_priority"])
        self.cell_topic = CellPublisher(n)  # /dualarm/cell: what this run runs with, latched (for its bag)
        self.period_s = float(p["control_period"])
        self.moving = MovingBodies(scenario.moving_obstacles, self.cell.client_id)  # a hand: moved every step
        self.moving_topic = ObstacleTopics(n, (), scenario.moving_obstacles, scene=False, live=True)

    def close(self) -> None:
        self.log.info(f"stopping after {self.steps} steps ({self.steps * self.period_ns / 1e9:.3f} s sim time), "
                      f"{self.received} commands received, {self.rejected} rejected, {self.timeouts} command timeouts, "
                      f"{self.contacts.total} contact-steps" + (f" ({self.contacts.pairs_text()}, deepest "
                                                                f"{self.contacts.deepest * 1e3:.1f} mm)"
                                                                if self.contacts.total else ""))
        self.cell.close()

    def _stamp_ns(self) -> int:
        return self.steps * self.period_ns if self.lockstep else time.time_ns()

    def publish_state(self) -> None:
        sample, self.stepped = self.stepped or self.cell.state(), None  # the step's own state, else a read
        ns = self._stamp_ns()
        publish_if_subscribed(self.pub_clock, lambda: convert.clock(self.steps * self.period_ns))
        self.moving_topic.publish_moving(self.steps * self.period_s, ns)  # where the hand is at this state
        positions, velocities = sample.positions, sample.velocities
        if self.cell.held_names or self.extra:
            held_q, held_qd = self.cell.held_state()
            zeros = np.zeros(len(self.extra))
            positions = np.concatenate((positions, held_q, zeros))
            velocities = np.concatenate((velocities, held_qd, zeros))
        for pub, state in zip(self.pub_js, self.layout):
            pub.publish(convert.joint_state(state.names, ns, positions[state.indices], velocities[state.indices]))
        publish_if_subscribed(self.pub_wrench, lambda: convert.wrench_stamped(ns, self.cell.wrench()))
        if self.wrists is not None:
            wrists = self.wrists
            for pub, frame, reading in zip(self.pub_wrists, (LEFT_TOOL, RIGHT_TOOL), wrists, strict=True):
                pub.publish(convert.wrench_stamped(ns, reading, frame))
        held = self.cell.held_object
        if self.pub_object is not None and held is not None:  # the box where it is at this state (a carry's slip)
            publish_if_subscribed(self.pub_object, lambda: convert.world_pose_stamped(ns, held.pose_vector()))
        if self.pub_contact is not None and self.contact is not None:
            contact = self.contact
            publish_if_subscribed(self.pub_contact, lambda: convert.contact_force(ns, self.cell.contact_force(*contact)))
        self.last_publish = time.monotonic()

    def reject(self, reason: str) -> None:
        """A rejected command: counted, WARN on /diagnostics, throttled log; the last valid command is kept."""
        self.rejected += 1
        line = self.throttle.text(reason)
        if line is not None:
            self.log.warning(line)
        self.pub_diag.publish(convert.diagnostics(self._stamp_ns(), "sim_node", 1, reason,
                                                  {"status": "input_rejected", "rejected_inputs": self.rejected}))

    def on_rejected_command(self, exc: InputRejected) -> None:
        """A command its output's decoder rejected (count, NaN/inf, joints): received, then rejected."""
        self.received += 1
        self.reject(exc.reason)

    def on_command(self, output: str, data: np.ndarray) -> None:
        """A command of one output of the profile; lockstep: the step runs once every output's has arrived."""
        self.received += 1
        self.command_ns = self._stamp_ns()
        if self.received == 1:  # the command path works (a restarted simulator waits for the controller's writer)
            self.log.info(f"{FIRST_COMMAND} ({output})")
        self.merger.put(output, data, self.cell.reference)
        if self.lockstep and not self.merger.complete:
            return
        report = self.cell.apply_command(self.merger.take())
        if report.clipped:
            line = self.throttle.text(f"command: {report.reason}")
            if line is not None:
                self.log.warning(line)
        if self.lockstep and self.started:
            self.step()
            self.publish_state()

    def on_tick(self) -> None:
        self.step()
        self.publish_state()

    def step(self) -> None:
        """One period of physics; a command older than ``command_timeout`` is replaced by rest (cell)."""
        timed_out = self.cell.timed_out
        if timed_out and not self.timed_out:
            self.timeouts += 1
            self.log.warning(f"no command for more than {self.cell.config.command_timeout:g} s (sim time): "
                             "arms brought to rest")
        elif self.timed_out and not timed_out:
            self.log.info("commands resumed")
        changed, self.timed_out = timed_out != self.timed_out, timed_out
        if changed:  # the status says so at once, not up to STATUS_PERIOD_S later
            self.publish_status()
        self.moving.place(self.steps * self.period_s)
        self.stepped = self.cell.step()
        if self.wrists is not None:
            self.wrists = self.cell.wrist_wrenches()
        if self.holds:  # a position command moves its joints once, then they hold it
            self.cell.hold(self.merger.position_mask)
        self.steps += 1
        if self.table:
            self.table_contacts += self.cell.table_contacts()
        for event in self.contacts.update(self.cell.contacts()):  # rclpy: one severity per call site
            if event.started:
                self.log.warning(event.text())
            else:
                self.log.info(event.text())

    def publish_status(self) -> None:
        values = {"steps": self.steps, "commands_received": self.received, "commands_rejected": self.rejected,
                  "command_timeouts": self.timeouts, "timed_out": self.timed_out,
                  "last_command_ns": self.command_ns,
                  **({"table_contacts": self.table_contacts} if self.table else {}), **self.contacts.diagnostics()}
        touching = ", ".join(f"{a}-{b}" for a, b in self.contacts.current)
        message = ("arms at rest: command timeout" if self.timed_out else
                   f"links in contact: {touching}" if touching else "running")
        self.pub_diag.publish(convert.diagnostics(self._stamp_ns(), "sim_node", 1 if self.timed_out or touching else 0,
                                                  message, values))
        unheard = self.unheard_commands()
        if unheard:
            self.log.warning(unheard)

    def unheard_commands(self) -> str:
        """:data:`UNHEARD` with the command topics' publishers (node names), when the physics steps, no command
        has arrived, and a command topic has had a publisher for :data:`UNHEARD_AFTER_S`; '' otherwise (and
        always once a command has arrived)."""
        if self.received or self.rejected or not self.steps:
            return ""
        found = {topic: sorted({info.node_name for info in self.node.get_publishers_info_by_topic(topic)})
                 for topic in self.command_topics}
        named = "; ".join(f"{topic} by {', '.join(nodes)}" for topic, nodes in found.items() if nodes)
        now = time.monotonic()
        if not named:
            self.publishers_seen = None
            return ""
        if self.publishers_seen is None:
            self.publishers_seen = now
        waited = now - self.publishers_seen
        if waited < UNHEARD_AFTER_S:
            return ""
        return (f"{UNHEARD} in the {waited:.1f} s since commands are published ({named}): none has reached this "
                "simulator (none sent yet, or DDS discovery has not yet matched this reader to that writer: a "
                "restarted node can wait seconds for it)")

    def lockstep_watchdog(self) -> None:
        """Start once the readers are matched; re-send a state that got no command: before the first
        step (a discovery race: a reader matched on the writer's side only missed it) or, with
        best_effort streams, a state or command lost. Not once the cell steps on reliable streams: a
        state without a command is then the run's end (no target for it) or a node stopping, and a
        re-sent one would only repeat its stamp in a recording while the nodes flush (ros.node.run)."""
        if not self.started:
            if min(self.node.count_subscribers(s.topic) for s in self.layout) < self.wait_for:
                return
            if self.readers_matched_at is None:
                self.readers_matched_at = time.monotonic()
            if time.monotonic() - self.readers_matched_at < self.start_delay:
                return
            self.started = True
            self.log.info(f"{self.wait_for} joint_states readers matched: starting lockstep")
            self.publish_state()
        elif (self.steps == 0 or self.best_effort) and time.monotonic() - self.last_publish > self.resend_s:
            self.publish_state()


def main(args: list[str] | None = None) -> int:
    argv = list(sys.argv if args is None else args)
    request = node_scheduling(argv, DEFAULT_PRIORITY, "sim_node")
    help_text = usage("sim_node", __doc__ or "", PARAMETERS)
    return run(lambda context: SimNode(context, request.note), argv, help_text, request.granted)


if __name__ == "__main__":
    exit_process(main())
