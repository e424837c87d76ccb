"""docs/hardware.md's "Your own cell, step by step", followed word for word (issue 40 item 5).

The page's profile (``my_cell.yaml``: the LWR4 cell whose hardware names its joints franka-style,
``left_arm_joint1``..., one trajectory controller on the velocity interface) is written as the page gives
it, and the page's command lines are run as they are written, in the folder holding it; the simulator
stands in for the hardware (it speaks the profile: the hardware's joint names on ``/joint_states`` and on
the commands). Checked:

* step 4 (lockstep, the simulator): ``dualarm report`` of the renamed cell's bag equals the default
  profile's report of the same scenario to 1e-6, and the bag's joint states and commands carry the
  hardware's names;
* step 5 (real time, the simulator as the robot's ros2_control): ``dualarm hardware check`` passes, and the
  controller and the trajectory node started with the page's command lines drive the arms to the scenario's
  end (every segment reached, the last within 1 mm), or (interactive) to the page's goal (``dualarm goal
  --wait``: reached; measured 0.05 mm).

The fast variants run ``test/data/short.yaml`` (4 cm, 15 deg) where the page says ``assembly``; the
``slow`` ones the assembly itself.
"""

from __future__ import annotations

import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest
from launching import side_by_side
from reports import assert_same_report, report_metrics
from waiting import NodeProcess, node_env

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "hardware.md"
SECTION = "## Your own cell, step by step"
SHORT = str(ROOT / "test" / "data" / "short.yaml")
ACCELERATION = str(ROOT / "config" / "acceleration_limit.yaml")
"""The profile's bound (10 rad/s^2): the default profile's run gets the same one."""
FENCE = re.compile(r"^```(\w*)\n(.*?)^```", re.DOTALL | re.MULTILINE)


def section() -> str:
    text = PAGE.read_text()
    start = text.index(SECTION)
    end = text.find("\n## ", start + len(SECTION))
    return text[start:end if end >= 0 else len(text)]


def step(n: int) -> str:
    """The text of step ``n`` (from its ``**n.`` to the next step's)."""
    text = section()
    start = text.index(f"**{n}. ")
    end = text.find(f"**{n + 1}. ", start)
    return text[start:end if end >= 0 else len(text)]


def profile_text() -> str:
    (block,) = [b for lang, b in FENCE.findall(section()) if lang == "yaml" and b.startswith("# my_cell.yaml")]
    return block


def command_lines(text: str) -> list[str]:
    """The ``dualarm`` command lines of the bash blocks of ``text``, in order."""
    return [line.strip() for lang, block in FENCE.findall(text) if lang == "bash"
            for line in block.splitlines() if line.strip().startswith("dualarm ")]


def argv(line: str, scenario: str) -> list[str]:
    """A page's command line as this interpreter runs it, on ``scenario`` where the page says ``assembly``."""
    words = [w.replace("scenario:=assembly", f"scenario:={scenario}") for w in shlex.split(line)]
    words = [scenario if w == "assembly" else w for w in words]
    assert words[0] == "dualarm", line
    return [sys.executable, "-m", "dualarm_control.app.cli", *words[1:]]


def run(line: str, scenario: str, cwd: Path, env: dict[str, str], timeout: float) -> str:
    done = subprocess.run(argv(line, scenario), cwd=cwd, capture_output=True, text=True, timeout=timeout,
                          env={**node_env(), **env}, check=False)
    assert done.returncode == 0, f"{line}: exit {done.returncode}\n{done.stdout[-3000:]}\n{done.stderr[-3000:]}"
    return done.stdout + done.stderr


@pytest.fixture
def cell(tmp_path: Path) -> Path:
    """The folder the user works in: the page's my_cell.yaml, written as the page gives it."""
    (tmp_path / "my_cell.yaml").write_text(profile_text())
    return tmp_path


def simulator_step(cell: Path, scenario: str, timeout: float) -> None:
    """Step 4 on ``scenario`` beside the default profile's lockstep run of it; the reports compared."""
    lines = command_lines(step(4))
    assert [shlex.split(line)[1] for line in lines] == ["launch", "report"], lines
    default = cell / "default"
    default.mkdir()

    def mine(env: dict[str, str]) -> str:
        return "".join(run(line, scenario, cell, env, timeout) for line in lines)

    def reference(env: dict[str, str]) -> str:
        run(f"dualarm launch assembly --lockstep --params {ACCELERATION} --record bag", scenario, default, env,
            timeout)
        return run("dualarm report bag --output report", scenario, default, env, timeout)

    out = side_by_side({"mine": mine, "default": reference})
    assert "robot 'lwr4_cell' from the hardware profile (hardware.robot: lwr4_cell)" in out["mine"], out["mine"]
    report = next(Path(w) for w in shlex.split(lines[1]) if w.endswith("_report"))
    got = report_metrics(cell / report)
    compared = assert_same_report(report_metrics(default / "report"), got)
    print(f"{compared} metrics equal to 1e-6; {got}")
    for label in got:
        assert got[label]["max_joint_acceleration"] <= 10.0 * (1 + 1e-6), got[label]
    hardware_names(cell / next(w for w in shlex.split(lines[0]) if w.endswith("_bag")))


def hardware_names(bag: Path) -> None:
    """The bag's joint states and commands name the joints as the hardware does (the map was in effect)."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    names: dict[str, set[str]] = {}
    with AnyReader([bag], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as reader:
        for conn, _, raw in reader.messages():
            if conn.topic in ("/joint_states", "/arms_trajectory_controller/joint_trajectory"):
                msg = reader.deserialize(raw, conn.msgtype)
                names.setdefault(conn.topic, set()).update(msg.name if conn.topic == "/joint_states"
                                                           else msg.joint_names)
    want = {f"{side}_arm_joint{k}" for side in ("left", "right") for k in range(1, 8)}
    assert names.get("/joint_states") == want, names
    assert names.get("/arms_trajectory_controller/joint_trajectory") == want, names


def test_the_page_names_what_a_lab_needs() -> None:
    """The steps are there: robot, joint map, a controller that stops, the simulator, the cell (interactive
    goals, a scenario from the measured state), discovery beyond localhost, what each profile does when the
    controller dies."""
    text = section()
    for words in ("hardware.robot", "hardware.joint_map", "cmd_timeout", "mode:=interactive", "dualarm goal",
                  "measured", "ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET", "ROS_STATIC_PEERS", "LOCALHOST",
                  "ros2_control_velocity.yaml", "lbr_dual_position.yaml", "JointGroupVelocityController"):
        assert words in text, words
    assert [shlex.split(line)[1] for line in command_lines(step(5))] == ["hardware", "run", "run", "goal", "run"]


def test_the_renamed_cell_on_the_simulator_reports_as_the_default_profile(cell: Path) -> None:
    simulator_step(cell, SHORT, 240.0)


@pytest.mark.slow
def test_the_renamed_cell_runs_the_assembly_as_the_default_profile(cell: Path) -> None:
    simulator_step(cell, "assembly", 900.0)


def start_cell(cell: Path, scenario: str, trajectory: str) -> list[NodeProcess]:
    """Step 5's check, controller and ``trajectory`` line (the page's), with the simulator as the robot's
    ros2_control (real time); the nodes started (the simulator first)."""
    check, controller = command_lines(step(5))[:2]
    nodes = [NodeProcess("sim_node", "--params-file", str(cell / "my_cell.yaml"), "-p", f"scenario:={scenario}")]
    nodes[0].wait_for("real-time at")
    out = run(check, scenario, cell, {}, 120.0)
    assert "joints matched: 14 of 14" in out and "the profile can run" in out, out
    for line in (controller, trajectory):  # in the user's folder: the page's relative profile path made absolute
        words = [str(cell / w) if w == "my_cell.yaml" else w for w in argv(line, scenario)]
        assert words[3:6] == ["run", words[4], "--ros-args"], line
        nodes.append(NodeProcess(words[4], *words[6:]))
        if words[4] == "controller_node":
            nodes[-1].wait_for("hardware profile matches the graph")
    return nodes


def real_cell_step(cell: Path, scenario: str, timeout: float) -> None:
    """Step 5 with the simulator as the robot's ros2_control: the check, the controller, the trajectory node
    running the scenario from the measured state, to its end within 1 mm."""
    nodes: list[NodeProcess] = []
    try:
        nodes = start_cell(cell, scenario, command_lines(step(5))[4])
        traj = nodes[2]
        traj.wait_for("complete at", timeout=timeout)
        verdicts = [m for line in traj.lines for m in [re.search(r": (\w+), error ([0-9.]+) mm", line)] if m]
        print("\n".join(traj.lines[-5:]))
        assert verdicts and all(m[1] == "reached" for m in verdicts), traj.lines[-10:]
        assert float(verdicts[-1][2]) < 1.0, traj.lines[-10:]  # mm
    finally:
        for node in reversed(nodes):
            node.stop()


@pytest.mark.realtime
def test_the_renamed_cell_with_the_pages_node_commands(cell: Path) -> None:
    real_cell_step(cell, SHORT, 120.0)


@pytest.mark.slow
@pytest.mark.realtime
def test_the_renamed_cell_runs_the_assembly_with_the_pages_node_commands(cell: Path) -> None:
    real_cell_step(cell, "assembly", 240.0)


@pytest.mark.slow  # 62 s here: the goal is 15 cm and half a turn from the assembly's start
@pytest.mark.realtime
def test_the_renamed_cell_follows_the_pages_interactive_goal(cell: Path) -> None:
    """Step 5's interactive trajectory node and the page's goal (the assembly's start, real time): reached."""
    _, _, interactive, goal, _ = command_lines(step(5))
    nodes: list[NodeProcess] = []
    try:
        nodes = start_cell(cell, "assembly", interactive)
        nodes[2].wait_for("holding the measured relative pose")
        out = run(goal, "assembly", cell, {}, 240.0)
        print(out)
        assert "reached" in out, out
    finally:
        for node in reversed(nodes):
            node.stop()
