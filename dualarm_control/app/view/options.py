"""The ``dualarm view`` options that its parser adds and the viewers read (defaults, ``--size``), apart from
the viewers: ``dualarm --help`` builds every verb's parser, and these import nothing heavy (no pybullet,
pinocchio, rosbags or foxglove)."""

from __future__ import annotations

import argparse
from typing import Any, Final

DEFAULT_FPS: Final = 25.0
DEFAULT_SIZE: Final = (640, 480)
DEFAULT_FOXGLOVE_PORT: Final = 8765


def parse_size(text: str) -> tuple[int, int]:
    """``WIDTHxHEIGHT`` -> (width, height)."""
    try:
        width, height = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"size {text!r} is not WIDTHxHEIGHT, e.g. 640x480") from None
    return width, height


def add_video_arguments(parser: argparse._ActionsContainer) -> None:
    """``--video FILE.mp4``, ``--fps`` and ``--size`` on a verb taking a BAG (``dualarm view``)."""
    parser.add_argument("--video", metavar="FILE.mp4",
                        help="render the bag's run to an MP4 with pybullet's offscreen renderer (no viewer)")
    parser.add_argument("--fps", type=float, default=DEFAULT_FPS,
                        help="video frames per second; joint states resampled on that clock (default: %(default)g)")
    parser.add_argument("--size", type=parse_size, default=DEFAULT_SIZE, metavar="WxH",
                        help="video size in pixels, both even (default: 640x480)")


def add_foxglove_arguments(parser: Any) -> None:
    """``--foxglove``, ``--foxglove-port`` and ``--speed`` on a verb taking a BAG (``dualarm view``)."""
    parser.add_argument("--foxglove", action="store_true",
                        help="serve the run over the Foxglove WebSocket protocol (Foxglove app: Open connection, "
                        "Foxglove WebSocket, ws://127.0.0.1:PORT)")
    parser.add_argument("--foxglove-port", type=int, default=DEFAULT_FOXGLOVE_PORT, metavar="PORT",
                        help="port of the Foxglove WebSocket server (default: %(default)s)")
    parser.add_argument("--speed", type=float, default=1.0, help="replay speed of a bag (default: %(default)g)")


