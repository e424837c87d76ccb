"""``dualarm sweep SPEC.yaml`` and ``dualarm sweep report TABLE`` (issue 28, docs/sweep.md)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from dualarm_control.errors import DualArmError

EXIT_INTERRUPTED = 130
DEFAULT_OUTPUT = "out/sweep"


def add_sweep_parser(sub: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    """Register the ``sweep`` verb."""
    swp = sub.add_parser(
        "sweep", help="closed-loop runs over random relative tasks x robots x solvers on Dask (Parquet rows)",
        description="Run the grid of SPEC.yaml (robots x solvers x variants x tasks, config/sweeps/) as Dask tasks "
        "(a local cluster on 127.0.0.1 by default) into the Parquet dataset DIR; runs already in DIR are skipped. "
        "'dualarm sweep report TABLE' writes the paired l0 ratios (medians, bootstrap 95 % CIs), report.md and "
        "box plots. 'dualarm sweep scaling SPEC.yaml' runs the same runs in this process, on one local worker and "
        "on two, one after the other, and writes the rates and their ratios (scaling.md, scaling.json).")
    swp.add_argument("spec", metavar="SPEC.yaml|report|scaling", help="the sweep spec, or 'report' or 'scaling'")
    swp.add_argument("table", nargs="?", default=None, metavar="TABLE|SPEC.yaml",
                     help="report: the sweep's output directory; scaling: the spec")
    swp.add_argument("--tasks", type=int, default=None, metavar="N", help="number of tasks (default: the spec's)")
    swp.add_argument("--robots", default=None, metavar="NAME,...", help="only these of the spec's robots")
    swp.add_argument("--output", default=None, metavar="DIR",
                     help=f"sweep: the Parquet dataset (default: {DEFAULT_OUTPUT}/<spec name>); report: where "
                     "report.md and the figures go (default: TABLE/report); scaling: where the layouts' rows, "
                     f"scaling.md and scaling.json go (default: {DEFAULT_OUTPUT}/<spec name>_scaling)")
    swp.add_argument("--scheduler", default=None, metavar="tcp://HOST:PORT",
                     help="an existing Dask scheduler (default: a local cluster on 127.0.0.1)")
    swp.add_argument("--workers", type=int, default=2, metavar="N",
                     help="local cluster worker processes (default: %(default)s; 0: in this process, no Dask)")
    swp.add_argument("--interleave", type=int, default=0, metavar="ROUNDS",
                     help="scaling: also measure one warm worker against this process task by task, each task "
                     "on both sides one right after the other, ROUNDS passes over the tasks (the fair overhead "
                     "figure, with a bootstrap interval; default: %(default)s, off)")
    swp.add_argument("--seed", type=int, default=0, help="report: bootstrap seed (default: %(default)s)")
    swp.add_argument("--no-progress", action="store_true", help="no progress bar")
    swp.set_defaults(func=cmd_sweep)


def cmd_sweep(args: argparse.Namespace) -> int:
    """Dispatch ``sweep SPEC`` / ``sweep report TABLE``."""
    if args.spec == "report":
        if args.table is None:
            raise DualArmError("sweep report: give the sweep's output directory (TABLE)")
        from dualarm_control.app.sweep.report import report

        table = Path(args.table)
        if not table.is_dir():
            raise DualArmError(f"sweep report: {table} is not a sweep output directory")
        text, paths = report(table, Path(args.output) if args.output else table / "report", args.seed)
        print(text)
        print("wrote " + ", ".join(str(p) for p in paths))
        return 0
    if args.spec == "scaling":
        if args.table is None:
            raise DualArmError("sweep scaling: give the sweep spec (SPEC.yaml)")
        if args.tasks is not None and args.tasks < 1:
            raise DualArmError("sweep: --tasks must be >= 1")
        from dualarm_control.app.sweep.scaling import scaling
        from dualarm_control.app.sweep.spec import load_spec

        spec = load_spec(Path(args.table)).with_tasks(args.tasks).with_robots(args.robots)
        out = Path(args.output) if args.output else Path(DEFAULT_OUTPUT) / f"{spec.name}_scaling"
        if args.interleave < 0:
            raise DualArmError(f"sweep scaling: --interleave {args.interleave}: expected rounds >= 0")
        text, paths = scaling(spec, out, progress=lambda m: print(m, file=sys.stderr), rounds=args.interleave)
        print(text)
        print("wrote " + ", ".join(str(p) for p in paths))
        return 0
    if args.table is not None:
        raise DualArmError(f"sweep: unexpected argument {args.table!r} (did you mean 'sweep report TABLE'?)")
    if args.workers < 0 or (args.tasks is not None and args.tasks < 1):
        raise DualArmError("sweep: --workers must be >= 0 and --tasks >= 1")
    from dualarm_control.app.sweep.execute import run_sweep
    from dualarm_control.app.sweep.spec import load_spec

    spec = load_spec(Path(args.spec)).with_tasks(args.tasks).with_robots(args.robots)
    out = Path(args.output) if args.output else Path(DEFAULT_OUTPUT) / spec.name
    where = args.scheduler or ("this process" if args.workers == 0 else f"a local cluster of {args.workers} workers")
    print(f"sweep {spec.name!r}: {len(spec.robots)} robots x {len(spec.solvers)} solvers x {len(spec.variants)} "
          f"variants x {spec.tasks} tasks on {where}; output {out}", file=sys.stderr)
    try:
        result = run_sweep(spec, out, args.scheduler, args.workers, show_progress=not args.no_progress)
    except KeyboardInterrupt:
        print(f"\ninterrupted: the rows that arrived are in {out}; run again to do the rest", file=sys.stderr)
        return EXIT_INTERRUPTED
    print(f"{result.total} runs: {result.skipped} already done, {result.ran} ran, {result.failed} with an error; "
          f"rows in {out}")
    return 0
