"""``dualarm view [BAG]``: the cell in Rerun, live from the running cell or replayed from a bag.

Register with :func:`add_view_parser` (one call in ``cli.py``).
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import time
from pathlib import Path
from typing import Any

from dualarm_control.errors import DualArmError

NO_VIEWER = 2


def add_view_parser(sub: Any) -> None:
    """The ``view`` verb on the ``dualarm`` sub-parsers."""
    from dualarm_control.app.view.server import DEFAULT_GRPC_PORT, DEFAULT_WEB_PORT

    view = sub.add_parser(
        "view", help="see the cell in Rerun: 3D (URDF posed by the joint states) and plots, live or from a bag",
        description="Log a run of the cell to Rerun: the cell's URDF posed by the joint states, the relative target "
        "as axes in the left tool frame, and plots on one time axis (||qd||_0 and ||qd||_1, tracking errors, solve "
        "and cycle time, solver status changes; for task scenarios the task values with their bounds and the "
        "contact force). With BAG, replay that recording; without, subscribe to the running cell (/joint_states, "
        "/velocity_controller/commands, /relative_target, /diagnostics) until Ctrl-C. Needs the view extra "
        "(pip install 'dualarm_control[view]').")
    view.add_argument("bag", nargs="?", help="rosbag2 directory to replay (default: live)")
    view.add_argument("--web", action="store_true",
                      help="serve the web viewer on 127.0.0.1 and print its URL (serves until Ctrl-C)")
    view.add_argument("--save", metavar="FILE.rrd", help="write a Rerun recording (open it with: rerun FILE.rrd)")
    view.add_argument("--grpc-port", type=int, default=DEFAULT_GRPC_PORT, help="--web: gRPC port (default: %(default)s)")
    view.add_argument("--web-port", type=int, default=DEFAULT_WEB_PORT, help="--web: page port (default: %(default)s)")
    view.add_argument("--duration", type=float, metavar="S", help="live: stop after S seconds")
    view.set_defaults(func=cmd_view)


def _interrupt(signum: int, frame: object) -> None:
    """SIGTERM ends ``dualarm view`` like Ctrl-C (the web viewer's server is then stopped)."""
    raise KeyboardInterrupt


def _has_display() -> bool:
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def cmd_view(args: argparse.Namespace) -> int:
    """``dualarm view``: log the bag or the live cell to the chosen sinks."""
    try:
        import rerun as rr
    except ImportError:
        raise DualArmError("the Rerun viewer is not installed: pip install 'dualarm_control[view]'") from None
    from dualarm_control.app.view import rerun_view as rv
    from dualarm_control.app.view.server import WebViewer

    if not args.web and not args.save and not _has_display():
        print("dualarm view: no display for the native viewer. Use --web (open the printed URL in a browser) or "
              "--save FILE.rrd (then: rerun FILE.rrd on a machine with a display).", file=sys.stderr)
        return NO_VIEWER
    arrays = None
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

            model = DualArmModel()
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
