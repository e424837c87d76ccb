"""The ``dualarm faults`` and ``dualarm soak`` verbs: the fault matrix and the soak run against real
processes (docs/safety.md); their parsers and commands."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path


def cmd_faults(args: argparse.Namespace) -> int:
    """The fault matrix against real processes: DIR/faults.md and faults.json; exit 1 if a row failed."""
    from dualarm_control.app.faults.matrix import format_table, write_results
    from dualarm_control.app.faults.rows import ROWS
    from dualarm_control.app.faults.run_all import run_matrix
    from dualarm_control.scenario import scenario_file

    scenario_file(args.scenario)
    only = [n.strip() for n in args.only.split(",") if n.strip()] if args.only else list(ROWS)
    bad = [n for n in only if n not in ROWS]
    if bad:
        print(f"dualarm faults: unknown rows {', '.join(bad)}; valid: {', '.join(ROWS)}", file=sys.stderr)
        return 2  # usage
    out = Path(args.output)
    start = time.monotonic()
    rows = run_matrix(out, args.scenario, only, lambda text: print(f"[faults] {text}", flush=True))
    seconds = time.monotonic() - start
    write_results(out, rows, seconds)
    print(format_table(rows))
    print(f"\n{sum(r.status == 'pass' for r in rows)} passed, {sum(r.status == 'FAIL' for r in rows)} failed, "
          f"{sum(r.status == 'skipped' for r in rows)} skipped in {seconds:.0f} s; wrote {out}/faults.md and faults.json")
    return 1 if any(r.status == "FAIL" for r in rows) else 0


def cmd_soak(args: argparse.Namespace) -> int:
    """The scenario on repeat over ROS: RSS growth, missed-deadline bursts, accounting (soak.md/json)."""
    from dualarm_control.app.faults.soak import format_soak, run_soak, write_soak
    from dualarm_control.scenario import scenario_file

    scenario_file(args.scenario)
    doc = run_soak(args.minutes, args.scenario, lambda text: print(f"[soak] {text}", flush=True))
    out = Path(args.output)
    write_soak(out, doc)
    print(format_soak(doc))
    print(f"\nwrote {out}/soak.md and soak.json")
    return 0 if doc["passed"] else 1


def add_faults_parsers(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add ``faults`` and ``soak`` to the ``dualarm`` command's verbs."""
    fau = sub.add_parser("faults", help="fault matrix against real processes (watchdogs, kills, signals, links)",
                         description="Inject faults into real-time runs of the three nodes (loopback, and private "
                         "network namespaces when root and iproute2 are available) and judge each from the run's bag "
                         "and logs. Prints and writes DIR/faults.md and faults.json; exit 1 if a row failed. Rows that "
                         "cannot run here are reported as skipped, with the reason.")
    fau.add_argument("--output", default="out/faults", metavar="DIR", help="output directory (default: %(default)s)")
    fau.add_argument("--scenario", default="assembly", help="scenario of the runs (default: %(default)s)")
    from dualarm_control.app.faults.rows import ROWS

    fau.add_argument("--only", metavar="ROW,...", help=f"run only these rows (default: all): {', '.join(ROWS)}")
    fau.set_defaults(func=cmd_faults)
    soak = sub.add_parser("soak", help="benchmark: the scenario on repeat at 200 Hz over ROS for minutes",
                          description="Run the three nodes with the scenario on repeat (trajectory_node repeat:=true) "
                          "in real time; sample each node's RSS and the /diagnostics counters every second; report "
                          "RSS growth (<= 5 %), missed-deadline bursts and whether every command is accounted for. "
                          "Writes DIR/soak.md and soak.json; exit 1 if a criterion fails.")
    soak.add_argument("--minutes", type=float, default=10.0, help="duration (default: %(default)s)")
    soak.add_argument("--scenario", default="assembly", help="scenario (default: %(default)s)")
    soak.add_argument("--output", default="out/soak", metavar="DIR", help="output directory (default: %(default)s)")
    soak.set_defaults(func=cmd_soak)
