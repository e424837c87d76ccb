"""``dualarm view``: what goes to Rerun, read back from a saved .rrd, and the web viewer in a real browser.

The run is a real one: the short scenario (test/data/short.yaml, 4 cm and 15 degrees)
in-process in lockstep with sparse_qp, the same runner as ``dualarm experiment``. The
browser test serves it with ``rerun --serve-web`` on 127.0.0.1 and opens the page in
headless Chromium over the DevTools protocol (skipped, saying why, without /usr/bin/chromium).
Set ``DUALARM_VIEW_SCREENSHOT=PATH.png`` to keep its screenshot (docs/visualization_web_viewer.png).
"""

from __future__ import annotations

import io
import os
import sys
import time
import xml.etree.ElementTree as ET
from collections import Counter
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from chromium import Chromium, free_port
from waiting import wait_until

rr = pytest.importorskip("rerun", reason="rerun-sdk not installed (the view extra)")

from dualarm_control.app import cli
from dualarm_control.app.run.experiment import run_scenario
from dualarm_control.app.view import rerun_view as rv
from dualarm_control.app.view.from_bag import (
    RunArrays,
    record_arrays,
    relative_run_arrays,
)
from dualarm_control.app.view.live import LiveLog
from dualarm_control.app.view.server import WebViewer
from dualarm_control.controller_params import controller_params
from dualarm_control.kinematics import DualArmModel
from dualarm_control.ros.convert import quaternion_xyzw
from dualarm_control.scenario import load_scenario

REPO = Path(__file__).resolve().parents[1]
SHORT = REPO / "test" / "data" / "short.yaml"
CHROMIUM = Path("/usr/bin/chromium")


# ----------------------------------------------------------------------------- a real run, as arrays


@pytest.fixture(scope="module")
def short_run() -> RunArrays:
    scenario, model = load_scenario(str(SHORT)), DualArmModel()
    log = run_scenario(scenario, controller_params({"solver": "sparse_qp"}), model)
    trajectory = scenario.trajectory(*model.relative_pose(log.positions[0]))
    target = np.array([[*s.position, *quaternion_xyzw(s.rotation)] for s in map(trajectory.sample, log.time)])
    return record_arrays(log, model, {"relative_target": target})


def read_rrd(path: Path) -> tuple[Counter[str], dict[str, np.ndarray]]:
    """Rows per entity on the ``time`` timeline (static entities: rows without it) and the scalars per entity."""
    from rerun.chunk import RrdReader

    rows: Counter[str] = Counter()
    scalars: dict[str, list[float]] = {}
    for chunk in RrdReader(str(path)).stream():
        if chunk.is_static or rv.TIMELINE in chunk.timeline_names:
            rows[chunk.entity_path] += chunk.num_rows
        batch = chunk.to_record_batch()
        if "Scalars:scalars" in batch.schema.names:
            for cell in batch.column("Scalars:scalars").to_pylist():
                scalars.setdefault(chunk.entity_path, []).extend(cell)
    return rows, {k: np.array(v) for k, v in scalars.items()}


def visual_links(urdf: Path) -> list[str]:
    return [link.get("name", "") for link in ET.parse(urdf).getroot().iter("link") if link.find("visual") is not None]


def save(arrays: RunArrays, path: Path) -> None:
    rec = rr.RecordingStream(rv.APPLICATION_ID)
    rec.save(str(path))
    arrays.log(rec)
    rec.flush()
    rec.disconnect()


# ----------------------------------------------------------------------------- the saved recording


def test_saved_rrd_holds_every_link_and_one_value_per_cycle(short_run: RunArrays, tmp_path: Path) -> None:
    path = tmp_path / "run.rrd"
    save(short_run, path)
    rows, scalars = read_rrd(path)
    n = len(short_run.stamps)
    robot = rv.robot_name(short_run.urdf)
    links = visual_links(short_run.urdf)
    assert len(links) == 25  # torso, per arm link_0..7 and the flange, the peg and hole's 6 bodies
    for link in links:
        assert rows[f"/{robot}/visual_geometries/{link}/visual_0"] > 0, link
    for joint in short_run.joint_names:
        assert rows[f"/joint_tf/{joint}"] == n, joint
    assert rows["/frames/relative_target/pose"] == n
    for name, values in short_run.series.items():
        np.testing.assert_allclose(scalars[f"/plot/{name}"], values, rtol=0, atol=0, err_msg=name)
    # Fig. 5's ||qd||_0 is the count of |qd_i| > 1e-3 rad/s: the run moves, and not with every joint all the time
    l0 = scalars[f"/plot/{rv.VELOCITY_L0}"]
    assert l0.max() > 0 and set(np.unique(l0)) <= set(range(15))
    changes = sum(a != b for a, b in zip(short_run.statuses, short_run.statuses[1:])) + 1  # type: ignore[arg-type]
    assert rows[f"/{rv.STATUS_ENTITY}"] == changes


def test_log_run_refuses_arrays_of_other_lengths(short_run: RunArrays) -> None:
    rec = rr.RecordingStream(rv.APPLICATION_ID)
    rec.memory_recording()
    with pytest.raises(ValueError, match="stamps"):
        rv.log_run(short_run.urdf, short_run.stamps[:-1], short_run.q, short_run.joint_names, {}, recording=rec)


# ----------------------------------------------------------------------------- bags and the live view


def test_bag_adapter_is_per_controller_cycle(tmp_path: Path) -> None:
    sys.path.insert(0, str(REPO / "test"))
    from test_bag import N_CYCLES, write_synthetic_bag

    bag = tmp_path / "synthetic"
    write_synthetic_bag(bag)
    arrays = relative_run_arrays(bag, DualArmModel())
    k = np.arange(N_CYCLES)
    np.testing.assert_allclose(arrays.stamps, k * 0.01)  # the cycles' stamp_ns, 10 ms apart
    np.testing.assert_array_equal(arrays.series[rv.VELOCITY_L0], k % 4 + 1)  # joint 13 at 5e-4 rad/s is inactive
    np.testing.assert_allclose(arrays.series[rv.CYCLE_TIME], 0.001 * (k + 1))
    np.testing.assert_allclose(arrays.frames["relative_target"][0, :3], [0.1, 0.2, 0.3])
    assert arrays.q.shape == (N_CYCLES, 14) and arrays.statuses is not None and arrays.statuses[3] == "infeasible"
    out = tmp_path / "bag.rrd"
    assert cli.main(["view", str(bag), "--save", str(out)]) == 0
    rows, _ = read_rrd(out)
    assert rows["/joint_tf/left_joint_1"] == N_CYCLES


def test_view_without_display_or_sink_says_what_to_do(monkeypatch: pytest.MonkeyPatch,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    assert cli.main(["view"]) == 2
    assert "--web" in capsys.readouterr().err


def test_live_log_batches_the_cells_messages(short_run: RunArrays, tmp_path: Path) -> None:
    """The live view's decoding and batching, fed with the CDR bytes the nodes publish."""
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.serialization import deserialize_message

    from dualarm_control.ros import convert

    model = DualArmModel()
    rec = rr.RecordingStream(rv.APPLICATION_ID)
    path = tmp_path / "live.rrd"
    rec.save(str(path))
    live = LiveLog(model, rec)
    states = convert.JointStateInput({name: i for i, name in enumerate(model.joint_names)})
    commands = convert.CommandInput(model.nq)
    n, t0 = 30, 5 * convert.NS
    for k in range(n):
        ns = t0 + k * 5_000_000
        live.joint_state(states.from_bytes(convert.joint_state(model.joint_names, ns, short_run.q[k], np.zeros(14))))
        live.command(commands.from_bytes(convert.float_array(np.full(14, 0.01 * (k % 3)))))
        live.diagnostics(deserialize_message(convert.diagnostics(ns, "controller_node", 0, "ok", {
            "status": "solved" if k < 20 else "infeasible", "stamp_ns": ns, "cycle_time_s": 1e-3,
            "solve_time_s": 5e-4, "position_error_m": 1e-4, "orientation_error_rad": 1e-3}), DiagnosticArray))
        if k % 10 == 9:
            live.flush()
    rec.flush()
    rec.disconnect()
    rows, scalars = read_rrd(path)
    assert rows["/joint_tf/right_joint_7"] == n
    np.testing.assert_array_equal(scalars[f"/plot/{rv.VELOCITY_L0}"], [14 * (k % 3 > 0) for k in range(n)])
    np.testing.assert_allclose(scalars[f"/plot/{rv.SOLVE_TIME}"], 5e-4)
    assert rows[f"/{rv.STATUS_ENTITY}"] == 2  # solved, then the change to infeasible


# ----------------------------------------------------------------------------- a real browser


VIEW_REGION = (slice(80, 480), slice(0, 740))
"""Page pixels (rows, columns) inside the 3D view of the blueprint at 1280x800."""
DRAWN_PIXELS = 1000
"""Pixels of the 3D view that must differ from its white background by more than 0.25 (the empty
view's grid lines differ by less than 0.15: 0 such pixels; the cell: about 2700)."""
ARM_PIXELS = 200
"""Orange pixels (red - blue > 0.25: the arms' links, URDF colour 0.9 0.5 0.1) the 3D view must show."""
MOVED_PIXELS = 100
"""Pixels of the 3D view that must change between the first and the last cycle."""
POLL_S = 5.0
LOAD_TIMEOUT_S = 300.0


def image(png: bytes) -> np.ndarray:
    import matplotlib.image

    return np.asarray(matplotlib.image.imread(io.BytesIO(png), format="png"))[..., :3]


def drawn_pixels(img: np.ndarray) -> int:
    return int(np.count_nonzero(np.abs(img[VIEW_REGION] - 1.0).max(axis=-1) > 0.25))


def orange_pixels(img: np.ndarray) -> int:
    view = img[VIEW_REGION]
    return int(np.count_nonzero(view[..., 0] - view[..., 2] > 0.25))


def shows_arms(img: np.ndarray) -> bool:
    return drawn_pixels(img) >= DRAWN_PIXELS and orange_pixels(img) >= ARM_PIXELS


def changed_pixels(a: np.ndarray, b: np.ndarray) -> int:
    return int(np.count_nonzero(np.abs(a[VIEW_REGION] - b[VIEW_REGION]).max(axis=-1) > 0.1))


def load(browser: Chromium, url: str, deadline: float, keep: Path,
         also: Callable[[np.ndarray], bool] | None = None, what: str = "") -> tuple[bytes, np.ndarray]:
    """Open ``url``; poll screenshots until the 3D view shows the arms (and ``also`` holds of the
    image, when given: a part of the recording that the page may draw after the arms): the PNG (also
    written to ``keep``) and its image. Fails with the pixel counts of the last screenshot at
    ``deadline``."""
    browser.navigate(url)
    browser.screenshot()  # warm-up: blocks while the page first draws (tens of seconds)
    shots: list[bytes] = []

    def drawn() -> tuple[bytes, np.ndarray] | None:
        shots.append(browser.screenshot())
        keep.write_bytes(shots[-1])
        img = image(shots[-1])
        return (shots[-1], img) if shows_arms(img) and (also is None or also(img)) else None

    def last() -> str:
        img = image(shots[-1])
        return (f"{drawn_pixels(img)} drawn, {orange_pixels(img)} orange and {red_pixels(img)} red pixels in "
                f"the 3D view; screenshot: {keep}")

    return wait_until(drawn, last, what=f"the arms{what} in the 3D view of {url}", interval=POLL_S,
                      timeout=max(0.0, deadline - time.monotonic()))


def test_web_viewer_shows_the_arms_in_chromium(short_run: RunArrays, tmp_path: Path) -> None:
    """The served viewer of the run shows the arms; at the first cycle they are elsewhere than at the last.

    The viewer opens a recording at its latest time (it follows the data): the last cycle. Rerun
    0.41 has no time-cursor field in the blueprint, and the Home key (tried) does not move it; so
    the start is shown by serving the same run cut after its first cycle (latest time = 0 s), on
    a second server, in the same browser.
    """
    if not CHROMIUM.exists():
        reason = f"{CHROMIUM} missing: apt-get install chromium (.ci/run does, as root)"
        print(f"SKIP: {reason}")
        pytest.skip(reason)
    first_cycle = RunArrays(short_run.urdf, short_run.stamps[:1], short_run.q[:1], short_run.joint_names,
                            {k: v[:1] for k, v in short_run.series.items()},
                            {k: v[:1] for k, v in short_run.frames.items()}, (short_run.statuses or [])[:1] or None)
    start = time.monotonic()
    deadline = start + LOAD_TIMEOUT_S
    with (WebViewer(free_port(), free_port()) as whole, WebViewer(free_port(), free_port()) as cut,
          Chromium() as browser):
        for server, run in ((whole, short_run), (cut, first_cycle)):
            rec = rr.RecordingStream(rv.APPLICATION_ID)
            rec.connect_grpc(server.grpc_url)
            run.log(rec)
            rec.flush()
            rec.disconnect()  # the proxy keeps the data for the page
        png_end, end = load(browser, whole.url, deadline, tmp_path / "end.png")
        _, first = load(browser, cut.url, deadline, tmp_path / "start.png")
        moved = changed_pixels(first, end)
        print(f"browser test: {drawn_pixels(end)} drawn, {orange_pixels(end)} orange pixels, {moved} pixels moved, "
              f"{time.monotonic() - start:.0f} s; screenshots in {tmp_path}")
        assert moved >= MOVED_PIXELS, f"only {moved} pixels differ between the first and the last cycle"
        keep = os.environ.get("DUALARM_VIEW_SCREENSHOT")
        if keep:
            Path(keep).write_bytes(png_end)


NEAR_Q = [1.1261, -1.6987, -1.1776, 0.8174, 2.7065, -1.2329, 2.6597, 0.246, 0.1941, 0.1538, -1.3768, -1.7228, -1.8484,
          2.4161]
"""An LWR4 cell configuration with the hole block (left_hole_wall_xn) 2.1 cm from right_link_3 (found by a
seeded search, when the block was a solid box on left_flange)."""


def red_pixels(img: np.ndarray) -> int:
    view = img[VIEW_REGION]
    return int(np.count_nonzero((view[..., 0] > 0.7) & (view[..., 1] < 0.35) & (view[..., 2] < 0.35)))


def near_contact_run(with_pair: bool) -> RunArrays:
    model = DualArmModel()
    q = np.array([NEAR_Q, NEAR_Q])
    closest = rv.closest_pairs(model, q) if with_pair else None
    return RunArrays(model.urdf, np.array([0.0, 0.005]), q, list(model.joint_names), {}, closest=closest)


def test_the_closest_pair_is_in_the_recording(tmp_path: Path) -> None:
    """Issue 27: /collision/closest holds one line per cycle between coal's witness points, labelled
    with the pair and the distance, and its distance is plotted."""
    run = near_contact_run(True)
    assert run.closest is not None
    assert run.closest.labels[0].startswith("left_hole_wall_xn – right_link_3 0.021"), run.closest.labels
    save(run, tmp_path / "near.rrd")
    rows, scalars = read_rrd(tmp_path / "near.rrd")
    # one row per cycle, and the static coordinate frame of the witness points
    assert rows[f"/{rv.CLOSEST_ENTITY}"] == 2 + 1 and rows[f"/{rv.CLOSEST_ENTITY}/points"] == 2 + 1
    np.testing.assert_allclose(scalars[f"/plot/{rv.CLOSEST_DISTANCE}"], run.closest.distance, rtol=0, atol=0)
    gap = np.linalg.norm(run.closest.points[0, 1] - run.closest.points[0, 0])
    assert abs(gap - run.closest.distance[0]) < 1e-9


def test_web_viewer_draws_the_closest_pair_in_red(tmp_path: Path) -> None:
    """In chromium, the served viewer of a cell 2.1 cm from contact shows the closest pair's red
    witness points; the same run without the pair has none of those pixels."""
    if not CHROMIUM.exists():
        pytest.skip(f"{CHROMIUM} missing: apt-get install chromium (.ci/run does, as root)")
    deadline = time.monotonic() + LOAD_TIMEOUT_S
    with (WebViewer(free_port(), free_port()) as drawn, WebViewer(free_port(), free_port()) as plain,
          Chromium() as browser):
        for server, run in ((drawn, near_contact_run(True)), (plain, near_contact_run(False))):
            rec = rr.RecordingStream(rv.APPLICATION_ID)
            rec.connect_grpc(server.grpc_url)
            run.log(rec)
            rec.flush()
            rec.disconnect()
        # The run without the pair first: its red pixels are the baseline. The page draws the pair's
        # line after the arms' meshes (under load, seconds later: a screenshot at the arms alone had
        # 0 red pixels), so the run with the pair is polled until its line is there, with a deadline.
        _, without = load(browser, plain.url, deadline, tmp_path / "plain.png")
        base = red_pixels(without)
        _, with_pair = load(browser, drawn.url, deadline, tmp_path / "pair.png",
                            also=lambda img: red_pixels(img) >= base + 20,
                            what=f" and at least {base + 20} red pixels (the closest pair's line)")
    red = red_pixels(with_pair)
    print(f"red pixels: {red} with the closest pair, {base} without; screenshots in {tmp_path}")
    assert red >= base + 20, f"{red} red pixels with the pair, {base} without"
