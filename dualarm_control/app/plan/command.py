"""``dualarm plan SCENARIO --output DIR [--starts N] [--seed S]``: plan, execute, write plan.json and figures.

Only argparse is imported at module level: the cli builds this parser for every verb.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from collections.abc import Callable
from pathlib import Path

from dualarm_control.app.run.progress import progress_bar
from dualarm_control.errors import DualArmError

ProgressFactory = Callable[[str], Callable[[float, str], None]]

def add_plan_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The ``plan`` verb's arguments (the cli's parser hook); it runs :func:`run_plan_command`."""
    pl = sub.add_parser("plan", help="global manipulability plan of a relative path (paper 003) vs the baseline",
                        description="Optimise the joint configurations along the scenario's relative path "
                        "(key points then inner points, multi-start on a process pool), run the pseudo-inverse "
                        "baseline from the same start, execute the plan in the simulated cell, and write "
                        "DIR/plan.json, DIR/index_along_path.png (Fig. 4) and DIR/initial_configuration.png (Fig. 5).")
    pl.add_argument("scenario", help="scenario with a corner path (e.g. corner_path) or a YAML path")
    pl.add_argument("--output", default="out/plan", metavar="DIR", help="output directory (default: %(default)s)")
    pl.add_argument("--starts", type=int, metavar="N", help="random starts of the key-point NLP (default: the "
                    "scenario's plan.starts, 100)")
    pl.add_argument("--candidates", type=int, metavar="K", help="best distinct key-point optima completed by the "
                    "inner stage; the lowest whole-path cost wins (default: the scenario's plan.candidates, 4; "
                    "1 = the paper's method)")
    pl.add_argument("--seed", type=int, metavar="S", help="base seed (default: the scenario's plan.seed, 0)")
    pl.add_argument("--workers", type=int, metavar="W", help="processes (default: every core)")
    pl.add_argument("--no-execute", action="store_true", help="skip the execution in the simulator")
    pl.add_argument("--robot", default=None, metavar="NAME|PATH",
                    help="plan for this robot (config/robots/ name or YAML) instead of the scenario's; the path must "
                    "be within its reach")
    pl.set_defaults(func=run_plan_command)


def run_plan_command(args: argparse.Namespace, progress: ProgressFactory = progress_bar) -> int:
    """Body of ``dualarm plan`` (see :func:`add_plan_parser`)."""
    from dualarm_control.app.plan.optimise import default_workers, plan
    from dualarm_control.app.plan.record import plan_record
    from dualarm_control.app.record.figures import write_figures
    from dualarm_control.app.record.report import write_json
    from dualarm_control.collision import CollisionParams
    from dualarm_control.kinematics import DualArmModel
    from dualarm_control.planning.config import load_plan_config

    config = load_plan_config(args.scenario, args.robot)
    given = {key: getattr(args, key) for key in ("starts", "candidates", "seed") if getattr(args, key) is not None}
    for key in ("starts", "candidates"):
        if given.get(key, 1) < 1:
            raise DualArmError(f"--{key}: got {given[key]}, expected >= 1")
    config = dataclasses.replace(config, **given)
    workers = default_workers() if args.workers is None else args.workers
    if workers < 1:
        raise DualArmError(f"--workers: got {workers}, expected >= 1")
    out = Path(args.output)
    print(f"plan {config.name!r}: {config.starts} key-point starts, {config.candidates} candidates, "
          f"{min(config.starts, config.inner_starts)} inner starts per interval, seed {config.seed}, "
          f"{workers} workers; output {out}", file=sys.stderr)
    result = plan(config, workers, progress("plan"))
    model = DualArmModel(config.robot)
    execution = None
    if not args.no_execute:
        from dualarm_control.app.plan.execute import execute_plan

        execution = execute_plan(config, result.configurations, model, progress("execute"))
    doc = plan_record(result, model, execution)
    path = write_json(out / "plan.json", doc, indent=1)
    figures = [str(out / f) for f in write_figures("plan", out, config.name, plan=result)]
    print(f"average index            {doc['average_index']:.4f}")
    print(f"baseline average index   {doc['baseline_average_index']:.4f}")
    print(f"ratio                    {doc['index_ratio']:.3f}")
    print(f"max closure error        {doc['max_closure_error_m']:.2e} m, {doc['max_closure_error_rad']:.2e} rad")
    print(f"joint-limit violations   {doc['joint_limit_violations']}")
    print(f"optimisation runtime     {doc['runtime_s']:.1f} s ({workers} workers)")
    safety = CollisionParams().safety_distance
    print(f"closest link pair        {doc['closest_pair']} at {doc['closest_pair_m'] * 1e3:.1f} mm"
          + (f" (point {doc['closest_pair_point']})" if doc["closest_pair_point"] else ""))
    if doc["closest_pair_m"] < safety:
        print(f"warning: the plan brings {doc['closest_pair']} closer than the safety distance "
              f"{safety * 1e3:g} mm (paper 003's planner does not avoid collisions): its execution stops at the "
              "collision limit, off the path; try another --seed or more --starts", file=sys.stderr)
    if execution is not None:
        print(f"executed path error      max {execution.max_error_m * 1e3:.3f} mm, {execution.max_error_rad:.2e} rad; "
              f"rms {execution.rms_error_m * 1e3:.3f} mm, {execution.rms_error_rad:.2e} rad")
        print(f"executed closest pair    {execution.closest_pair} at {execution.closest_distance_m * 1e3:.1f} mm")
        print(f"execution                {execution.outcome}")
        if execution.stalled:
            print(f"warning: the plan's execution stalled: {execution.outcome}", file=sys.stderr)
    print(f"\nwrote {path}, {' and '.join(figures)}")
    return 0
