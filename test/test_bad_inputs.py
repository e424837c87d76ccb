"""Bad files and places given to the `dualarm` verbs (issue 38): a truncated or corrupt bag, a bad plan file,
a malformed URDF, a YAML alias bomb, an output directory that cannot be written. Each ends with exit 2 and one
line naming the file and what is wrong (no traceback), and leaves nothing half-written behind."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
EXIT_USAGE = 2


def dualarm(*args: str, timeout: float = 300.0) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "dualarm_control.app.cli", *args], cwd=REPO, check=False,
                          capture_output=True, text=True, timeout=timeout)


def assert_refused(done: subprocess.CompletedProcess[str], *words: str) -> str:
    """Exit 2, no traceback, and the error line holds each of ``words``; the error line."""
    seen = f"exit {done.returncode}\nstdout:\n{done.stdout[-2000:]}\nstderr:\n{done.stderr[-3000:]}"
    assert done.returncode == EXIT_USAGE, seen
    assert "Traceback" not in done.stderr, seen
    line = done.stderr.strip().splitlines()[-1]
    assert ": error: " in line and all(word in line for word in words), seen
    return line


# ---- bags ----------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def good_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A small rosbag2 (MCAP, as the recorder writes it): 2000 commands on /velocity_controller/commands."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    msgtype = "std_msgs/msg/Float64MultiArray"
    cls = store.types[msgtype]
    layout = store.types["std_msgs/msg/MultiArrayLayout"](dim=[], data_offset=0)
    path = tmp_path_factory.mktemp("bags") / "good"
    with Writer(path, version=8, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection("/velocity_controller/commands", msgtype, typestore=store)
        import numpy as np

        for i in range(2000):
            data = store.serialize_cdr(cls(layout=layout, data=np.full(14, 0.001 * i)), msgtype)
            writer.write(conn, 5_000_000 * (i + 1), data)
    return path


def damaged(good: Path, tmp_path: Path, how: str) -> Path:
    import shutil

    bag = tmp_path / how
    shutil.copytree(good, bag)
    (storage,) = bag.glob("*.mcap")
    data = bytearray(storage.read_bytes())
    if how == "truncated":
        data = data[: len(data) // 2]
    else:  # 4 KiB of garbage a quarter into the file (in the chunks; the summary at the end is intact)
        start = len(data) // 4
        data[start:start + 4096] = b"\xa5" * 4096
    storage.write_bytes(bytes(data))
    return bag


@pytest.mark.parametrize("how", ["truncated", "corrupt"])
def test_report_on_a_damaged_bag_is_refused_naming_it(good_bag: Path, tmp_path: Path, how: str) -> None:
    bag = damaged(good_bag, tmp_path, how)
    out = tmp_path / "report"
    assert_refused(dualarm("report", str(bag), "--output", str(out)), str(bag), "cannot read bag")
    assert not out.exists()  # nothing half-written


def test_bag_info_on_a_truncated_bag_is_refused_naming_it(good_bag: Path, tmp_path: Path) -> None:
    bag = damaged(good_bag, tmp_path, "truncated")
    assert_refused(dualarm("bag", "info", str(bag)), str(bag), "cannot read bag")


# ---- plan files ----------------------------------------------------------------------------------


def write_plan(tmp_path: Path, name: str, change: str) -> Path:
    """A plan.json of corner_path (zero configurations, inside the limits) with one thing wrong at point 3."""
    import json
    import math

    from dualarm_control.kinematics import DualArmModel
    from dualarm_control.planning.plan_file import PLAN_FORMAT
    from dualarm_control.scenario import load_scenario

    joints = DualArmModel(load_scenario("corner_path").robot).joint_names
    points = [{"configuration_rad": [0.0] * len(joints)} for _ in range(5)]
    row = points[3]["configuration_rad"]
    if change == "count":
        del row[-1]
    elif change == "nan":
        row[2] = math.nan
    elif change == "limits":
        row[2] = 7.0  # rad: beyond every joint of the LWR4 (2.97 rad at most)
    path = tmp_path / name
    path.write_text(json.dumps({"format": PLAN_FORMAT, "scenario": "corner_path", "joint_names": joints,
                                "points": points}))
    return path


@pytest.mark.parametrize(("change", "words"), [("count", "point 3 has 13 joint values, expected 14"),
                                                ("nan", "point 3, joint left_joint_3: nan is not finite"),
                                                ("limits", ("point 3, joint left_joint_3: 7 rad is beyond the joint "
                                                            "limits [-2.96706, 2.96706]"))])
def test_plan_loader_refuses_a_bad_plan_naming_the_file_point_and_joint(tmp_path: Path, change: str,
                                                                        words: str) -> None:
    from dualarm_control.errors import ScenarioError
    from dualarm_control.kinematics import DualArmModel
    from dualarm_control.planning.plan_file import read_plan
    from dualarm_control.scenario import load_scenario

    model = DualArmModel(load_scenario("corner_path").robot)
    path = write_plan(tmp_path, f"{change}.json", change)
    with pytest.raises(ScenarioError) as refused:
        read_plan(path, model.joint_names, model.q_min, model.q_max)
    assert str(path) in str(refused.value) and words in str(refused.value)
    good = read_plan(write_plan(tmp_path, "good.json", ""), model.joint_names, model.q_min, model.q_max)
    assert good.configurations.shape == (5, 14)


@pytest.mark.parametrize(("change", "words"), [("count", "has 13 joint values"), ("nan", "is not finite"),
                                              ("limits", "point 3, joint left_joint_3: 7 rad is beyond the joint limits")])
def test_launch_refuses_a_bad_plan_with_exit_2(tmp_path: Path, change: str, words: str) -> None:
    """Refused by `dualarm launch` itself before any node starts (the model's limits included)."""
    path = write_plan(tmp_path, f"{change}.json", change)
    assert_refused(dualarm("launch", "corner_path", "--plan", str(path), "--lockstep"), str(path), words)


# ---- robot descriptions --------------------------------------------------------------------------


def test_a_robot_whose_urdf_is_malformed_xml_is_refused_naming_the_urdf(tmp_path: Path) -> None:
    """A robot YAML (the xArm7 pair's) pointing to a URDF that is not well-formed XML."""
    urdf = tmp_path / "broken.urdf"
    urdf.write_text('<robot name="x">\n  <link name="a">\n  <joint name="j" type="revolute">\n</robot>\n')
    robot = tmp_path / "robot.yaml"
    robot.write_text((Path(__file__).parent / "data" / "xarm7_pair.yaml").read_text()
                     .replace("urdf: example-robot-data:xarm_description/urdf/xarm7.urdf", "urdf: broken.urdf"))
    out = tmp_path / "out"
    assert_refused(dualarm("experiment", "assembly", "--robot", str(robot), "--solver", "sparse_qp", "--output",
                           str(out)), f"{urdf}: not a valid URDF (mismatched tag: line 4")
    assert not out.exists()


# ---- output directories --------------------------------------------------------------------------


@pytest.mark.parametrize(("where", "why"), [("file", "a file, not a directory"), ("under_file", "Not a directory")])
def test_an_output_that_cannot_be_written_is_refused_before_the_run(tmp_path: Path, where: str, why: str) -> None:
    """`dualarm experiment --output` on a regular file or under one: exit 2 naming it, before the runs."""
    blocker = tmp_path / "a_file"
    blocker.write_text("not a directory\n")
    out = blocker if where == "file" else blocker / "sub"
    done = dualarm("experiment", str(Path(__file__).parent / "data" / "short.yaml"), "--solver", "sparse_qp",
                   "--output", str(out))
    assert_refused(done, f"output directory {out}: cannot write there ({why})")
    assert "done:" not in done.stderr  # refused before the first run
    assert blocker.read_text() == "not a directory\n" and [p.name for p in tmp_path.iterdir()] == ["a_file"]
