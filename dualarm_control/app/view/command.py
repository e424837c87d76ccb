"""``dualarm view [BAG]``: the cell in Rerun, live from the running cell or replayed from a bag; with
``--video`` a video of a bag (``video.py``), with ``--foxglove`` a Foxglove WebSocket server
(``foxglove_view.py``).

Register with :func:`add_view_parser` (one call in ``cli.py``).
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from dualarm_control.app.view.options import add_foxglove_arguments, add_video_arguments
from dualarm_control.errors import DualArmError

if TYPE_CHECKING:
    from dualarm_control.robot import RobotDescription

NO_VIEWER = 2
LIVE_VIEW_NICENESS = 19
"""A live view lowers its own CPU priority to this niceness (the lowest): on a busy machine the
control nodes come first (docs/visualization.md, what the view costs the control loop)."""


def add_view_parser(sub: Any) -> None:
    """The ``view`` verb on the ``dualarm`` sub-parsers."""
    from dualarm_control.app.view.server import DEFAULT_GRPC_PORT, DEFAULT_WEB_PORT

    view = sub.add_parser(
        "view", help="see the cell: Rerun 3D and plots (live or from a bag), a video of a bag, or a Foxglove server",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description="""See a run of the cell, live (no BAG: subscribe to the running cell until Ctrl-C) or from a bag.
Needs the view extra (pip install 'dualarm_control[view]'). Runs in its own process.

modes:
  dualarm view [BAG] [--web] [--save FILE.rrd]
      Rerun (default): the cell's URDF posed by the joint states, the relative target as axes in
      the left tool frame, and plots on one time axis (||qd||_0 and ||qd||_1, tracking errors,
      solve and cycle time, solver status changes; for task scenarios the task values with their
      bounds and the contact force). Native viewer when there is a display; --web serves the web
      viewer on 127.0.0.1 and prints its URL; --save writes a recording (open: rerun FILE.rrd).
      Live: /joint_states, /velocity_controller/commands, /relative_target, /diagnostics.
  dualarm view BAG --video run.mp4 [--fps F] [--size WxH]
      a video of the recorded run without any viewer: pybullet's offscreen renderer, H.264 by
      the ffmpeg of imageio-ffmpeg.
  dualarm view [BAG] --foxglove [--foxglove-port PORT] [--speed S]
      a Foxglove WebSocket server on 127.0.0.1 (Foxglove app: Open connection > Foxglove
      WebSocket > ws://127.0.0.1:PORT): /robot_description, /tf_static, /tf, /joint_states and the
      signals as ROS 2 messages; a bag is replayed in a loop, else the running cell is relayed.
See docs/visualization.md.""")
    view.add_argument("bag", nargs="?", help="rosbag2 directory to replay (default: live)")
    rerun_group = view.add_argument_group("Rerun (default mode)")
    rerun_group.add_argument("--web", action="store_true",
                             help="serve the web viewer on 127.0.0.1 and print its URL (serves until Ctrl-C)")
    rerun_group.add_argument("--save", metavar="FILE.rrd",
                             help="write a Rerun recording (open it with: rerun FILE.rrd)")
    rerun_group.add_argument("--grpc-port", type=int, default=DEFAULT_GRPC_PORT,
                             help="--web: gRPC port (default: %(default)s)")
    rerun_group.add_argument("--web-port", type=int, default=DEFAULT_WEB_PORT,
                             help="--web: page port (default: %(default)s)")
    rerun_group.add_argument("--duration", type=float, metavar="S", help="live: stop after S seconds")
    view.add_argument("--robot", default=None, metavar="NAME|PATH",
                      help="live: the running cell's robot (config/robots/ name or YAML; default: the --params "
                      "profile's hardware.robot, else lwr4_cell, said in one line); a bag names its own")
    view.add_argument("--params", action="append", default=[], metavar="FILE",
                      help="live: the cell's hardware profile (its hardware.robot is the robot; repeatable)")
    add_video_arguments(view.add_argument_group("video of a bag (--video)"))
    add_foxglove_arguments(view.add_argument_group("Foxglove WebSocket server (--foxglove)"))
    view.set_defaults(func=cmd_view)


def cell_robot_of(params: list[str], robot: str | None) -> RobotDescription:
    """The live cell's robot: the ``params`` profile's ``hardware.robot``, else ``robot``, else the LWR4 cell, said
    in one line (dualarm_control/cell_robot.py); ParameterError when the two disagree."""
    from dualarm_control.cell_robot import cell_robot, robot_note
    from dualarm_control.scenario import load_scenario

    chosen, profile_robot = cell_robot(params, robot)
    scenario = load_scenario("assembly", chosen)
    print(f"dualarm view: {robot_note(scenario, profile_robot, chosen or '')}", flush=True)
    return scenario.robot


def _interrupt(signum: int, frame: object) -> None:
    """SIGTERM ends ``dualarm view`` like Ctrl-C (the web viewer's server is then stopped)."""
    raise KeyboardInterrupt


def yield_to_the_cell() -> None:
    """Lower this process's priority to :data:`LIVE_VIEW_NICENESS` before any of its threads start
    (Linux niceness is per thread and inherited by the threads and processes started later)."""
    os.nice(max(0, LIVE_VIEW_NICENESS - os.nice(0)))


def cmd_view(args: argparse.Namespace) -> int:
    """``dualarm view``: a video (``--video``), a Foxglove server (``--foxglove``), or else Rerun."""
    if args.video and args.foxglove:
        raise DualArmError("dualarm view: --video and --foxglove are separate modes: give one")
    rerun_options = [name for name, given in (("--web", args.web), ("--save", args.save),
                                              ("--duration", args.duration is not None)) if given]
    if (args.video or args.foxglove) and rerun_options:
        mode = "--video" if args.video else "--foxglove"
        raise DualArmError(f"dualarm view: {', '.join(rerun_options)} belong to the Rerun mode, not to {mode}")
    if args.video:
        from dualarm_control.app.view.video import video_from_args

        return video_from_args(args.bag, args)
    if args.foxglove:
        from dualarm_control.app.view.foxglove_view import foxglove_from_args

        if args.bag is None:
            yield_to_the_cell()
        return foxglove_from_args(args.bag, args)
    return _rerun_view(args)


def _rerun_view(args: argparse.Namespace) -> int:
    """The Rerun mode: log the bag or the live cell to the chosen sinks."""
    try:
        import rerun as rr
    except ImportError:
        raise DualArmError("the Rerun viewer is not installed: pip install 'dualarm_control[view]'") from None
    from dualarm_control.app.view import rerun_view as rv
    from dualarm_control.app.view.server import WebViewer

    if not args.web and not args.save and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        print("dualarm view: no display for the native viewer. Use --web (open the printed URL in a browser) or "
              "--save FILE.rrd (then: rerun FILE.rrd on a machine with a display).", file=sys.stderr)
        return NO_VIEWER
    if args.bag is None:
        yield_to_the_cell()
    arrays = None
    live_robot = None if args.bag else cell_robot_of(args.params, args.robot)  # a bad --params fails before a viewer
    if args.bag:
        from dualarm_control.app.view.from_bag import bag_run_arrays

        arrays = bag_run_arrays(Path(args.bag))  # read first: a bad bag fails before any viewer starts
    rec = rr.RecordingStream(rv.APPLICATION_ID)
    previous = signal.signal(signal.SIGTERM, _interrupt)  # SIGTERM stops like Ctrl-C: the server is closed
    server = WebViewer(args.grpc_port, args.web_port) if args.web else None
    try:
        sinks: list[Any] = []
        if args.save:
            Path(args.save).parent.mkdir(parents=True, exist_ok=True)
            sinks.append(rr.FileSink(str(args.save)))
        if server is not None:
            sinks.append(rr.GrpcSink(server.grpc_url))
        if sinks:
            rec.set_sinks(*sinks)
        else:
            rec.spawn()
        if server is not None:
            print(f"dualarm view: web viewer at {server.url}", flush=True)
        if arrays is not None:
            arrays.log(rec)
            print(f"dualarm view: logged {len(arrays.stamps)} cycles of {args.bag}", flush=True)
        else:
            from dualarm_control.app.view.live import live_groups, run_live
            from dualarm_control.kinematics import DualArmModel

            assert live_robot is not None  # no bag: the live cell
            model = DualArmModel(live_robot)
            rec.send_blueprint(rv.blueprint(rv.robot_name(Path(model.urdf)), live_groups()))
            run_live(model, rec, args.duration)
        rec.flush()
        rec.disconnect()  # closes the file; the web viewer's proxy keeps what it received
        if args.save:
            print(f"dualarm view: wrote {args.save}", flush=True)
        if server is not None and arrays is not None:
            print("dualarm view: serving until Ctrl-C", flush=True)
            try:
                while server.process.poll() is None:
                    time.sleep(0.5)
            except KeyboardInterrupt:
                pass
    except KeyboardInterrupt:
        pass
    finally:
        if server is not None:
            server.close()
        signal.signal(signal.SIGTERM, previous)
    return 0
