"""The ``dualarm`` command: experiments, benchmarks, and ros2-like verbs for machines without ROS.

Run ``dualarm --help`` or ``dualarm <verb> --help``.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from dualarm_control.app.faults.command import add_faults_parsers
from dualarm_control.app.ros_verbs import (
    add_bag_parser,
    add_param_parser,
    add_topic_parser,
)
from dualarm_control.app.run import DEFAULT_SOLVERS
from dualarm_control.errors import DualArmError

EXIT_USAGE = 2


ROBOT_HELP = ("robot description: a name of config/robots/ (lwr4_cell, baxter, panda_pair, ur5_pair, ...) or a "
              "YAML path (docs/robots.md); default: the scenario's robot. Another robot than the scenario's "
              "starts at its ready positions")


def add_robot_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--robot", default=None, metavar="NAME|PATH", help=ROBOT_HELP)


def cmd_robot(args: argparse.Namespace) -> int:
    """``dualarm robot list|show|ready``: :mod:`dualarm_control.app.robot.command`."""
    from dualarm_control.app.robot import command

    if args.robot_verb == "list":
        return command.list_command()
    if args.robot_verb == "show":
        return command.show_command(args.robot)
    return command.ready_command(args.robot, args.distance, args.center, args.starts, args.seed)


def cmd_hardware(args: argparse.Namespace) -> int:
    """``dualarm hardware check``: :mod:`dualarm_control.app.hardware.command`."""
    from dualarm_control.app.hardware.command import check_command

    return check_command(args.params, args.robot, args.timeout)


def cmd_experiment(args: argparse.Namespace) -> int:
    """Run a scenario in-process (lockstep): :func:`dualarm_control.app.run.command.experiment_command`."""
    from dualarm_control.app.run.command import experiment_command

    return experiment_command(args.scenario, args.solver, args.params, Path(args.output), args.gains, args.force,
                              args.duration, args.robot)


def cmd_launch(args: argparse.Namespace) -> int:
    """Start the three nodes as processes on a scenario; optionally record a bag."""
    from dualarm_control.ros.env import stop_with_launcher

    stop_with_launcher()  # started by a launcher (or a test) that says so: stop with it, nodes and all
    from dualarm_control.app.run.launcher import (
        INTERACTIVE,
        INTERACTIVE_CELL,
        launch_scenario,
    )
    from dualarm_control.params import read_params_files
    from dualarm_control.scenario import load_scenario, scenario_file

    interactive = args.scenario == INTERACTIVE or args.interactive
    if interactive:  # the cell and limits of the interactive demo (or of the scenario given), driven live
        args.scenario = INTERACTIVE_CELL if args.scenario == INTERACTIVE else args.scenario
        if args.plan:
            raise DualArmError("'dualarm launch interactive' and --interactive follow live goals (no --plan)")
    if args.processes != 3 and args.lockstep:
        raise DualArmError(f"--processes {args.processes} runs in real time: --lockstep runs the nodes in "
                           "separate processes (--processes 3)")
    scenario_file(args.scenario)  # fail early (exit 2) on an unknown scenario
    read_params_files(args.params, "_check_")  # exit 2 naming a missing or bad --params file before any node starts
    extra = []
    if args.solver:
        extra += ["-p", f"solver:={args.solver}"]
    if (args.gain is not None or args.duration is not None or args.force) and load_scenario(args.scenario).tasks is None:
        raise DualArmError(f"--gain, --duration and --force apply to task scenarios (pan_cleaning), "
                           f"not to {args.scenario!r}")
    if args.gain is not None:
        extra += ["-p", f"task_gain:={float(args.gain)!r}"]
    if args.duration is not None:
        extra += ["-p", f"duration:={float(args.duration)!r}"]
    record = Path(args.record) if args.record else None
    plan = Path(args.plan) if args.plan else None
    if plan is not None:
        from dualarm_control.kinematics import DualArmModel
        from dualarm_control.planning.plan_file import read_plan

        model = DualArmModel(load_scenario(args.scenario, args.robot).robot)
        # exit 2 on a bad plan file (joints, NaN, configurations beyond the limits), before any node starts
        planned = read_plan(plan, model.joint_names, model.q_min, model.q_max).scenario
        if planned != args.scenario:
            raise DualArmError(f"--plan {plan} was planned on scenario {planned!r}, not {args.scenario!r}")
    return launch_scenario(args.scenario, args.params, extra, args.lockstep, record, args.timeout, args.rate,
                           plan=plan, force=args.force, interactive=interactive, processes=args.processes,
                           robot=args.robot)


def cmd_run(args: argparse.Namespace) -> int:
    """Run one node in the foreground (like ``ros2 run dualarm_control NODE``)."""
    import os

    from dualarm_control.app.run.launcher import NODES, node_command

    if args.node not in NODES:
        raise DualArmError(f"unknown node {args.node!r}; valid choices: {', '.join(NODES)}")
    from dualarm_control.cell_robot import with_absolute_robot

    cmd = node_command(args.node, with_absolute_robot(args.ros_args))  # a profile's relative robot path: the file's
    os.execv(cmd[0], cmd)
    return 0  # not reached


DEMO_VIDEO_SIZE = (320, 240)
"""Size of the demo's videos [px]: small, so that rendering adds little to the demo (docs/visualization.md)."""


def demo_video(bag: Path, out: Path) -> None:
    """The demo's video of one run (``dualarm view BAG --video``), skipped without the ``view`` extra."""
    from dualarm_control.app.view.video import VideoError, render_video

    try:
        render_video(bag, out, size=DEMO_VIDEO_SIZE, log=sys.stderr)
    except VideoError as exc:
        print(f"demo: no video of {bag}: {exc}", file=sys.stderr)


def cmd_demo(args: argparse.Namespace) -> int:
    """The main job: for each solver, three processes over ROS in lockstep with a bag, then
    ``dualarm report`` on the bag, then the in-process experiment, and a comparison of both."""
    import json

    from dualarm_control.app.run.launcher import launch_scenario

    out = Path(args.output)
    solvers = [s.strip() for s in args.solver.split(",") if s.strip()]
    reports: dict[str, dict[str, float]] = {}
    for name in solvers:
        bag = out / name / "bag"
        if bag.exists():
            import shutil

            shutil.rmtree(bag)
        bag.parent.mkdir(parents=True, exist_ok=True)
        print(f"=== {name}: sim_node + controller_node + trajectory_node over ROS (lockstep), bag {bag}", flush=True)
        code = launch_scenario(args.scenario, [], ["-p", f"solver:={name}"], True, bag, args.timeout)
        if code != 0:
            print(f"demo: the {name} run failed (exit {code})", file=sys.stderr)
            return code
        code = main(["report", str(bag), "--output", str(out / name / "report")])
        if code != 0:
            return code
        reports[name] = json.loads((out / name / "report" / "metrics.json").read_text())[name]
        demo_video(bag, out / name / "run.mp4")
    print("=== in-process experiment (same scenario and solvers) for comparison", flush=True)
    code = main(["experiment", args.scenario, "--solver", ",".join(solvers), "--output", str(out / "experiment")])
    if code != 0:
        return code
    experiment = json.loads((out / "experiment" / "metrics.json").read_text())
    comparison: dict[str, dict[str, dict[str, float]]] = {}
    print(f"\n{'solver':<24}{'metric':<9}{'bag (ROS)':>12}{'in-process':>12}{'rel. diff':>11}")
    for name in solvers:
        comparison[name] = {}
        for key in ("l0_mean", "l1_mean", "l2_mean"):
            a, b = reports[name][key], experiment[name][key]
            diff = abs(a - b) / max(abs(b), 1e-12)
            comparison[name][key] = {"bag": a, "experiment": b, "relative_difference": diff}
            print(f"{name:<24}{key:<9}{a:>12.4f}{b:>12.4f}{diff:>10.2%}")
    (out / "comparison.json").write_text(json.dumps(comparison, indent=2) + "\n")
    print(f"\nwrote {out}/<solver>/bag, {out}/<solver>/report/, {out}/<solver>/run.mp4, {out}/experiment/ and "
          f"{out}/comparison.json")
    return 0


def cmd_bench(args: argparse.Namespace) -> int:
    """Solver x QP back-end timings (random set, scenario), pink, exactness, scaling: DIR/bench.md and bench.json."""
    if sum(bool(x) for x in (args.realtime, args.messages, args.obstacles)) > 1:
        raise DualArmError("--realtime, --messages and --obstacles are separate benchmarks: choose one")
    for option in ("with_view", "load", "scheduling", "baseline", "processes", "floor"):
        if getattr(args, option) and not args.realtime:
            raise DualArmError(f"--{option.replace('_', '-')} belongs to --realtime")
    from dualarm_control.solvers import make_solver

    solvers = [s.strip() for s in args.solver.split(",") if s.strip()]
    if args.messages:  # per-period messages through rclpy objects and as CDR bytes
        from dualarm_control.ros.message_bench import (
            format_message_bench,
            run_message_bench,
            write_message_bench,
        )

        rows = run_message_bench()
        write_message_bench(Path(args.output), rows)
        print(format_message_bench(rows))
        print(f"\nwrote {Path(args.output) / 'messages.md'} and messages.json")
        return 0
    for name in solvers:
        make_solver(name)  # unknown names exit 2 before any run
    if args.obstacles:
        from dualarm_control.app.bench.obstacles import run_obstacle_bench

        return run_obstacle_bench(args.obstacles, solvers, Path(args.output))
    if args.realtime:  # real-time runs over ROS per solver, rate, load, scheduling, layout (and tree)
        from dualarm_control.app.bench.floor import floor_rows, format_floor
        from dualarm_control.app.bench.realtime import (
            LOADS,
            PROCESSES,
            SCHEDULINGS,
            baseline_tree,
            format_cpu,
            format_realtime,
            run_realtime,
            split_choices,
            write_realtime,
        )
        from dualarm_control.params import read_params_files
        from dualarm_control.scenario import scenario_file

        scenario_file(args.scenario)
        loads = split_choices(args.load or "none", LOADS, "--load")
        schedulings = split_choices(args.scheduling or "rt", SCHEDULINGS, "--scheduling")
        processes = [int(n) for n in split_choices(args.processes or "3", PROCESSES, "--processes")]
        baseline = Path(args.baseline) if args.baseline else None
        if baseline is not None:
            baseline_tree(baseline)
        read_params_files(args.params, "_check_")  # exit 2 on a bad --params file before any node starts
        rows = run_realtime(args.scenario, solvers, [float(r) for r in args.rates.split(",") if r.strip()],
                            params=args.params, with_view=args.with_view, loads=loads, schedulings=schedulings,
                            baseline=baseline, processes=processes)
        floor = floor_rows(rows) if args.floor else []
        write_realtime(Path(args.output), rows, args.scenario, floor)
        print(format_realtime(rows))
        print()
        print(format_cpu(rows))
        if floor:
            print()
            print(format_floor(floor))
        print(f"\nwrote {Path(args.output) / 'realtime.md'} and realtime.json")
        return 0
    from dualarm_control.app.bench.suite import format_bench, run_bench, write_bench
    from dualarm_control.qp import make_backend
    from dualarm_control.scenario import load_scenario

    scenario = None if args.scenario == "none" else load_scenario(args.scenario)
    backends = [b.strip() for b in args.backend.split(",") if b.strip()]
    for name in backends:
        make_backend(name)
    robots = [] if args.collision_robots == "none" else [r.strip() for r in args.collision_robots.split(",") if r.strip()]
    record = run_bench(scenario, solvers, backends, count=args.cases, seed=args.seed,
                       progress=lambda msg: print(f"[bench] {msg}", file=sys.stderr, flush=True),
                       collision_robots=robots)
    write_bench(Path(args.output), record)
    print(format_bench(record))
    print(f"wrote {Path(args.output) / 'bench.md'} and bench.json")
    return 0


def cmd_report(args: argparse.Namespace) -> int:
    """Metrics of a recorded run: DIR/metrics.json, the figures of its kind and the table."""
    from dualarm_control.app.record.bag_runs import report
    from dualarm_control.app.record.report import format_table, goal_lines

    out = Path(args.output)
    results, kind, figures = report(Path(args.bag), out)
    print(format_table(results, kind))
    print(goal_lines(results), end="")
    print(f"\nwrote {out / 'metrics.json'} and {', '.join(figures)} in {out}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="dualarm",
        description="Sparse hierarchical QP control of a simulated dual-arm cell (ROS 2 package dualarm_control).",
    )
    sub = parser.add_subparsers(dest="verb", metavar="VERB")
    sub.required = True

    exp = sub.add_parser(
        "experiment",
        help="run a scenario in-process for several solvers (Table I, Fig. 5)",
        description="Run SCENARIO in one process in lockstep (pybullet cell + controller + ruckig targets) "
        "for each solver; print a Table-I-style table, write DIR/metrics.json and DIR/velocity_norms.png. "
        "A task scenario (pan_cleaning, paper 001) runs the constraint_based solver once per gain (--gains, "
        "--force) and writes DIR/metrics.json, tool_path.png, task_values.png, joint_velocities.png "
        "(and contact_force.png).",
    )
    exp.add_argument("scenario", help="scenario name (config/scenarios/<name>.yaml) or a YAML path")
    exp.add_argument("--solver", default=None,
                     help=f"comma-separated solver names (default: {DEFAULT_SOLVERS}; for a task scenario: "
                     "constraint_based)")
    exp.add_argument("--params", action="append", default=[], metavar="FILE",
                     help="ROS-style parameter file for controller_node (repeatable; later files win)")
    exp.add_argument("--output", default="out/experiment", metavar="DIR", help="output directory (default: %(default)s)")
    exp.add_argument("--gains", default="", metavar="K,K,...",
                     help="task scenarios: task gains k [1/s] to compare (default: the scenario's, e.g. 1,0.5,0.2; "
                     "with --force the scenario's force.gain)")
    exp.add_argument("--force", action="store_true",
                     help="task scenarios: force feedback variant (eq 9): real brush-pan contact, noisy filtered "
                     "F/T sensor, PI force control, pan modelling error")
    exp.add_argument("--duration", type=float, default=None, metavar="S",
                     help="task scenarios: run time [s] (default: the scenario's)")
    add_robot_argument(exp)
    exp.set_defaults(func=cmd_experiment)

    rob = sub.add_parser("robot", help="robot descriptions: list, show, find ready positions (docs/robots.md)",
                         description="The robot descriptions (config/robots/<name>.yaml, or a YAML of your own): "
                         "list the shipped ones, show one resolved (joints, limits, tools, locked joints), or "
                         "search ready positions in which the tools face each other.")
    rverbs = rob.add_subparsers(dest="robot_verb", metavar="ROBOT_VERB")
    rverbs.required = True
    rverbs.add_parser("list", help="the shipped robots")
    show = rverbs.add_parser("show", help="one robot, resolved")
    show.add_argument("robot", help="name (config/robots/) or YAML path")
    ready = rverbs.add_parser("ready", help="ready positions: the tools DISTANCE apart, facing each other (IK)")
    ready.add_argument("robot", help="name (config/robots/) or YAML path")
    ready.add_argument("--distance", type=float, default=0.3, metavar="M",
                       help="distance between the tools [m] (default: %(default)s)")
    ready.add_argument("--center", type=float, nargs=3, default=None, metavar=("X", "Y", "Z"),
                       help="the tools' midpoint in the world [m] (default: in front of the arms' first joints)")
    ready.add_argument("--starts", type=int, default=24, help="IK starts (default: %(default)s)")
    ready.add_argument("--seed", type=int, default=0, help="seed of the random starts (default: %(default)s)")
    rob.set_defaults(func=cmd_robot)

    demo = sub.add_parser("demo", help="the main job: three nodes over ROS per solver, bags, reports",
                          description="For each solver: launch the three nodes over ROS in lockstep on the "
                          "scenario while recording a bag, run 'dualarm report' on the bag, then run the "
                          "in-process experiment and print how the bag metrics compare.")
    demo.add_argument("--scenario", default="assembly", help="scenario (default: %(default)s)")
    demo.add_argument("--solver", default="standard_qp,sparse_qp,hierarchical_sparse_qp",
                      help="comma-separated solvers (default: %(default)s)")
    demo.add_argument("--output", default="out/demo", metavar="DIR", help="output directory (default: %(default)s)")
    demo.add_argument("--timeout", type=float, default=600.0, metavar="S", help="per-run time limit (default: 600)")
    demo.set_defaults(func=cmd_demo)

    ben = sub.add_parser("bench", help="solver timing tables (percentiles and ratios to pink)",
                         description="Time RelativeController.step per solver and QP back-end on seeded random "
                         "configurations and on a scenario, next to pink's solve_ik (with the bench extra), check the "
                         "lasso's exactness and time 3- and 4-arm chains; p50/p99 and ratios from the same run.")
    ben.add_argument("--scenario", default="assembly", help="scenario, or 'none' (default: %(default)s)")
    ben.add_argument("--solver", default="pseudo_inverse,standard_qp,sparse_qp,hierarchical_sparse_qp",
                     help="comma-separated solvers (default: %(default)s)")
    ben.add_argument("--backend", default="daqp,proxsuite,quadprog",
                     help="comma-separated QP back-ends (default: %(default)s)")
    ben.add_argument("--cases", type=int, default=400, help="random configurations (default: %(default)s)")
    ben.add_argument("--seed", type=int, default=0, help="random seed (default: %(default)s)")
    ben.add_argument("--collision-robots", default="lwr4_cell,baxter", metavar="ROBOT,...",
                     help="robots of the collision part (the assembly's cycles with and without the collision "
                     "limit, interleaved), or 'none' (default: %(default)s)")
    ben.add_argument("--output", default="out/bench", metavar="DIR", help="output directory (default: %(default)s)")
    ben.add_argument("--realtime", action="store_true",
                     help="instead: the three nodes over ROS in real time per solver and --rates; missed deadlines, "
                     "period jitter and state-to-command latency over every cycle, and each node's CPU (cores, CPU "
                     "per control cycle in its main thread and its other threads, the control math per cycle) over "
                     "the steady motion, read from /proc (realtime.md/json)")
    ben.add_argument("--messages", action="store_true",
                     help="instead: the per-period messages (joint states, target, diagnostics, command) built and "
                     "read through rclpy message objects and as CDR bytes, in one process (messages.md/json)")
    ben.add_argument("--obstacles", type=int, default=0, metavar="N",
                     help="instead: the control cycle with N live obstacles and without (the assembly's states "
                     "replayed, interleaved; --solver), and a 100k-point cloud's intake in control periods "
                     "(obstacles.md/json; docs/obstacles.md)")
    ben.add_argument("--rates", default="200,500,1000", metavar="HZ,...",
                     help="control rates of --realtime (default: %(default)s)")
    ben.add_argument("--params", action="append", default=[], metavar="FILE",
                     help="--realtime: ROS-style parameter file passed to every node (repeatable), e.g. "
                     "config/realtime_1khz.yaml")
    ben.add_argument("--with-view", action="store_true",
                     help="--realtime: run each launch twice, without and with 'dualarm view --save' (the live "
                     "Rerun view, its own process) beside it (needs the view extra)")
    ben.add_argument("--load", metavar="none,busy",
                     help="--realtime: what else runs during each launch, one row each: none, or busy (one core kept "
                     "busy by a normal-priority process: stress-ng --cpu 1, else a Python spin loop) (default: none)")
    ben.add_argument("--scheduling", metavar="rt,normal",
                     help="--realtime: rt (the nodes' SCHED_FIFO thread_priority defaults) or normal (thread_priority "
                     "0 for every node, passed after the --params files: a machine without rtprio), one row each "
                     "(default: rt)")
    ben.add_argument("--processes", metavar="3,2,1",
                     help="--realtime: the process layouts of 'dualarm launch --processes', one row each: 3 (each node "
                     "its own process), 2 (the simulator alone), 1 (all in one cell_container) (default: 3)")
    ben.add_argument("--floor", action="store_true",
                     help="--realtime: after the launches, the machine's floor for each rate, load and scheduling: a "
                     "process that only sleeps to each period and spins the CPU per cycle the leanest launch took, "
                     "its missed deadlines counted as the controller's (the 'floor' table)")
    ben.add_argument("--baseline", metavar="DIR",
                     help="--realtime: a source checkout of another commit (git worktree add --detach DIR REV); each "
                     "row is also run with the nodes and the recorder importing DIR (PYTHONPATH, same venv), right "
                     "before the current tree's, labelled with DIR's short commit")
    ben.set_defaults(func=cmd_bench)

    hw = sub.add_parser("hardware", help="hardware profiles against a live ros2_control graph (docs/hardware.md)",
                        description="Hardware profiles (hardware.* parameters of the controller, config/hardware/).")
    hverbs = hw.add_subparsers(dest="hardware_verb", metavar="HARDWARE_VERB", required=True)
    chk = hverbs.add_parser("check", help="does the profile match the live graph? (exit 0 only when it can run)",
                            description="List the profile's joint-state and command topics on the live graph, their "
                            "publishers and subscribers with types, the joint names matched or missing, and one line "
                            "per problem. Waits for discovery up to --timeout; exit 0 only when the profile can run.")
    chk.add_argument("--params", action="append", default=[], metavar="FILE",
                     help="the controller's parameter file with the profile (repeatable; default: the default profile)")
    chk.add_argument("--timeout", type=float, default=10.0, metavar="S",
                     help="how long to wait for the graph to match (discovery takes up to ~4 s)")
    chk.add_argument("--robot", default=None, metavar="NAME|PATH",
                     help="the robot description whose joints the profile is checked for: a name of config/robots/ "
                     "(lwr4_cell, baxter, panda_pair, ur5_pair, ...) or a YAML path (docs/robots.md); default: the "
                     "--params files' robot parameter (controller_node's), else the robot of their scenario "
                     "parameter (default assembly: lwr4_cell)")
    chk.set_defaults(func=cmd_hardware)

    run = sub.add_parser("run", help="run one node (like ros2 run dualarm_control NODE)",
                         description="Run NODE (sim_node, controller_node, trajectory_node) in the foreground. "
                         "Arguments after the node are ROS arguments: --ros-args --params-file F -p k:=v -r a:=b. "
                         "'dualarm run NODE --help' (or --ros-args --help) prints the node's usage and parameters.")
    run.add_argument("node", help="sim_node, controller_node or trajectory_node")
    run.add_argument("ros_args", nargs=argparse.REMAINDER, help="--ros-args ...")
    run.set_defaults(func=cmd_run)

    lau = sub.add_parser("launch", help="start the nodes as processes on a scenario (sim, controller, trajectory; no trajectory for a task scenario)",
                         description="Start sim_node, controller_node and trajectory_node as separate processes "
                         "over ROS (localhost discovery by default), prefix their output, and stop everything when the "
                         "scenario is complete or on Ctrl-C. Exit status is non-zero if a node failed.")
    lau.add_argument("scenario", help="scenario name or YAML path; 'interactive': the cell of interactive_demo "
                     "driven live by /relative_goal and /relative_twist (dualarm goal, dualarm jog, any ROS 2 tool)")
    lau.add_argument("--params", action="append", default=[], metavar="FILE",
                     help="ROS-style parameter file passed to every node (repeatable)")
    lau.add_argument("--solver", help="shortcut for -p solver:=NAME on the controller")
    lau.add_argument("--lockstep", action="store_true",
                     help="deterministic: the simulator steps only when the command for the step arrives")
    lau.add_argument("--record", metavar="BAG", help="record the graph's topics to this rosbag2 directory")
    lau.add_argument("--rate", type=float, metavar="HZ", help="control rate of every node (default: 200 Hz)")
    lau.add_argument("--plan", metavar="PLAN_JSON",
                     help="execute a plan of 'dualarm plan': the sim starts at its first configuration, the "
                     "trajectory node streams its joint trajectory, the controller tracks it (plan:=FILE)")
    lau.add_argument("--force", action="store_true",
                     help="task scenario: force feedback variant (contact in the sim, -p force:=true on both nodes)")
    lau.add_argument("--gain", type=float, metavar="K",
                     help="task scenario: gain k of every task (-p task_gain:=K; default: the scenario's first "
                     "gain, or force.gain with --force)")
    lau.add_argument("--duration", type=float, metavar="S",
                     help="task scenario: run S seconds of task time (-p duration:=S; default: the scenario's)")
    lau.add_argument("--timeout", type=float, default=None, metavar="S", help="stop after S seconds")
    lau.add_argument("--interactive", action="store_true",
                     help="drive the scenario's cell live instead of its script: /relative_goal, /relative_twist, "
                     "and with its absolute_frame /absolute_goal, /absolute_twist (dualarm goal/jog [--absolute])")
    lau.add_argument("--processes", type=int, choices=(1, 2, 3), default=3, metavar="N",
                     help="3: each node its own process (default); 2: the simulator alone, the controller and the "
                     "trajectory node in one; 1: all in one. Nodes sharing a process run as cell_container (one "
                     "executor, one DDS participant, their per-cycle samples passed in the process and published for "
                     "every other tool); real time only. What each costs: docs/bench.md, 'Processes'")
    add_robot_argument(lau)
    lau.set_defaults(func=cmd_launch)
    add_faults_parsers(sub)
    add_bag_parser(sub)
    add_topic_parser(sub)
    add_param_parser(sub)
    rep = sub.add_parser("report", help="metrics of a recorded run (metrics.json, velocity_norms.png, table)",
                         description="Read a bag of a run (commands, joint states, diagnostics, relative pose "
                         "and target) and write DIR/metrics.json and DIR/velocity_norms.png like 'experiment'.")
    rep.add_argument("bag", help="rosbag2 directory")
    rep.add_argument("--output", default="out/report", metavar="DIR", help="output directory (default: %(default)s)")
    rep.set_defaults(func=cmd_report)
    from dualarm_control.app.plan.command import add_plan_parser

    add_plan_parser(sub)
    from dualarm_control.app.view.command import add_view_parser

    add_view_parser(sub)
    from dualarm_control.ros.drive import add_drive_parsers

    add_drive_parsers(sub)
    from dualarm_control.app.sweep.command import add_sweep_parser

    add_sweep_parser(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args))
    except DualArmError as exc:
        print(f"dualarm {args.verb}: error: {exc}", file=sys.stderr)
        return EXIT_USAGE


if __name__ == "__main__":
    sys.exit(main())
