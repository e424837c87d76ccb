"""``dualarm experiment SCENARIO``: in-process runs of a scenario, their metrics, table and figures.

One run per solver (relative motion) or per gain k (a task scenario) by the one in-process runner
(:func:`dualarm_control.app.run.experiment.run_scenario`), summarised and drawn by
:mod:`dualarm_control.app.record.report`. The cli imports this module when the verb runs.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from dualarm_control.app.record.figures import write_figures
from dualarm_control.app.record.report import (
    format_table,
    goal_lines,
    prepare_output,
    summarize_run,
    write_json,
)
from dualarm_control.app.record.run_record import RunRecord
from dualarm_control.app.run import DEFAULT_SOLVERS
from dualarm_control.app.run.experiment import run_scenario
from dualarm_control.app.run.progress import progress_bar
from dualarm_control.cell_robot import cell_robot, robot_note
from dualarm_control.controller import ControllerParams
from dualarm_control.controller_params import controller_params
from dualarm_control.errors import DualArmError
from dualarm_control.kinematics import DualArmModel
from dualarm_control.params import read_params_files
from dualarm_control.scenario import Scenario, load_scenario

EXIT_INTERRUPTED = 130
"""Exit code of an interrupted experiment (what it completed is written)."""


def cell_values(scenario: Scenario, params_files: Sequence[str]) -> dict[str, Any]:
    """The controller parameter values of a run of ``scenario``: the cell's defaults
    (:meth:`~dualarm_control.scenario.Scenario.controller_defaults`), then the ``controller_node`` values of
    ``params_files`` in order (a file overrides a default: ``acceleration_limit: [0.0]`` turns a cell's bound off)."""
    return {**scenario.controller_defaults(), **read_params_files(params_files, "controller_node")}


def experiment_command(scenario_name: str, solver_names: str | None, params_files: list[str], out: Path,
                       gain_values: str | None, force: bool, duration: float | None, robot: str | None = None) -> int:
    """``dualarm experiment``: one run per solver, or for a task scenario one per gain k (force
    variant with ``force``); write ``out/metrics.json`` and the figures of the scenario's kind,
    print the table. Returns the exit code (130 when interrupted)."""
    robot, profile_robot = cell_robot(params_files, robot)  # the hardware profile's robot (hardware.robot) first
    scenario = load_scenario(scenario_name, robot)
    if params_files:
        print(robot_note(scenario, profile_robot, robot or ""), file=sys.stderr)
    spec = scenario.tasks
    base = cell_values(scenario, params_files)
    runs: list[tuple[str, ControllerParams, float | None]]
    if spec is None:
        if gain_values or force or duration:
            raise DualArmError(f"--gains, --force and --duration apply to task scenarios (pan_cleaning), "
                               f"not to {scenario.name!r}")
        solvers = [s.strip() for s in (solver_names or DEFAULT_SOLVERS).split(",") if s.strip()]
        runs = [(name, controller_params({**base, "solver": name}), None) for name in solvers]  # validates all first
        model: DualArmModel | None = DualArmModel(scenario.robot)
        print(f"scenario {scenario.name!r} ({scenario.source}) on robot {scenario.robot.name!r}; solvers: "
              f"{', '.join(solvers)}; output: {out}", file=sys.stderr)
    else:
        solver = solver_names or "constraint_based"
        if "," in solver:
            raise DualArmError("a task scenario runs one solver (constraint_based); got --solver " + solver)
        params = controller_params({**base, "solver": solver})
        try:
            gains = [float(g) for g in gain_values.split(",") if g.strip()] if gain_values else (
                [spec.force.gain] if force else list(spec.gains))
        except ValueError:
            raise DualArmError(f"--gains {gain_values!r}: expected comma-separated numbers > 0") from None
        if not gains or any(not g > 0 for g in gains):
            raise DualArmError(f"--gains {gain_values!r}: expected comma-separated numbers > 0")
        runs = [(f"k={gain:g}" + (" force" if force else ""), params, gain) for gain in gains]
        model = None  # each run builds the model of the scenario's URDF
        print(f"scenario {scenario.name!r} ({scenario.source}); solver {solver}; gains {gains}"
              f"{'; force feedback' if force else ''}; output: {out}", file=sys.stderr)

    prepare_output(out)  # before the runs: an output that cannot be written fails now, not after minutes
    results: dict[str, dict[str, Any]] = {}
    logs: list[RunRecord] = []
    try:
        for label, params, gain in runs:
            start = time.perf_counter()
            log = run_scenario(scenario, params, model, progress_bar(label), gain=gain, force=force, duration=duration)
            results[log.label] = summarize_run(log, scenario, model, params.alpha)
            logs.append(log)
            print(f"[{label}] done: {len(log.time)} cycles in {time.perf_counter() - start:.1f} s wall", file=sys.stderr)
    except KeyboardInterrupt:
        print("\ninterrupted: writing what is complete", file=sys.stderr)
        if results:
            write_json(out / "metrics.json", results)
        return EXIT_INTERRUPTED
    write_json(out / "metrics.json", results)
    kind = scenario.reference.kind
    paths = [str(out / f) for f in ("metrics.json", *write_figures(kind, out, scenario.name, logs, scenario))]
    print(format_table(results, kind))
    print(goal_lines(results), end="")
    print(f"\nwrote {' and '.join(paths) if len(paths) == 2 else ', '.join(paths)}")
    return 0
