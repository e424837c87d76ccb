"""A video of a recorded run, without any viewer: ``dualarm view BAG --video run.mp4``.

The cell (:class:`dualarm_sim.cell.DualArmCell`, the bag's URDF) is posed at the bag's joint
states resampled on the video clock and drawn by pybullet's offscreen renderer (DIRECT client,
``ER_TINY_RENDERER``, no GPU, no display); the frames are encoded to H.264 by the ffmpeg that
ships in the imageio-ffmpeg wheel (extra ``view``).

Video clock: frame k shows the joint state at t_k = k / fps after the first joint state
(linear interpolation per joint), k = 0 .. floor(duration x fps), so a run of ``duration``
seconds gives floor(duration x fps) + 1 frames.
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Final, TextIO

import numpy as np
import numpy.typing as npt

from dualarm_control.app.view.obstacles_view import CameraObstacles, ObstacleTrack
from dualarm_control.app.view.options import DEFAULT_FPS, DEFAULT_SIZE
from dualarm_control.app.view.recording import JointRecording, read_joint_recording
from dualarm_control.arrays import FloatArray
from dualarm_control.errors import DualArmError
from dualarm_control.obstacles import AttachedBox

CAMERA_EYE: Final = (2.1, -1.6, 1.6)
"""Camera position [m] in the world: in front of and to the right of the cell, above the torso."""
CAMERA_TARGET: Final = (0.5, 0.0, 0.75)
"""Point the camera looks at [m]: between both arms' workspaces."""
FIELD_OF_VIEW_DEG: Final = 45.0
PROGRESS_EVERY_S: Final = 2.0


class VideoError(DualArmError):
    """A video cannot be written (imageio-ffmpeg missing, bad size or fps)."""


@dataclass(frozen=True)
class VideoInfo:
    """What :func:`render_video` wrote.

    Attributes:
        path: the video file.
        frames: number of frames, floor(duration_s x fps) + 1.
        fps: frames per second of the video clock.
        size: (width, height) [px].
        duration_s: the run's duration (first to last joint state) [s].
        render_s: time spent posing and rendering [s] (wall clock).
        encode_s: time spent in the encoder [s] (wall clock).
    """

    path: Path
    frames: int
    fps: float
    size: tuple[int, int]
    duration_s: float
    render_s: float
    encode_s: float

    @property
    def render_ms_per_frame(self) -> float:
        return 1e3 * self.render_s / self.frames


def frame_times(duration_s: float, fps: float) -> npt.NDArray[np.float64]:
    """Times [s] after the first joint state of the video's frames: k / fps, k = 0 .. floor(duration x fps)."""
    n = math.floor(duration_s * fps + 1e-9) + 1
    return np.arange(n) / fps


class CellCamera:
    """The cell in a DIRECT pybullet client and a fixed camera looking at both arms."""

    def __init__(self, urdf_text: str, size: tuple[int, int], joint_names: tuple[str, ...] = (),
                 obstacles: dict[str, ObstacleTrack] | None = None, held: AttachedBox | None = None,
                 box_poses: Mapping[int, FloatArray] | None = None) -> None:
        import pybullet as p

        from dualarm_sim.cell import DualArmCell
        from dualarm_sim.cell_config import CellConfig

        width, height = size
        if width <= 0 or height <= 0 or width % 2 or height % 2:
            raise VideoError(f"video size {width}x{height}: width and height must be even and positive")
        self._p = p
        self.size = size
        with tempfile.TemporaryDirectory(prefix="dualarm_video_") as tmp:
            path = Path(tmp) / "robot_description.urdf"
            path.write_text(urdf_text)
            self.cell = DualArmCell(CellConfig(urdf=path, joints=joint_names, visual_shapes=True))  # posed by name: q in that order
        self.lower, self.upper = self.cell.position_limits
        self.obstacles = CameraObstacles(obstacles or {}, self.cell.client_id)  # the bag's scene, drawn
        self._view = p.computeViewMatrix(CAMERA_EYE, CAMERA_TARGET, (0.0, 0.0, 1.0))
        self._projection = p.computeProjectionMatrixFOV(FIELD_OF_VIEW_DEG, width / height, 0.05, 20.0)
        self.held, self._box = held, None
        # the simulator's box where it was (a bag's /held_object/pose by stamp): on its support before the grasp
        # and after the release; else drawn on its frame
        self._box_stamps = np.array(sorted(box_poses or {}), dtype=np.int64)
        self._box_poses = dict(box_poses or {})
        if held is not None:  # a held object: a box drawn on its frame (no collision shape: it is only drawn)
            visual = p.createVisualShape(p.GEOM_BOX, halfExtents=[0.5 * s for s in held.size],
                                         rgbaColor=(0.2, 0.5, 0.9, 1), physicsClientId=self.cell.client_id)
            self._box = p.createMultiBody(0.0, -1, visual, physicsClientId=self.cell.client_id)

    def render(self, q: npt.NDArray[np.float64], stamp_ns: int | None = None) -> npt.NDArray[np.uint8]:
        """The cell at joint positions q [rad] (clipped to the URDF limits) as RGB, (height, width, 3); the
        moving obstacles where they were at ``stamp_ns`` (the joint states' clock) when given."""
        p = self._p
        self.cell.reset(np.clip(q, self.lower, self.upper))
        if stamp_ns is not None:
            self.obstacles.place(stamp_ns)
        if self._box is not None and stamp_ns is not None and len(self._box_stamps):
            i = max(int(np.searchsorted(self._box_stamps, stamp_ns, side="right")) - 1, 0)
            pose = self._box_poses[int(self._box_stamps[i])]
            p.resetBasePositionAndOrientation(self._box, pose[:3].tolist(), pose[3:].tolist(),
                                              physicsClientId=self.cell.client_id)
        elif self.held is not None and self._box is not None:
            position, rotation = self.cell.link_pose(self.held.frame)
            centre = position + rotation @ np.asarray(self.held.position, dtype=float)
            import pinocchio as pin

            quaternion = pin.Quaternion(rotation @ self.held.rotation)
            p.resetBasePositionAndOrientation(self._box, centre.tolist(), (quaternion.x, quaternion.y, quaternion.z,
                                                                           quaternion.w),
                                              physicsClientId=self.cell.client_id)
        width, height = self.size
        _, _, rgba, _, _ = p.getCameraImage(width, height, self._view, self._projection, shadow=0,
                                            renderer=p.ER_TINY_RENDERER, physicsClientId=self.cell.client_id)
        return np.asarray(rgba, dtype=np.uint8).reshape(height, width, 4)[:, :, :3]

    def close(self) -> None:
        self.cell.close()


def render_recording(recording: JointRecording, out_path: Path, fps: float = DEFAULT_FPS,
                     size: tuple[int, int] = DEFAULT_SIZE, log: TextIO | None = sys.stderr,
                     held: AttachedBox | None = None, box_poses: Mapping[int, FloatArray] | None = None) -> VideoInfo:
    """Encode ``recording`` as an H.264 MP4 at ``out_path`` (module docstring); progress on ``log``; ``held``: a
    held object's box, drawn on its frame."""
    try:
        import imageio_ffmpeg
    except ImportError as exc:
        raise VideoError("a video needs imageio-ffmpeg: pip install 'dualarm_control[view]'") from exc
    if not (math.isfinite(fps) and fps > 0):
        raise VideoError(f"fps={fps!r} must be a positive number")
    times = frame_times(recording.duration_s, fps)
    positions = recording.at(times)
    out_path = Path(out_path)
    out_path.parent.mkdir(parents=True, exist_ok=True)
    camera = CellCamera(recording.urdf_text, size, recording.joint_names, recording.obstacles, held, box_poses)
    writer = imageio_ffmpeg.write_frames(str(out_path), size, fps=fps, codec="libx264", macro_block_size=2,
                                         ffmpeg_log_level="error")
    render_s = encode_s = 0.0
    next_progress = time.monotonic() + PROGRESS_EVERY_S
    try:
        writer.send(None)  # start ffmpeg
        for k, q in enumerate(positions):
            t0 = time.perf_counter()
            image = camera.render(q, int(recording.stamps_ns[0] + times[k] * 1e9))
            t1 = time.perf_counter()
            writer.send(np.ascontiguousarray(image))
            render_s += t1 - t0
            encode_s += time.perf_counter() - t1
            if log is not None and time.monotonic() >= next_progress:
                print(f"video: frame {k + 1}/{len(times)}", file=log, flush=True)
                next_progress = time.monotonic() + PROGRESS_EVERY_S
        t1 = time.perf_counter()
        writer.close()
        encode_s += time.perf_counter() - t1
    finally:
        camera.close()
    info = VideoInfo(out_path, len(times), fps, size, recording.duration_s, render_s, encode_s)
    if log is not None:
        print(f"video: {out_path} ({info.frames} frames, {size[0]}x{size[1]} at {fps:g} fps, "
              f"{info.duration_s:.2f} s run; render {info.render_ms_per_frame:.1f} ms/frame, encode {encode_s:.2f} s, "
              f"{out_path.stat().st_size / 1024:.0f} KiB)", file=log, flush=True)
    return info


def render_video(bag_path: Path, out_path: Path, fps: float = DEFAULT_FPS, size: tuple[int, int] = DEFAULT_SIZE,
                 log: TextIO | None = sys.stderr) -> VideoInfo:
    """Render the run recorded in ``bag_path`` (its /joint_states and /robot_description) to an MP4.

    Args:
        bag_path: rosbag2 directory holding /joint_states (and /robot_description; else the package's cell).
        out_path: the .mp4 to write (its directory is created).
        fps: frames per second of the video clock (joint states resampled on it).
        size: (width, height) [px], both even.
        log: progress and the summary line (None: quiet).

    Returns:
        :class:`VideoInfo` (frames, render and encode times). Raises BagError (no joint states)
        or VideoError.
    """
    held = held_box(Path(bag_path))
    return render_recording(read_joint_recording(Path(bag_path)), Path(out_path), fps, size, log, held,
                            box_poses(Path(bag_path)) if held is not None else None)


def held_box(bag_path: Path) -> AttachedBox | None:
    """The held object of the task scenario a bag ran (its controller's /diagnostics name it), None without one
    or when that scenario cannot be loaded here."""
    from dualarm_control.app.record.bag import SCENARIO_KEY, read_bag
    from dualarm_control.scenario import load_scenario

    try:
        bag = read_bag(bag_path)
        name = next((v[SCENARIO_KEY] for _, v in bag.task_cycles if v.get(SCENARIO_KEY)), "")
        bodies = load_scenario(name).held_bodies if name else ()
    except DualArmError:
        return None
    return bodies[0] if bodies else None


def box_poses(bag_path: Path) -> dict[int, FloatArray]:
    """The simulator's held box in the world by stamp [ns] (``/held_object/pose``: x, y, z, qx, qy, qz, qw), {}
    when the bag has none."""
    from dualarm_control.app.record.bag import read_bag

    try:
        return dict(read_bag(bag_path).object_poses)
    except DualArmError:
        return {}


def video_from_args(bag: str | None, args: argparse.Namespace) -> int:
    """Handle ``--video`` (after :func:`dualarm_control.app.view.options.add_video_arguments`): render ``bag`` to ``args.video``; 0 on success."""
    if bag is None:
        raise VideoError("--video renders a recorded run: name the BAG")
    render_video(Path(bag), Path(args.video), fps=args.fps, size=args.size, log=sys.stderr)
    return 0
