"""Which robot a cell runs on (issue 40 item 5): the hardware profile names it, every verb takes it from there.

A hardware profile carries its robot (``hardware.robot``: a name of ``config/robots/`` or a YAML path,
a relative path taken relative to the profile file when a tool reads the file). The nodes, ``dualarm
hardware check``, ``launch``, ``experiment`` and ``run`` choose the robot by one rule (:func:`choose_robot`):

* the profile's robot, when it names one; a ``--robot`` (or ``robot`` parameter) naming another robot
  is refused, naming both;
* else ``--robot`` / the ``robot`` parameter;
* else the scenario's robot (the LWR4 cell of the shipped scenarios), said in one line
  (:func:`robot_note`), never silently.

ROS-free.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from dualarm_control.errors import ParameterError
from dualarm_control.params import read_params_file, read_params_files
from dualarm_control.robot_files import RobotError
from dualarm_control.robot_params import robot_file
from dualarm_control.scenario import Scenario, load_scenario

KEY = "hardware.robot"
CONTROLLER = "controller_node"


def _file(robot: str) -> Path | None:
    """The resolved file of a robot name or path (None if there is none: load_robot then says why)."""
    try:
        return robot_file(robot).resolve()
    except RobotError:
        return None


def choose_robot(profile_robot: str, robot: str, key: str = KEY) -> str:
    """The robot of the cell: ``profile_robot`` (``hardware.robot``), else ``robot`` (``--robot`` or the
    ``robot`` parameter), else '' (the scenario's). ParameterError naming both when the two name
    different robots (compared by their files)."""
    if profile_robot and robot and _file(profile_robot) != _file(robot):
        raise ParameterError(key, profile_robot, f"the robot that --robot / the robot parameter names ({robot!r}): "
                             f"the hardware profile runs on {profile_robot!r}; drop --robot or change {key}")
    return profile_robot or robot


def robot_note(scenario: Scenario, profile_robot: str, robot: str) -> str:
    """The one line that says where the cell's robot comes from."""
    name = scenario.robot.name
    if profile_robot:
        return f"robot '{name}' from the hardware profile ({KEY}: {profile_robot})"
    if robot:
        return f"robot '{name}' from --robot / the robot parameter ({robot}); the hardware profile names none ({KEY})"
    return (f"robot '{name}': the scenario '{scenario.name}''s, as the hardware profile names none ({KEY}) and no "
            "--robot was given (docs/hardware.md: 'Your own cell, step by step')")


def node_scenario(values: Mapping[str, Any], node: str) -> tuple[Scenario, str]:
    """A node's scenario on the cell's robot (its ``scenario``, ``robot`` and ``hardware.robot`` values)
    and the line saying where the robot comes from."""
    profile_robot, robot = str(values.get(KEY, "")), str(values.get("robot", ""))
    chosen = choose_robot(profile_robot, robot, f"{node}.{KEY}")
    scenario = load_scenario(str(values["scenario"]), chosen or None)
    return scenario, robot_note(scenario, profile_robot, robot)


def params_robot(params: Sequence[str | Path]) -> str:
    """``hardware.robot`` of the controller's parameter files (the last file that sets it wins), a
    relative YAML path made absolute against that file's folder; '' when none names a robot."""
    found = ""
    for path in params:
        value = str(read_params_file(path, CONTROLLER).get(KEY, "") or "")
        if value:
            relative = value.endswith((".yaml", ".yml")) and not Path(value).is_absolute()
            found = str((Path(path).resolve().parent / value).resolve()) if relative else value
    return found


def cell_robot(params: Sequence[str | Path], robot: str | None) -> tuple[str | None, str]:
    """What a tool runs on, from its ``--params`` files and ``--robot`` (else the files' ``robot``): the robot
    (None: the scenario's) and the profile's robot ('' when it names none; a path made absolute).
    ParameterError when the two differ."""
    profile_robot = params_robot(params)
    given = robot or str(read_params_files(params, CONTROLLER).get("robot", "") or "")
    return choose_robot(profile_robot, given) or None, profile_robot


def with_absolute_robot(ros_args: Sequence[str]) -> list[str]:
    """A node's ROS arguments with ``-p hardware.robot:=PATH`` added when a ``--params-file`` names a relative
    ``hardware.robot`` path (made absolute against that file's folder, as the tools read it; a node alone
    would read it against its working directory). Unchanged when an argument sets hardware.robot itself."""
    args = list(ros_args)
    files = [args[i + 1] for i, a in enumerate(args[:-1]) if a == "--params-file"]
    if not files or any(a.startswith((f"{KEY}:=", f"{CONTROLLER}:{KEY}:=")) for a in args):
        return args
    raw = [str(read_params_file(f, CONTROLLER).get(KEY, "") or "") for f in files]
    last = next((r for r in reversed(raw) if r), "")
    if not last.endswith((".yaml", ".yml")) or Path(last).is_absolute():
        return args
    return [*args, "-p", f"{KEY}:={params_robot(files)}"]
