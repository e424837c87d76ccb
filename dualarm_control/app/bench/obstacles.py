"""``dualarm bench --obstacles N``: what live obstacles cost the control cycle, and a point cloud's intake
(issue 42; docs/obstacles.md).

* Cycle: the assembly task is run once in one process; its recorded joint states and targets are
  replayed through two controllers per solver, one with N live obstacles (spheres, boxes and
  cylinders scattered around the arms' path) and one without, interleaved case by case (the order
  alternating), so both see the same machine at the same moment; p50/p99 and their ratios. Three
  scenes: the obstacles at least 3.5 cm from every link along the path (about 6 pairs within d_i
  every cycle: what avoiding them costs), at least 12 cm (none in reach: what having them costs), and
  the first scene's obstacles swinging 1 cm, a new snapshot every cycle (what moving obstacles cost:
  markers that move, as a node's intake publishes them, untimed, before each cycle).
* Cloud: a 100,000-point PointCloud2 (a table top and three boxes seen from above, 2 cm voxels)
  taken in by the intake's worker from its CDR bytes (read, voxelise, octree): p50/p99 over
  repetitions, in control periods, wall clock and the worker thread's CPU time (the wall clock
  includes the waits for a core on a loaded machine); and what the executor's callback costs (a
  queue append).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import coal
import numpy as np

from dualarm_control.app.bench.collision import interleaved_cycles, replay_cases
from dualarm_control.collision.live import LiveDistances, LiveObstacle
from dualarm_control.controller import ControllerParams, RelativeController
from dualarm_control.errors import DualArmError
from dualarm_control.kinematics import DualArmModel
from dualarm_control.metrics import percentiles
from dualarm_control.scenario import load_scenario

NEAR, FAR = 0.035, 0.12
"""m: the scattered obstacles stay at least this far from every link along the replayed run: NEAR, many
pairs within the influence distance d_i (0.10 m + 2 shape margins) every cycle (the limit's rows, its
coal calls); FAR, none within d_i (what having them costs when they are out of reach)."""
CLOUD_POINTS = 100_000
MOVE_AMPLITUDE, MOVE_PERIOD = 0.01, 2.0
"""m, s: the moving scene's obstacles swing 1 cm about their places (still >= 2.5 cm from the path), every 2 s."""


def scattered_obstacles(count: int, distances: LiveDistances, path: np.ndarray, seed: int = 0,
                        clearance: float = NEAR) -> list[LiveObstacle]:
    """``count`` obstacles around the LWR4 cell's workspace (x 0.3-1.3, y -0.6-0.6, z 0.9-1.8 m), each at
    least ``clearance`` [m] from every link at every configuration of ``path`` (k, n) [rad] (every 20th)."""
    rng = np.random.default_rng(seed)
    out: list[LiveObstacle] = []
    rows = path[::20]
    while len(out) < count:
        kind = len(out) % 3
        size = rng.uniform(0.03, 0.08)
        shape = (coal.Sphere(size) if kind == 0 else coal.Box(size, size * 1.5, size * 2) if kind == 1
                 else coal.Cylinder(size / 2, size * 3))
        candidate = LiveObstacle.make(f"o{len(out)}", shape, np.eye(3),
                                      rng.uniform([0.3, -0.6, 0.9], [1.3, 0.6, 1.8]))
        if all(not len(pairs) or pairs.distance.min() >= clearance
               for pairs in (distances.near(q, [candidate], clearance) for q in rows)):
            out.append(candidate)
    return out


def interleaved(on: RelativeController, off: RelativeController, cases: Sequence[tuple[Any, Any]],
                before: Callable[[int], None] | None = None) -> dict[str, Any]:
    """Each case's cycle through ``on`` (with live obstacles) and ``off``, the order alternating: p50/p99 [ms],
    their ratios, the median of the per-cycle ratios (each case with over without: the same cycle, paired), the live
    obstacle rows per cycle.

    The two ratios differ where the cycle without obstacles is bimodal (the assembly's: 39 % of its cycles have no
    collision row, 0.07 against 0.19 ms): the ratio of the p50s then moves with where the p50 falls between the two
    modes (1.30-1.47 in four passes of one process), the paired median does not (1.29-1.30)."""
    with_obstacles, without, near = interleaved_cycles(on, off, cases, "live_obstacles", before)
    (on50, on99), (off50, off99) = percentiles(with_obstacles), percentiles(without)
    return {"cycles": len(cases), "rows_mean": float(near.mean()), "cycles_with_rows": int(np.count_nonzero(near)),
            "with_p50_ms": on50 * 1e3, "with_p99_ms": on99 * 1e3, "without_p50_ms": off50 * 1e3,
            "without_p99_ms": off99 * 1e3, "ratio_p50": on50 / off50, "ratio_p99": on99 / off99,
            "paired_ratio_p50": float(np.median(with_obstacles / without))}


def bench_live_obstacles(count: int, solvers: Sequence[str], progress: Callable[[str], None] | None = None,
                         scenario_name: str = "assembly") -> dict[str, dict[str, Any]]:
    """Rows "solver": cycle times [ms] with ``count`` live obstacles and without, their ratios, the rows per cycle."""
    scenario = load_scenario(scenario_name)
    model = DualArmModel(scenario.robot)
    if progress:
        progress(f"obstacles: {scenario_name} (recording the states to replay)")
    cases = replay_cases(scenario, model)
    rows: dict[str, dict[str, Any]] = {}
    for solver in solvers:
        for clearance, moving in ((NEAR, False), (FAR, False), (NEAR, True)):
            params = scenario.controller_params(ControllerParams(solver=solver))
            on = RelativeController(model, replace(params, collision=replace(params.collision, live_obstacles=count)))
            off = RelativeController(model, params)
            limit: Any = on.limit("live_obstacles")
            obstacles = scattered_obstacles(count, limit.distances, np.array([q for q, _ in cases]), clearance=clearance)
            limit.feed.publish(tuple(obstacles))
            snapshots = moving_snapshots(obstacles, len(cases), params.period) if moving else None
            scene = f">= {clearance * 100:g} cm" + (", moving" if moving else "")
            if progress:
                progress(f"obstacles: {solver}, {len(cases)} cycles with {count} live obstacles {scene} from the path "
                         "and without")
            before = None if snapshots is None else (lambda k, s=snapshots, f=limit.feed: f.publish(s[k]))
            rows[f"{solver} | {scene}"] = {"obstacles": count, "clearance_m": clearance, "moving": moving,
                                           **interleaved(on, off, cases, before)}
    return rows


def moving_snapshots(obstacles: Sequence[LiveObstacle], cycles: int, period: float, amplitude: float = MOVE_AMPLITUDE,
                     seconds: float = MOVE_PERIOD) -> list[tuple[LiveObstacle, ...]]:
    """One snapshot per cycle: each obstacle swinging about its place along its own random direction, ``amplitude``
    [m] over ``seconds`` [s], with its velocity [m/s] (what a node's intake publishes for markers that move every
    cycle: the same shape objects, new poses)."""
    rng = np.random.default_rng(1)
    directions = rng.normal(size=(len(obstacles), 3))
    directions /= np.linalg.norm(directions, axis=1)[:, None]
    omega = 2.0 * np.pi / seconds
    out = []
    for k in range(cycles):
        phase = omega * k * period
        out.append(tuple(o.moved(o.position + amplitude * math.sin(phase) * d,
                                 amplitude * omega * math.cos(phase) * d) for o, d in zip(obstacles, directions)))
    return out


def cloud_bytes(points: int = CLOUD_POINTS, seed: int = 0) -> bytes:
    """A serialized PointCloud2 (frame ``world``) of ``points`` points: 60 % on a 1.2 x 1.2 m table top at
    z = 0.8 m, the rest on the tops and sides of three boxes standing on it."""
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import PointCloud2, PointField

    rng = np.random.default_rng(seed)
    table = int(points * 0.6)
    xyz = np.empty((points, 3), dtype=np.float32)
    xyz[:table] = np.c_[rng.uniform(0.3, 1.5, table), rng.uniform(-0.6, 0.6, table), np.full(table, 0.8)]
    rest = points - table
    centres = np.array([[0.6, -0.3, 0.9], [0.9, 0.2, 0.95], [1.2, -0.1, 0.85]])
    box = rng.integers(0, 3, rest)
    xyz[table:] = centres[box] + rng.uniform(-0.1, 0.1, (rest, 3))
    msg = PointCloud2()
    msg.header.frame_id = "world"
    msg.height, msg.width = 1, points
    msg.fields = [PointField(name=c, offset=4 * i, datatype=PointField.FLOAT32, count=1) for i, c in enumerate("xyz")]
    msg.point_step, msg.row_step, msg.is_dense = 12, 12 * points, True
    msg.data = xyz.tobytes()
    return bytes(serialize_message(msg))


def bench_cloud(period: float, repetitions: int = 30, points: int = CLOUD_POINTS) -> dict[str, Any]:
    """The intake of a ``points``-point cloud: the worker's time p50/p99 [ms] and in control periods
    (``period`` [s]), the executor callback's [us], the voxels it gave."""
    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import PointCloud2

    from dualarm_control.collision.live_feed import LiveObstacleFeed
    from dualarm_control.ros.obstacle_io import ObstacleIntake, fixed_frames

    model = DualArmModel("lwr4_cell")
    intake = ObstacleIntake(LiveObstacleFeed(1), fixed_frames(model.model), lambda text: None,
                            lambda data, kind: deserialize_message(data, PointCloud2))
    data = cloud_bytes(points)
    append = np.empty(repetitions)
    for k in range(repetitions):
        start = time.perf_counter()
        intake.on_cloud(data)
        append[k] = time.perf_counter() - start
        intake.process()
    worker = np.array(intake.cloud_seconds)
    (w50, w99), (a50, a99) = percentiles(worker), percentiles(append)
    c50, c99 = percentiles(np.array(intake.cloud_cpu_seconds))
    octree = intake.scene.feed.snapshot()[0].shape
    return {"points": points, "repetitions": repetitions, "worker_p50_ms": w50 * 1e3, "worker_p99_ms": w99 * 1e3,
            "worker_p50_periods": w50 / period, "worker_p99_periods": w99 / period,
            "worker_cpu_p50_ms": c50 * 1e3, "worker_cpu_p99_ms": c99 * 1e3,
            "executor_p50_us": a50 * 1e6, "executor_p99_us": a99 * 1e6,
            "voxels": len(np.asarray(octree.toBoxes())), "period_ms": period * 1e3}


def format_obstacle_bench(rows: dict[str, dict[str, Any]], cloud: dict[str, Any]) -> str:
    """The two tables as Markdown."""
    lines = [("| solver, obstacles' clearance | obstacles | rows/cycle | with p50 / p99 [ms] | without p50 / p99 [ms] "
              "| ratio p50 / p99 | per-cycle ratio p50 |"),
             "|---|---:|---:|---|---|---|---:|"]
    for solver, r in rows.items():
        paired = f"{r['paired_ratio_p50']:.2f}x" if "paired_ratio_p50" in r else "-"
        lines.append(f"| {solver} | {r['obstacles']} | {r['rows_mean']:.2f} | {r['with_p50_ms']:.3f} / "
                     f"{r['with_p99_ms']:.3f} | {r['without_p50_ms']:.3f} / {r['without_p99_ms']:.3f} | "
                     f"{r['ratio_p50']:.2f}x / {r['ratio_p99']:.2f}x | {paired} |")
    lines += ["", ("| cloud | voxels | worker p50 / p99 [ms] | in periods (T = "
              f"{cloud['period_ms']:g} ms) | worker CPU p50 / p99 [ms] | executor callback p50 / p99 [us] |"),
              "|---:|---:|---|---|---|---|",
              (f"| {cloud['points']} points | {cloud['voxels']} | {cloud['worker_p50_ms']:.2f} / "
              f"{cloud['worker_p99_ms']:.2f} | {cloud['worker_p50_periods']:.2f} / {cloud['worker_p99_periods']:.2f} | "
              f"{cloud['worker_cpu_p50_ms']:.2f} / {cloud['worker_cpu_p99_ms']:.2f} | "
              f"{cloud['executor_p50_us']:.1f} / {cloud['executor_p99_us']:.1f} |")]
    return "\n".join(lines)


def run_obstacle_bench(count: int, solvers: Sequence[str], output: Path) -> int:
    """``dualarm bench --obstacles N``: both parts, printed and written to ``output``/obstacles.md and .json."""
    import json
    import sys

    if count < 1:
        raise DualArmError(f"--obstacles {count}: expected a number of obstacles >= 1")
    from dualarm_control.collision.params import MAX_LIVE_OBSTACLES

    if count > MAX_LIVE_OBSTACLES:
        raise DualArmError(f"--obstacles {count}: at most {MAX_LIVE_OBSTACLES} (collision.live_obstacles)")
    rows = bench_live_obstacles(count, solvers, lambda text: print(f"[bench] {text}", file=sys.stderr, flush=True))
    cloud = bench_cloud(ControllerParams().period)
    text = format_obstacle_bench(rows, cloud)
    output.mkdir(parents=True, exist_ok=True)
    (output / "obstacles.md").write_text(text + "\n")
    (output / "obstacles.json").write_text(json.dumps({"cycle": rows, "cloud": cloud}, indent=2) + "\n")
    print(text)
    print(f"\nwrote {output / 'obstacles.md'} and obstacles.json")
    return 0
